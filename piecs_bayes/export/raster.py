"""Figures as PNG pixels, drawn in this process or in a helper process beside it.

Drawing a figure (Agg: ticks, text, lines) is most of a report's time and uses one
core. `Rasteriser` hands figures, pickled, to one helper process, and the caller
goes on with its own work (the PDF's text pages); when it needs a figure that the
helper has not started, it draws that one itself. The PNG is the same either way:
the same matplotlib draws the same pickled figure under the same rc settings
(tests/export/test_raster.py). A figure that cannot be pickled, a machine with one
core, or a helper that cannot start or dies: the figure is drawn here.

This module imports matplotlib and PIL only (not JAX), so that the helper starts in
about half a second.
"""

from __future__ import annotations

import io
import os
import pickle
import threading

#: colours of a report figure's PNG: a palette image, its colours chosen per figure
PNG_COLOURS = 256

#: ``PIECS_BAYES_DRAW_HELPER=0`` draws every figure in the calling process
HELPER_ENV = "PIECS_BAYES_DRAW_HELPER"


def png_bytes(fig, dpi: float | None = None) -> bytes:
    """`fig` as PNG, at `dpi` (the style's `savefig.dpi` when None), in at most
    `PNG_COLOURS` colours (octree, no dithering).

    A plot's pixels are a few thousand shades of the lines' antialiased edges, and a
    palette of 256 keeps each within a few levels of 255 (47 at worst on the
    translucent traces). The PDF embeds a figure of at most 256 colours indexed
    instead of compressing its 24-bit pixels a second time, and the HTML is a third
    of the size (docs/models/report.md, "Drawn once, written small")."""
    from matplotlib import rcParams
    from PIL import Image

    d = rcParams["savefig.dpi"] if dpi is None else dpi
    d = fig.dpi if d == "figure" else float(d)
    raw = _Pixels()  # Agg's pixels as they are: no PNG written and read back
    fig.savefig(raw, format="rgba", dpi=d)
    if len(raw.shape) == 3:  # (height, width, 4): the renderer's buffer
        rgba = Image.frombuffer("RGBA", raw.shape[1::-1], raw.data, "raw", "RGBA", 0, 1)
    else:  # a matplotlib that writes bytes: its size is not known here, read a PNG
        png = io.BytesIO()
        fig.savefig(png, format="png", dpi=d, pil_kwargs={"compress_level": 0})
        with Image.open(png) as im:
            rgba = im.convert("RGBA")
    flat = Image.new("RGBA", rgba.size, "white")  # on white, as the page shows it
    flat.alpha_composite(rgba)
    pal = flat.convert("RGB").quantize(
        PNG_COLOURS, method=Image.Quantize.FASTOCTREE, dither=Image.Dither.NONE
    )
    buf = io.BytesIO()
    pal.save(buf, format="png", optimize=False, dpi=(d, d))
    return buf.getvalue()


class _Pixels:
    """A file for `savefig(format="rgba")` that keeps what Agg writes, the renderer's
    buffer, with its shape."""

    shape: tuple = ()
    data: bytes = b""

    def write(self, b) -> int:
        view = memoryview(b)
        self.shape, self.data = view.shape, view.tobytes()
        return view.nbytes

    def seek(self, offset: int, whence: int = 0) -> int:  # a file handle, to matplotlib
        return 0


def _serve() -> None:  # pragma: no cover - runs in the helper process
    """The helper's loop: requests on stdin, PNGs on stdout (`_Helper`), until EOF."""
    import sys
    import traceback

    from matplotlib import rc_context

    src, out = sys.stdin.buffer, sys.stdout.buffer
    while True:
        head = src.read(8)
        if len(head) < 8:
            return
        fig_blob, rc, dpi = pickle.loads(src.read(int.from_bytes(head, "little")))
        try:
            with rc_context(rc):
                ok, body = b"\x00", png_bytes(pickle.loads(fig_blob), dpi)
        except Exception:  # noqa: BLE001 - said to the caller, who draws it instead
            ok, body = b"\x01", traceback.format_exc().encode()
        out.write(ok + len(body).to_bytes(8, "little") + body)
        out.flush()


def _style(rc) -> dict:
    """The settings of `rc` (an rcParams) that differ from matplotlib's defaults: what
    a fresh interpreter needs to draw as this one does (the backend is its own)."""
    from matplotlib import rcParamsDefault

    return {
        k: v
        for k, v in dict(rc).items()
        if not k.startswith("backend") and k in rcParamsDefault and v != rcParamsDefault[k]
    }


def _cores() -> int:
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return os.cpu_count() or 1


class _Job:
    def __init__(self, request: bytes):
        self.request = request
        self.done = threading.Event()
        self.png: bytes | None = None  # None when done: the helper could not draw it


