"""Figures drawn into PNG in the helper process (`export.raster`): the same pixels as
drawn here, whichever process draws them; a figure that cannot be pickled, a helper
that is switched off or dies, and the caller's own script (never run again by the
helper)."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from matplotlib import rc_context
from matplotlib.figure import Figure
from matplotlib.ticker import FuncFormatter
from PIL import Image

from piecs_bayes.export import raster
from piecs_bayes.export.figures import RC

ROOT = Path(__file__).resolve().parents[2]
needs_helper = pytest.mark.skipif(
    raster._cores() < 2 or os.environ.get(raster.HELPER_ENV) == "0",
    reason="the helper runs only with two cores or more",
)


def _figure(seed: int, formatter=None) -> Figure:
    """Lines, translucent fills, text with non-ASCII glyphs and a legend."""
    rng = np.random.default_rng(seed)
    fig = Figure(figsize=(5.0, 3.0), layout="constrained")
    ax = fig.add_subplot()
    x = np.linspace(0.0, 1.0, 200)
    for k in range(3):
        ax.plot(x, np.cumsum(rng.normal(size=x.size)), label=f"chain {k}", alpha=0.6)
    ax.fill_between(x, -2.0, 2.0, alpha=0.2, label="± 2 σ")
    ax.set_title(f"figure {seed}: Δ in µm")
    ax.legend()
    if formatter is not None:
        ax.xaxis.set_major_formatter(formatter)
    return fig


def _pixels(png: bytes) -> np.ndarray:
    return np.asarray(Image.open(io.BytesIO(png)).convert("RGB"), dtype=int)


def _here(seed: int, formatter=None) -> np.ndarray:
    """The pixels of `_figure(seed)` drawn in this process (a fresh figure: a figure
    drawn twice may be laid out anew)."""
    with rc_context(RC):
        return _pixels(raster.png_bytes(_figure(seed, formatter), 100.0))


@needs_helper
def test_the_helper_draws_the_pixels_this_process_draws():
    with rc_context(RC):
        r = raster.Rasteriser(__import__("matplotlib").rcParams, 100.0)
        figs = [_figure(s) for s in range(3)]
        drawings = [r.draw(f) for f in figs]
    assert r._helper is not None
    for d in drawings:  # let the helper finish every one: none is drawn here
        assert d._job.done.wait(120)
        assert d._job.png is not None
    for s, d in enumerate(drawings):
        assert np.array_equal(_pixels(d.png()), _here(s))


@needs_helper
def test_a_figure_the_helper_has_not_started_is_drawn_here():
    with rc_context(RC):
        r = raster.Rasteriser(__import__("matplotlib").rcParams, 100.0)
        with r._helper.lock:  # the helper's feeder waits: nothing is started
            drawings = [r.draw(_figure(10 + s)) for s in range(4)]
            first = drawings[0]
            pixels = [_pixels(first.png())]  # taken back from the queue, drawn here
            assert first._job is None and all(d._job in r._helper.queue for d in drawings[1:])
    pixels += [_pixels(d.png()) for d in drawings[1:]]  # the helper's (or here)
    for s, p in enumerate(pixels):
        assert np.array_equal(p, _here(10 + s))


def test_an_unpicklable_figure_is_drawn_here():
    label = FuncFormatter(lambda v, _: f"{v:.1f} mm")  # a local function
    with rc_context(RC):
        d = raster.Rasteriser(__import__("matplotlib").rcParams, 100.0).draw(_figure(20, label))
    assert d._job is None
    assert np.array_equal(_pixels(d.png()), _here(20, label))


def test_switched_off_no_helper(monkeypatch):
    monkeypatch.setenv(raster.HELPER_ENV, "0")
    with rc_context(RC):
        r = raster.Rasteriser(__import__("matplotlib").rcParams, 100.0)
        d = r.draw(_figure(30))
    assert r._helper is None and d._job is None
    assert d.png().startswith(b"\x89PNG\r\n\x1a\n")


@needs_helper
def test_a_helper_that_dies_leaves_the_drawing_here(monkeypatch):
    helper = raster._Helper()
    monkeypatch.setattr(raster, "_HELPER", helper)
    helper.proc.kill()
    helper.proc.wait(30)
    with rc_context(RC):
        r = raster.Rasteriser(__import__("matplotlib").rcParams, 100.0)
        d = r.draw(_figure(40))
    assert d._job.done.wait(60)  # handed to the dead helper, not taken back here
    assert d._job.png is None and not helper.alive  # stopped: later figures drawn here
    assert np.array_equal(_pixels(d.png()), _here(40))
    assert raster._helper() is None


SCRIPT = """
import matplotlib
from matplotlib.figure import Figure
from piecs_bayes.export import raster
print("RUN", flush=True)
fig = Figure(figsize=(2, 2))
fig.add_subplot().plot([0, 1], [1, 0])
d = raster.Rasteriser(matplotlib.rcParams, 50.0).draw(fig)
assert d._job is not None, "no helper"
d._job.done.wait(120)
assert d.png().startswith(bytes([137, 80, 78, 71]))
print("PNG", "helper" if d._job is None else "", flush=True)
"""


@needs_helper
def test_the_callers_script_is_not_run_again(tmp_path):
    """A script without `if __name__ == "__main__"` (multiprocessing's spawn would run
    it again in the helper, job and all)."""
    script = tmp_path / "user_script.py"
    script.write_text(SCRIPT)
    env = {**os.environ, "PYTHONPATH": str(ROOT), "MPLBACKEND": "Agg"}
    out = subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, env=env, timeout=300
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.count("RUN") == 1 and "PNG" in out.stdout
