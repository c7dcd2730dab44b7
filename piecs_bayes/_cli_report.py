"""``piecs-bayes report``: run the main job on a study and write the report.

- ``report STUDY --out DIR [--part P] [--no-bayes] [--steps N] [--nose-radius R]``
  runs :func:`piecs_bayes.workflow.run_job` (robust and Bayesian fit, decisions,
  adjusted tool path with its bounds, adjusted program, error spec and tool
  offsets, capability when the probe data hold several parts) with progress
  shown, and writes ``report.html`` (one self-contained file) and ``report.pdf``.

``piecs-bayes demo`` (in ``cli.py``) runs the same job and also writes every
results table. Errors: bad input exits 2, a failed analysis exits 1.
"""

from __future__ import annotations

from pathlib import Path

from . import _cli_types as T

__all__ = ["register", "job_options", "run_job_from_args", "write_report"]

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
    """Add ``report`` to the CLI's subparsers."""
    from .cli import _add_common, _sub

    p = _sub(
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
    _add_common(p)
    p.set_defaults(func=cmd_report)


def run_job_from_args(args, console):
    """Run the main job with the CLI's options and progress on the console."""
    from .errors import InputError
    from .workflow import run_job

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
    from .export import write_bytes_atomic, write_text_atomic
    from .export._report import report_files

    console.step("drawing the report")
    text, pdf = report_files(res)
    inputs = [f.path for f in res.inputs]
    written.append(write_text_atomic(out / "report.html", text, protect=inputs))
    written.append(write_bytes_atomic(out / "report.pdf", pdf, protect=inputs))


def cmd_report(args, console) -> int:
    from .cli import _out_dir

    res = run_job_from_args(args, console)
    out = _out_dir(args, res.study)
    written: list[Path] = []
    write_report(res, out, console, written)
    for step, why in res.unavailable.items():
        console.say(f"{step}: not available: {why}")
    for p in written:
        console.say(f"wrote {p}")
    return 0
