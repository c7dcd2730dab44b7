"""``piecs-bayes``: one command per user job; a thin layer over the public API.

Exit codes: 0 ok, 1 the analysis failed (no convergence, a gouge, a correction
above the limit), 2 bad input (a file, a cell, a setting) or usage.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

from . import _cli_types as T
from .errors import AnalysisError, InputError

__all__ = ["main", "build_parser"]

EXAMPLES = {
    "fit": "piecs-bayes fit data/demo/study.toml --out reports/fit --method robust",
    "compensate": "piecs-bayes compensate data/demo/study.toml --out reports/comp",
    "simulate": "piecs-bayes simulate demo --out data/demo --seed 20261123",
    "demo": "piecs-bayes demo data/demo/study.toml --out reports/demo",
}


class _Console:
    def __init__(self, quiet: bool):
        self.quiet = quiet
        self.t0 = time.perf_counter()

    def say(self, msg: str) -> None:
        if not self.quiet:
            print(msg, flush=True)

    def step(self, msg: str) -> None:
        if not self.quiet:
            print(f"[{time.perf_counter() - self.t0:6.1f} s] {msg}", flush=True)


def _add_common(p: argparse.ArgumentParser, *, out: bool = True) -> None:
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


def _sub(sub, name: str, help_: str) -> argparse.ArgumentParser:
    return sub.add_parser(
        name,
        help=help_,
        description=help_,
        epilog=f"example:\n  {EXAMPLES[name]}" if name in EXAMPLES else None,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )


def build_parser() -> argparse.ArgumentParser:
    from . import __version__

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

    p = _sub(sub, "fit", "Fit each feature's deviation from the probe points; write JSON and CSV.")
    p.add_argument("study", type=Path, help="study file (TOML)")
    p.add_argument(
        "--method",
        choices=("lsq", "robust", "bayes"),
        default=None,
        help="default: the study's fit.method; bayes: robust fit, then the posterior (emcee)",
    )
    p.add_argument(
        "--steps", type=T.positive_int, default=None, help="bayes: MCMC steps per ensemble"
    )
    p.add_argument("--part", default=None, help="part id when the probe data holds several parts")
    _add_common(p)
    p.set_defaults(func=cmd_fit)

    p = _sub(
        sub, "compensate", "Fit, mirror the deviations and write the adjusted tool-path vertices."
    )
    p.add_argument("study", type=Path, help="study file (TOML)")
    p.add_argument(
        "--method",
        choices=("lsq", "robust", "bayes"),
        default=None,
        help="default: the study's fit.method; bayes adds Monte Carlo bounds from the posterior",
    )
    p.add_argument(
        "--steps", type=T.positive_int, default=None, help="bayes: MCMC steps per ensemble"
    )
    p.add_argument("--part", default=None, help="part id when the probe data holds several parts")
    p.add_argument(
        "--gain", type=T.gain, default=None, help="feedback gain in [0, 1] (default: the study's)"
    )
    p.add_argument(
        "--program-out",
        type=Path,
        default=None,
        help="write the adjusted part program here (and FILE.diff); never the input",
    )
    p.add_argument(
        "--nose-radius",
        type=T.positive_mm,
        default=None,
        help="tool-nose radius (mm) for the gouge check (default: the study's [program])",
    )
    _add_common(p)
    p.set_defaults(func=cmd_compensate)

    p = _sub(sub, "simulate", "Write simulated data sets with known truth (demo part, batch run).")
    p.add_argument("which", choices=("demo", "batch"), help="which data set")
    p.add_argument("--parts", type=T.positive_int, default=36, help="batch: number of parts")
    _add_common(p)
    p.set_defaults(func=cmd_simulate)

    p = _sub(
        sub,
        "demo",
        "Run the main job on a study end to end (robust and Bayesian fit, decisions, adjusted "
        "tool path with bounds, adjusted program, error spec, tool offsets, report) and list "
        "what it wrote.",
    )
    p.add_argument("study", type=Path, help="study file (TOML)")
    from ._cli_report import job_options

    job_options(p)
    _add_common(p)
    p.set_defaults(func=cmd_demo)

    for module in _plugins():
        module.register(sub)
    return parser


def _plugins():
    """Command groups that live in their own modules (``register(subparsers)``)."""
    import importlib

    for name in ("_cli_gcode", "_cli_decide", "_cli_report"):
        try:
            yield importlib.import_module(f".{name}", __package__)
        except ModuleNotFoundError as exc:
            if exc.name != f"{__package__}.{name}":
                raise


def _out_dir(args, study) -> Path:
    if args.out is not None:
        return args.out
    return Path("reports") / study.path.stem


def _write(out: Path, name: str, text: str, study, console: _Console, written: list) -> Path:
    from .export import write_text_atomic

    inputs = [study.path, *study.probe_files] + ([study.program] if study.program else [])
    path = write_text_atomic(out / name, text, protect=inputs)
    written.append(path)
    return path


def _fit(args, console):
    from .pipeline import fit_study, load_study

    study = load_study(args.study)
    console.step(f"read {study!r}")
    method = args.method or study.fit.method
    fit = fit_study(study, method="robust" if method == "bayes" else method, part=args.part)
    console.step(f"fitted {len(fit.fits)} features ({fit.method})")
    return study, fit


def _bayes(args, study, fit, console):
    from .pipeline import bayes_study

    console.step("sampling the posterior (emcee)")
    bayes = bayes_study(study, fit, nsteps=args.steps, seed=args.seed, progress=not args.quiet)
    post = bayes.posterior
    console.step(
        f"posterior: {len(bayes.names)} parameters, "
        f"{'converged' if post.converged else 'NOT converged'}, "
        f"{post.ess_per_second:.0f} effective samples/s"
    )
    return bayes


def _write_bayes(out, study, bayes, console, written):
    from .export import posterior_csv

    _write(out, "posterior.csv", posterior_csv(bayes), study, console, written)
    from .export import write_file_atomic

    path = write_file_atomic(out / "posterior.nc", bayes.posterior.to_netcdf, protect=[study.path])
    written.append(path)


def _write_fit(out, study, fit, console, written):
    from .export import fit_csv, fit_json, residuals_csv

    _write(out, "fit.json", fit_json(fit, study=study), study, console, written)
    _write(out, "fit.csv", fit_csv(fit), study, console, written)
    _write(out, "residuals.csv", residuals_csv(fit), study, console, written)


def _print_fit(fit, console):
    console.say(
        f"{'feature':<12}{'parameter':<11}{'value':>14}{'std.unc.':>12}  outliers (file lines)"
    )
    for f in fit:
        lines = ", ".join(str(int(f.lines[i])) for i in f.outliers) or "-"
        se = f.std_errors if f.std_errors is not None else [float("nan")] * len(f.values)
        for k, (name, v, s) in enumerate(zip(f.param_names, f.values, se, strict=True)):
            unit = "rad" if name == "rotation" else "mm"
            console.say(
                f"{f.id if k == 0 else '':<12}{name:<11}{v:>+12.6f} {unit:<4}{s:>9.6f}  "
                + (lines if k == 0 else "")
            )
    if fit.unmeasured:
        console.say(f"not measured (left as drawn): {', '.join(fit.unmeasured)}")


def cmd_fit(args, console) -> int:
    study, fit = _fit(args, console)
    out = _out_dir(args, study)
    written: list[Path] = []
    _write_fit(out, study, fit, console, written)
    _print_fit(fit, console)
    if (args.method or study.fit.method) == "bayes":
        bayes = _bayes(args, study, fit, console)
        _write_bayes(out, study, bayes, console, written)
        console.say(bayes.posterior.summary())
    for p in written:
        console.say(f"wrote {p}")
    return 0


def _write_bounds(out, study, fit, bayes, gain, console, written):
    from .pipeline import toolpath_uncertainty

    unc = toolpath_uncertainty(study, fit, bayes=bayes, gain=gain)
    for tpu in unc.values():
        if tpu is not None:
            console.step(f"tool-path bounds: {tpu!r}")
    _write_unc(out, study, unc, console, written)
    return unc


def _write_unc(out, study, unc, console, written):
    from .export import band_csv, bounds_csv, bounds_json, budget_csv

    for key, tpu in unc.items():
        if tpu is None:
            continue
        suffix = "" if key == "linearised" else "_mc"
        _write(out, f"toolpath_bounds{suffix}.csv", bounds_csv(tpu), study, console, written)
        _write(
            out, f"toolpath_band{suffix}.csv", band_csv(tpu, study.profile), study, console, written
        )
    _write(
        out,
        "uncertainty_budget.csv",
        budget_csv(unc["linearised"], study.profile),
        study,
        console,
        written,
    )
    _write(out, "toolpath_bounds.json", bounds_json(unc, study.profile), study, console, written)


def cmd_compensate(args, console) -> int:
    from .decisions import write_compensation_outputs
    from .export import path_csv
    from .pipeline import compensate_study

    study, fit = _fit(args, console)
    path = compensate_study(study, fit, gain=args.gain)
    console.step(f"adjusted tool path: {path!r}")
    out = _out_dir(args, study)
    written: list[Path] = []
    _write_fit(out, study, fit, console, written)
    _write(out, "toolpath.csv", path_csv(path), study, console, written)
    bayes = None
    if (args.method or study.fit.method) == "bayes":
        bayes = _bayes(args, study, fit, console)
        _write_bayes(out, study, bayes, console, written)
    gain = study.compensation.gain if args.gain is None else args.gain
    _write_bounds(out, study, fit, bayes, gain, console, written)
    files = write_compensation_outputs(  # error spec, LinuxCNC tables, tool offsets
        study, fit, out, gain=args.gain, protect=[study.path, *study.probe_files]
    )
    written += files.written
    for line in files.lines():
        console.say(line)
    if args.program_out is not None:
        from .pipeline import adjust_study_program

        adj = adjust_study_program(study, path, nose_radius=args.nose_radius)
        console.step(f"adjusted program: {adj!r}")
        _write(args.program_out.parent, args.program_out.name, adj.text, study, console, written)
        diff = args.program_out.with_name(args.program_out.name + ".diff")
        _write(diff.parent, diff.name, adj.diff, study, console, written)
    for p in written:
        console.say(f"wrote {p}")
    return 0


def cmd_simulate(args, console) -> int:
    from . import simulate

    out = args.out or Path("data") / args.which
    if args.which == "demo":
        simulate.write_demo(out, seed=args.seed or 20261123)
    else:
        simulate.write_batch(out, n_parts=args.parts, seed=args.seed or 7)
    console.say(f"wrote simulated {args.which} data to {out}")
    return 0


def cmd_demo(args, console) -> int:
    """The main job end to end: every results table, the machine files and the report."""
    from ._cli_report import run_job_from_args, write_report
    from .decisions import write_compensation_outputs
    from .export import path_csv, write_text_atomic

    console.say(f"piecs-bayes demo on {args.study}")
    res = run_job_from_args(args, console)
    study, fit = res.study, res.fit
    _print_fit(fit, console)
    out = _out_dir(args, study)
    written: list[Path] = []
    _write_fit(out, study, fit, console, written)
    if res.bayes is not None:
        _write_bayes(out, study, res.bayes, console, written)
        console.say(res.bayes.posterior.summary())
    if res.decisions is not None:
        _write(out, "decisions.json", res.decisions.to_json(), study, console, written)
        _write(out, "decisions.csv", res.decisions.to_csv(), study, console, written)
        console.say(res.decisions.text())
    if res.path is not None:
        _write(out, "toolpath.csv", path_csv(res.path), study, console, written)
    if res.uncertainty is not None:
        _write_unc(out, study, res.uncertainty, console, written)
    if res.program is not None:
        inputs = [f.path for f in res.inputs]
        stem, suffix = study.program.stem, study.program.suffix
        for name, text in (
            (f"{stem}_adjusted{suffix}", res.program.text),
            (f"{stem}.diff", res.program.diff),
        ):
            written.append(write_text_atomic(out / name, text, protect=inputs))
        console.say(res.program.diff)
    if res.errspec is not None:
        files = write_compensation_outputs(  # error spec, LinuxCNC tables, tool offsets
            study, fit, out, gain=dict(res.gains), protect=[f.path for f in res.inputs]
        )
        written += files.written
        for line in files.lines():
            console.say(line)
    write_report(res, out, console, written)
    for step, why in res.unavailable.items():
        console.say(f"{step}: not available: {why}")
    console.step(f"done; outputs in {out}:")
    for p in written:
        console.say(f"  {p}")
    return 0


class Terminated(BaseException):
    """SIGTERM, raised where the program is, so that temporaries are removed."""


def _on_sigterm(signum, frame):
    raise Terminated()


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


def main(argv=None) -> int:
    """Run one command; every failure is one line on stderr and an exit code:
    0 ok, 1 the analysis failed, 2 bad input or usage (argparse), 130 interrupted
    (Ctrl-C), 143 terminated (SIGTERM). ``--debug`` shows the traceback instead."""
    import signal
    import traceback
    import warnings

    os.environ.setdefault("MPLBACKEND", "Agg")
    parser = build_parser()
    args = parser.parse_args(argv)
    debug = bool(getattr(args, "debug", False))
    console = _Console(getattr(args, "quiet", False))
    previous = None
    try:
        previous = signal.signal(signal.SIGTERM, _on_sigterm)
    except ValueError:  # not the main thread (e.g. called from a worker): leave it
        previous = None
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("default")  # shown once each, as one line; never fatal
            warnings.showwarning = _show_warning
            return int(args.func(args, console) or 0)
    except (InputError, AnalysisError) as exc:
        if debug:
            traceback.print_exc()
        bad_input = isinstance(exc, InputError)
        _say_error("error" if bad_input else "analysis failed", str(exc))
        return 2 if bad_input else 1
    except KeyboardInterrupt:
        _say_error("interrupted", "stopped by Ctrl-C; no partial output was left")
        return 130
    except Terminated:
        _say_error("terminated", "stopped by SIGTERM; no partial output was left")
        return 143
    except BrokenPipeError:
        # the reader of our output went away (`| head`): quiet, and no second error at exit
        try:
            devnull = os.open(os.devnull, os.O_WRONLY)
            os.dup2(devnull, sys.stdout.fileno())
        except (OSError, ValueError):
            pass
        _say_error("stopped", "standard output was closed (broken pipe)")
        return 1
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
        if previous is not None:
            signal.signal(signal.SIGTERM, previous)


if __name__ == "__main__":
    sys.exit(main())
