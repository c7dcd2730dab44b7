"""What every command shares: the console, the common options, the output folder and
the protected writer (never an input file), the fit of one part from the options,
the route to the machine (`--apply`, `--alternatives`) and the closing lines."""

from __future__ import annotations

import argparse
import re
import time
import unicodedata
from pathlib import Path

from . import _types as T


class Console:
    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def say(self, msg: str) -> None:
        if not self.quiet:
            print(msg, flush=True)

    def step(self, msg: str) -> None:
        if not self.quiet:
            print(f"[{time.perf_counter() - self.t0:6.1f} s] {msg}", flush=True)


#: what the report and posterior.nc import late, loaded while the sampler runs
#: (arviz with xarray 1.2 s, matplotlib's backends 0.2 s: 7 % of a warm demo)
_LATE_IMPORTS = (
    "arviz",
    "matplotlib.figure",
    "matplotlib.backends.backend_agg",
    "matplotlib.backends.backend_pdf",
)


def prefetch_imports(names=_LATE_IMPORTS):
    """Import `names` in a background thread: the sampler's compiled loop releases the
    GIL, so they load while it runs instead of after it. Best effort: a failure here is
    left for the import where the module is used, which reports it. arviz's import
    notice is silenced here, in the caller's thread (`quiet_arviz_notice`), as
    `import_arviz` silences it: without it, the thread's import showed it as a warning
    whenever it ran outside the sampler's recorded warnings (a cold demo)."""
    import importlib
    import threading

    from ..fit.mcmc import quiet_arviz_notice

    quiet_arviz_notice()

    def load():
        for name in names:
            try:
                importlib.import_module(name)
            except BaseException:  # noqa: BLE001 - the real import reports it
                return

    thread = threading.Thread(target=load, name="piecs-bayes-prefetch", daemon=True)
    thread.start()
    return thread


def add_common(p: argparse.ArgumentParser, *, out: bool = True) -> None:
    if out:
        p.add_argument(
            "--out",
            type=Path,
            default=None,
            help="output folder (default: reports/<slug of the study's [study] name>)",
        )
    p.add_argument(
        "--seed", type=T.nonneg_int, default=0, help="random seed for anything stochastic"
    )
    p.add_argument("--quiet", "-q", action="store_true", help="print only errors")
    p.add_argument(
        "--debug", action="store_true", default=argparse.SUPPRESS,
        help="show the traceback of an error instead of one line",
    )  # fmt: skip


def subcommand(sub, name: str, help_: str, example: str | None = None) -> argparse.ArgumentParser:
    """A subcommand with its help as description and its example as epilog."""
    return sub.add_parser(
        name,
        help=help_,
        description=help_,
        epilog=f"example:\n  {example}" if example else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def slug(name: str) -> str:
    """`name` as a folder name: ASCII, lower case, words joined by `-`
    (``"Demo stepped shaft"`` -> ``"demo-stepped-shaft"``); `""` when nothing is left."""
    text = unicodedata.normalize("NFKD", str(name)).encode("ascii", "ignore").decode()
    return re.sub(r"[^a-z0-9]+", "-", text.lower()).strip("-")


def out_dir(args, study) -> Path:
    """`--out`, else ``reports/<slug of [study] name>`` (else of the file's stem), so
    that two studies both called study.toml write to different folders."""
    if args.out is not None:
        return args.out
    return Path("reports") / (slug(study.name) or slug(study.path.stem) or "study")


#: `io.APPLY_ROUTES`, spelled here so that building the parser imports no JAX
#: (`--help` at once); tests/cli/test_startup.py checks that the two agree
APPLY_ROUTES = ("program", "errspec", "tool_offset", "none")


def add_apply(p: argparse.ArgumentParser, *, alternatives: bool = True) -> None:
    """`--apply ROUTE` (and `--alternatives`): the one route to the machine."""
    p.add_argument(
        "--apply",
        choices=APPLY_ROUTES,
        default=None,
        help="the one route of the correction to the machine (default: the study's "
        "[compensation] apply, else 'program' when it names a part program, else "
        "'errspec'); only this route's files are written",
    )
    if alternatives:
        p.add_argument(
            "--alternatives",
            action="store_true",
            help="also write the other routes' files, each marked 'alternative: do not "
            "combine' (never load two routes: each carries the whole correction)",
        )


def finish(console: Console, out: Path, written: list, machine=None) -> None:
    """The closing lines: every file written (alternatives marked), what to load on
    the machine, and "done" last."""
    from ..export.machine import ALTERNATIVE

    console.say(f"wrote {len(written)} file(s) in {out}:")
    for p in written:
        mark = machine is not None and machine.is_alternative(p)
        console.say(f"  {p}" + (f"   ({ALTERNATIVE})" if mark else ""))
    if machine is not None:
        for line in machine.instructions():
            console.say(line)
    console.step("done")


def write(out: Path, name: str, text: str, study, console: Console, written: list) -> Path:
    from ..io import write_text_atomic

    inputs = [study.path, *study.probe_files] + ([study.program] if study.program else [])
    path = write_text_atomic(out / name, text, protect=inputs)
    written.append(path)
    return path


def fit_from_args(args, console):
    """`(study, probe, fit)`: the study, its probe data (read once, for every later
    step) and the fit of the part the options choose."""
    from ..io import load_study
    from ..jobs import fit_study, load_probe_data

    study = load_study(args.study)
    console.step(f"read {study!r}")
    probe = load_probe_data(study)
    method = args.method or study.fit.method
    method = "robust" if method == "bayes" else method
    fit = fit_study(study, probe, method=method, part=args.part)
    console.step(f"fitted {len(fit.fits)} features ({fit.method})")
    return study, probe, fit
