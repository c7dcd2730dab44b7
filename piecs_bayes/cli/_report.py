"""``piecs-bayes report``: run the main job on a study and write the report.

- ``report STUDY --out DIR [--part P] [--no-bayes] [--steps N] [--nose-radius R]``
  runs `piecs_bayes.jobs.run_job` (robust and Bayesian fit, decisions,
  adjusted tool path with its bounds, adjusted program, error spec and tool
  offsets, capability when the probe data hold several parts) with progress
  shown, and writes ``report.html`` (one self-contained file) and ``report.pdf``.

``piecs-bayes demo`` runs the same job and also writes every results table.
Errors: bad input exits 2, a failed analysis exits 1.
"""

from __future__ import annotations

from pathlib import Path

from . import _types as T
from ._common import add_common, out_dir, subcommand, write
from ._outputs import print_fit, write_bayes, write_fit, write_unc

__all__ = ["register", "job_options", "run_job_from_args", "write_report"]

EXAMPLE_DEMO = "piecs-bayes demo data/demo/study.toml --out reports/demo"
EXAMPLE = (
    "piecs-bayes report data/demo/study.toml --out reports/demo-report --nose-radius 0.4\n"
    "  piecs-bayes report data/batch/study.toml --out reports/batch --no-bayes"
)


def job_options(p) -> None:
    """The options of the main job shared by ``report`` and ``demo``."""
    p.add_argument("--part", default=None, help="part id when the probe data holds several parts")
    p.add_argument(
        "--no-bayes", action="store_true", help="skip the Bayesian fit (and Monte Carlo bounds)"
    )
    p.add_argument(
        "--steps",
        type=T.positive_int,
        default=None,
        help="MCMC steps per ensemble (default: the study's fit.bayes_steps)",
    )
    p.add_argument(
        "--nose-radius",
        type=T.positive_mm,
        default=None,
        help="tool nose radius (mm) to check the adjusted program for gouges "
        "(default: the study's program.nose_radius, else offsets.current_r)",
    )
    p.add_argument(
        "--tool-table", type=Path, default=None, help="LinuxCNC tool table (.tbl, mm) instead"
    )


def register(subparsers) -> None:
    """Add ``report`` and ``demo`` to the CLI's subparsers."""
    p = subcommand(
        subparsers,
        "report",
        "Run the main job on a study and write report.html (self-contained) and report.pdf.",
    )
    p.epilog = (
        f"example:\n  {EXAMPLE}\n\nThe report: summary per feature, profile and adjusted "
        "tool path with bands,\nresiduals, posterior diagnostics, uncertainty budget, "
        "capability (several parts),\nprogram diff, error spec and offsets, inputs with "
        "SHA-256 hashes and versions."
    )
    p.add_argument("study", type=Path, help="study file (TOML)")
    job_options(p)
    add_common(p)
    p.set_defaults(func=cmd_report)

    p = subcommand(
        subparsers,
        "demo",
        "Run the main job on a study end to end (robust and Bayesian fit, decisions, adjusted "
        "tool path with bounds, adjusted program, error spec, tool offsets, report) and list "
        "what it wrote.",
        EXAMPLE_DEMO,
    )
    p.add_argument("study", type=Path, help="study file (TOML)")
    job_options(p)
    add_common(p)
    p.set_defaults(func=cmd_demo)


def run_job_from_args(args, console):
    """Run the main job with the CLI's options and progress on the console."""
    from ..errors import InputError
    from ..jobs import run_job

    if args.steps is not None and args.steps < 100:
        raise InputError(f"--steps: got {args.steps}, expected at least 100", value=args.steps)
    return run_job(
        args.study,
        part=args.part,
        bayes=not args.no_bayes,
        nsteps=args.steps,
        seed=args.seed,
        nose_radius=args.nose_radius,
        tool_table=args.tool_table,
        progress=False if console.quiet else console.step,
    )


def write_report(res, out: Path, console, written: list) -> None:
    """Write ``report.html`` and ``report.pdf`` of `res` into `out`."""
    from ..export import report_files
    from ..io import write_bytes_atomic, write_text_atomic

    console.step("drawing the report")
    text, pdf = report_files(res)
    inputs = [f.path for f in res.inputs]
    written.append(write_text_atomic(out / "report.html", text, protect=inputs))
    written.append(write_bytes_atomic(out / "report.pdf", pdf, protect=inputs))


def cmd_report(args, console) -> int:
    res = run_job_from_args(args, console)
    out = out_dir(args, res.study)
    written: list[Path] = []
    write_report(res, out, console, written)
    for step, why in res.unavailable.items():
        console.say(f"{step}: not available: {why}")
    for p in written:
        console.say(f"wrote {p}")
    return 0


def cmd_demo(args, console) -> int:
    """The main job end to end: every results table, the machine files and the report."""
    from ..export import (
        decisions_csv,
        decisions_json,
        decisions_text,
        path_csv,
        write_compensation_outputs,
    )
    from ..io import write_text_atomic

    console.say(f"piecs-bayes demo on {args.study}")
    res = run_job_from_args(args, console)
    study, fit = res.study, res.fit
    print_fit(fit, console)
    out = out_dir(args, study)
    written: list[Path] = []
    write_fit(out, study, fit, console, written)
    if res.bayes is not None:
        write_bayes(out, study, res.bayes, console, written)
        console.say(res.bayes.posterior.summary())
    if res.decisions is not None:
        write(out, "decisions.json", decisions_json(res.decisions), study, console, written)
        write(out, "decisions.csv", decisions_csv(res.decisions), study, console, written)
        console.say(decisions_text(res.decisions))
    if res.path is not None:
        write(out, "toolpath.csv", path_csv(res.path), study, console, written)
    if res.uncertainty is not None:
        write_unc(out, study, res.uncertainty, console, written)
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
