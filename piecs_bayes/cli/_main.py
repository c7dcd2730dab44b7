"""The command line: the parser of every command, and `main` (errors as one line and
an exit code)."""

from __future__ import annotations

import argparse
import gc
import os
import signal
import sys
import time

from ..errors import AnalysisError, InputError
from . import _decide, _feedback, _fit, _gauge_study, _gcode, _init, _plan, _probe_cal, _report
from ._common import Console


def build_parser() -> argparse.ArgumentParser:
    from .. import __version__

    parser = argparse.ArgumentParser(
        prog="piecs-bayes",
        description="Uncertainty-aware process-intermittent error compensation for turning.",
        epilog=(
            "Exit codes: 0 ok, 1 analysis failed, 2 bad input. See docs/formats.md for the files."
        ),
    )
    parser.add_argument("--version", action="version", version=f"piecs-bayes {__version__}")
    parser.add_argument("--debug", action="store_true", help="show tracebacks instead of one line")
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    sub.required = True

    for module in (
        _init,
        _plan,
        _probe_cal,
        _fit,
        _decide,
        _gcode,
        _report,
        _feedback,
        _gauge_study,
    ):
        module.register(sub)
    return parser


class Terminated(BaseException):
    """SIGTERM, raised where the program is, so that temporaries are removed."""


def _swallowed_at(frame) -> bool:
    """Whether an exception raised at `frame` would be printed and ignored: code run by
    the garbage collector (a `gc.callbacks` entry, such as JAX's, or a `__del__`)."""
    codes = {getattr(cb, "__code__", None) for cb in gc.callbacks}
    while frame is not None:
        if frame.f_code in codes or frame.f_code.co_name == "__del__":
            return True
        frame = frame.f_back
    return False


def _importing_at(frame) -> bool:
    """Whether `frame` runs inside an import (a module's top-level code, an extension's
    initialisation): an exception raised there can come out as another error (NumPy's
    extension turns it into an ImportError and prints its traceback, a class being
    made into a RuntimeError from `__set_name__`) and leaves the module's file open."""
    while frame is not None:
        if frame.f_code.co_filename.startswith("<frozen importlib._bootstrap"):
            return True
        frame = frame.f_back
    return False


#: seconds a stop waits at most for an import to end (one that hangs still stops)
_IMPORT_WAIT = 5.0


def _stop(exc_type, frame, since: float | None = None):
    """Raise `exc_type` where the program is, or, when that code would swallow it (a
    signal handled inside a GC callback after a long compiled call: the sampler's
    loop) or change it (inside an import: a Ctrl-C while `fit` imports JAX), 50 ms
    later from a SIGALRM, again until it can be raised, so that the job still stops
    and unwinds."""
    since = time.monotonic() if since is None else since
    waiting = _importing_at(frame) and time.monotonic() - since < _IMPORT_WAIT
    if _swallowed_at(frame) or waiting:
        signal.signal(signal.SIGALRM, lambda s, f: _stop(exc_type, f, since))
        signal.setitimer(signal.ITIMER_REAL, 0.05)
        return
    raise exc_type()


def _on_sigterm(signum, frame):
    _stop(Terminated, frame)


def _on_sigint(signum, frame):
    _stop(KeyboardInterrupt, frame)


def _show_warning(message, category, filename, lineno, file=None, line=None):
    print(f"piecs-bayes: warning: {message}", file=sys.stderr, flush=True)


def _say_error(prefix: str, msg: str) -> None:
    try:
        print(f"piecs-bayes: {prefix}: {msg}", file=sys.stderr, flush=True)
    except (BrokenPipeError, OSError):
        pass


def _os_error(exc: OSError) -> str:
    where = f"{exc.filename}: " if exc.filename else ""
    what = {
        PermissionError: "permission denied",
        FileNotFoundError: "not found",
        IsADirectoryError: "is a folder, expected a file",
        NotADirectoryError: "a parent of this path is a file, not a folder",
        FileExistsError: "exists and is not a folder",
    }.get(type(exc), exc.strerror or str(exc))
    return f"{where}{what}"


#: exit status of a command whose reader closed standard output: 128 + SIGPIPE, as a
#: Unix tool killed by the signal reports it (`| head -1`)
_BROKEN_PIPE = 128 + signal.SIGPIPE


_INTERRUPTED = ("interrupted", "stopped by Ctrl-C; no partial output was left")
_TERMINATED = ("terminated", "stopped by SIGTERM; no partial output was left")


