"""What every command shares: the console, the common options, the output folder and
the protected writer (never an input file), the fit of one part from the options."""

from __future__ import annotations

import argparse
import time
from pathlib import Path

from . import _types as T

__all__ = ["Console", "add_common", "subcommand", "out_dir", "write", "fit_from_args"]


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


def add_common(p: argparse.ArgumentParser, *, out: bool = True) -> None:
    if out:
        p.add_argument(
            "--out", type=Path, default=None, help="output folder (default: reports/<study name>)"
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


def out_dir(args, study) -> Path:
    if args.out is not None:
        return args.out
    return Path("reports") / study.path.stem


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