class _Helper:
    """One helper process (a fresh interpreter running `_serve`: not `multiprocessing`,
    whose spawn re-runs the caller's main script) and a thread that hands it one job
    at a time from `queue`, the newest first. A job still in `queue` can be taken
    back (`take`)."""

    def __init__(self):
        import subprocess
        import sys
        from collections import deque
        from pathlib import Path

        root = str(Path(__file__).resolve().parents[2])  # where piecs_bayes is found
        path = os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")]))
        env = {**os.environ, "MPLBACKEND": "Agg", "PYTHONPATH": path}
        self.proc = subprocess.Popen(
            [sys.executable, "-c", "from piecs_bayes.export.raster import _serve; _serve()"],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, env=env,
        )  # fmt: skip
        self.queue: deque[_Job] = deque()
        self.lock = threading.Condition()
        self.alive = True
        threading.Thread(target=self._feed, name="piecs-bayes-draw", daemon=True).start()

    def submit(self, job: _Job) -> None:
        with self.lock:
            if not self.alive:
                raise RuntimeError("the drawing helper has stopped")
            self.queue.append(job)
            self.lock.notify()

    def take(self, job: _Job) -> bool:
        """Take `job` back if the helper has not started it."""
        with self.lock:
            try:
                self.queue.remove(job)
                return True
            except ValueError:
                return False

    def _feed(self) -> None:
        try:
            while True:
                with self.lock:
                    while not self.queue and self.alive:
                        self.lock.wait()
                    if not self.alive:
                        return
                    job = self.queue.pop()  # the newest: the caller needs the oldest first
                try:
                    self.proc.stdin.write(len(job.request).to_bytes(8, "little") + job.request)
                    self.proc.stdin.flush()
                    head = self.proc.stdout.read(9)
                    body = self.proc.stdout.read(int.from_bytes(head[1:], "little"))
                    if len(head) == 9 and head[:1] == b"\x00":
                        job.png = body
                    elif len(head) < 9:  # the helper died: every job is drawn here
                        self.stop()
                except (OSError, ValueError):
                    self.stop()
                job.done.set()
        finally:  # the helper's end: its pipes closed, the process reaped
            self.stop()
            try:
                self.proc.wait(10)
            except Exception:  # noqa: BLE001 - does not exit: killed
                self.proc.kill()
                self.proc.wait()
            self.proc.stdout.close()

    def stop(self) -> None:
        """No more jobs: those queued are left to the caller; the helper exits once
        its stdin is closed."""
        with self.lock:
            self.alive = False
            left, self.queue = list(self.queue), type(self.queue)()
            self.lock.notify_all()
        for job in left:
            job.done.set()
        try:
            self.proc.stdin.close()
        except (OSError, ValueError):
            pass


_HELPER: _Helper | None | bool = None
_HELPER_LOCK = threading.Lock()


def _helper() -> _Helper | None:
    """The helper (started once per process, on first use), or None where drawing here
    is all there is: one core, ``PIECS_BAYES_DRAW_HELPER=0``, or no process started."""
    global _HELPER
    if os.environ.get(HELPER_ENV, "1") == "0" or _cores() < 2:
        return None
    with _HELPER_LOCK:
        if _HELPER is None:
            try:
                _HELPER = _Helper()
                import atexit

                atexit.register(_HELPER.stop)
            except OSError:
                _HELPER = False
        return (_HELPER or None) if (_HELPER and _HELPER.alive) else None


def start_helper() -> None:
    """Start the helper now (a caller that will draw later: its interpreter and
    matplotlib load while the caller computes)."""
    _helper()


class Drawing:
    """A figure's PNG, being drawn: `png()` waits for it (or draws it here)."""

    def __init__(self, fig, how: tuple, job: _Job | None = None, helper=None):
        self._fig, self._how, self._job, self._helper = fig, how, job, helper
        self._png: bytes | None = None

    def png(self) -> bytes:
        if self._png is None:
            self._png = self._collect()
            self._fig = self._job = None  # the pixels are all that is kept
        return self._png

    def _collect(self) -> bytes:
        job = self._job
        if job is not None and not self._helper.take(job):  # started in the helper
            job.done.wait()
            if job.png is not None:
                return job.png
        from matplotlib import rc_context

        rc, dpi = self._how
        with rc_context(rc):
            return png_bytes(self._fig, dpi)


class Rasteriser:
    """Draws figures into PNG (`png_bytes`), in the helper process where it can.

    `draw(fig)` returns a `Drawing` at once. The helper takes the newest drawing
    queued, and `Drawing.png()` draws here any it has not started: a caller that
    queues figures as it makes them and then needs them in that order draws from the
    front while the helper works from the back. Every figure is drawn under the rc
    settings of `rc` (the rcParams the figures were made with), at `dpi`."""

    def __init__(self, rc, dpi: float | None = None):
        self._how = (_style(rc), dpi)
        self._helper = _helper()

    def draw(self, fig) -> Drawing:
        helper = self._helper
        if helper is not None:
            try:
                job = _Job(pickle.dumps((pickle.dumps(fig), *self._how)))
                helper.submit(job)
                return Drawing(fig, self._how, job, helper)
            except (pickle.PicklingError, AttributeError, TypeError):
                pass  # a local function in the figure (a formatter): drawn here
            except RuntimeError:  # the helper has stopped
                self._helper = None
        return Drawing(fig, self._how)