def _leave(code: int, message: tuple[str, str] | None = None) -> None:
    """End the program now with `code`, its output flushed: every file it wrote is
    closed and renamed into place by then. A Ctrl-C or SIGTERM that comes while it
    leaves is the user's word all the same: 130 or 143 and its one line. The
    interpreter's teardown is skipped: it frees JAX's and matplotlib's objects one by
    one (1 s after a demo, 0.2 s after a `fit`), and after a signal XLA's threads may
    still be inside a computation the signal cut short, which crashed the teardown
    (SIGSEGV instead of 130/143); its atexit callbacks could be interrupted too."""
    late: list[int] = []
    for sig, late_code in ((signal.SIGINT, 130), (signal.SIGTERM, 143)):
        try:
            signal.signal(sig, lambda s, f, c=late_code: late.append(c))
        except ValueError:  # not the main thread
            pass
    if message is not None:
        _say_error(*message)
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    if late and code not in (130, 143):
        code = late[0]
        _say_error(*(_INTERRUPTED if code == 130 else _TERMINATED))
    os._exit(code)


def main(argv=None) -> int:
    """Run one command and return its exit code; the program itself (``argv`` None,
    the console script and ``python -m piecs_bayes.cli``) ends there (`_leave`), its
    signal handlers kept to the last instruction."""
    if argv is not None:
        return _run(argv, restore=True)
    try:
        _leave(_run(None, restore=False))
    except KeyboardInterrupt:  # outside the command's own handling: as it returned
        _leave(130, _INTERRUPTED)
    except Terminated:
        _leave(143, _TERMINATED)
    return 0  # not reached: _leave ends the program


def _run(argv, *, restore: bool) -> int:
    """Run one command; every failure is one line on stderr and an exit code:
    0 ok, 1 the analysis failed, 2 bad input or usage (argparse), 130 interrupted
    (Ctrl-C), 143 terminated (SIGTERM), 141 (no message) when the reader of standard
    output went away (`| head -1`). ``--debug`` shows the traceback instead."""
    import traceback
    import warnings

    os.environ.setdefault("MPLBACKEND", "Agg")
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = bool(getattr(args, "debug", False))
    console = Console(getattr(args, "quiet", False))
    previous = None
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
        if signal.getsignal(signal.SIGINT) is signal.default_int_handler:
            signal.signal(signal.SIGINT, _on_sigint)  # Ctrl-C as before, never swallowed
    except ValueError:  # not the main thread (e.g. called from a worker): leave it
        previous = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default")  # shown once each, as one line; never fatal
            # but not the interpreter's note of a file left open, hidden by Python's own
            # defaults: never about the user's files (a Ctrl-C inside an import leaves
            # the module's .pyc open, and its note came before the one line of 130)
            warnings.simplefilter("ignore", ResourceWarning)
            warnings.showwarning = _show_warning
            return int(args.func(args, console) or 0)
    except (InputError, AnalysisError) as exc:
        if debug:
            traceback.print_exc()
        bad_input = isinstance(exc, InputError)
        _say_error("error" if bad_input else "analysis failed", str(exc))
        return 2 if bad_input else 1
    except KeyboardInterrupt:
        _say_error(*_INTERRUPTED)
        return 130
    except Terminated:
        _say_error(*_TERMINATED)
        return 143
    except BrokenPipeError:
        # the reader of our output went away (`| head -1`): stop quietly as Unix tools do,
        # with 128 + SIGPIPE and no message; standard output goes to /dev/null so that
        # the interpreter's flush at exit does not print "Exception ignored ..."
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        return _BROKEN_PIPE
    except UnicodeDecodeError as exc:
        if debug:
            raise
        _say_error("error", f"a file is not valid {exc.encoding} text (byte {exc.start}): {exc}")
        return 2
    except OSError as exc:
        if debug:
            raise
        _say_error("error", _os_error(exc))
        return 2
    except Exception as exc:  # noqa: BLE001 - the last line of defence: one line, exit 1
        if debug:
            raise
        _say_error(
            "internal error",
            f"{type(exc).__name__}: {exc} (please report it; rerun with --debug for the traceback)",
        )
        return 1
    finally:
        if previous is not None and restore:
            signal.signal(signal.SIGTERM, previous)
            if signal.getsignal(signal.SIGINT) is _on_sigint:
                signal.signal(signal.SIGINT, signal.default_int_handler)
