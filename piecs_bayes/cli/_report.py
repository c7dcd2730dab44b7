"""``piecs-bayes report``: run the main job on a study and write the report.

- ``report STUDY --out DIR [--part P] [--no-bayes] [--steps N] [--nose-radius R]
  [--apply ROUTE]`` runs `piecs_bayes.jobs.run_job` (robust and Bayesian fit,
  decisions, adjusted tool path with its bounds, adjusted program, error spec and
  tool offsets, capability when the probe data hold several parts) with progress
  shown, and writes ``report.html`` (one self-contained file) and ``report.pdf``.

``piecs-bayes demo`` runs the same job and also writes every results table and the
machine files of one route (``--apply``; ``--alternatives`` adds the others,
marked), then says what to load. Errors: bad input exits 2, a failed analysis
exits 1.
"""

from __future__ import annotations

from pathlib import Path

from . import _types as T
from ._common import add_apply, add_common, finish, out_dir, prefetch_imports, subcommand, write
from ._outputs import print_fit, write_bayes, write_fit, write_unc

EXAMPLE_DEMO = "piecs-bayes demo data/demo/study.toml --out reports/demo"
EXAMPLE = (
    "piecs-bayes report data/demo/study.toml --out reports/demo-report --nose-radius 0.4\n"
    "  piecs-bayes report data/batch/study.toml --out reports/batch --no-bayes"
)


def job_options(p, *, alternatives: bool = False) -> None:
    """The options of the main job shared by ``report`` and ``demo`` (which writes
    machine files, and so takes `--alternatives`)."""
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
    add_apply(p, alternatives=alternatives)


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
        "tool path with bounds, the machine files of one route: adjusted program, error spec "
        "or tool offsets, report), list what it wrote and say what to load on the machine.",
        EXAMPLE_DEMO,
    )
    p.add_argument("study", type=Path, help="study file (TOML)")
    job_options(p, alternatives=True)
    add_common(p)
    p.set_defaults(func=cmd_demo)


def run_job_from_args(args, console):
    """Run the main job with the CLI's options and progress on the console."""
    from ..errors import InputError
    from ..export.raster import start_helper
    from ..jobs import JobOptions, run_job

    prefetch_imports()  # the report's and posterior.nc's modules, while the job runs
    start_helper()  # the process that draws the report's figures, loading meanwhile

    if args.steps is not None and args.steps < 100:
        raise InputError(f"--steps: got {args.steps}, expected at least 100", value=args.steps)
    options = JobOptions(
        bayes=not args.no_bayes,
        nsteps=args.steps,
        seed=args.seed,
        nose_radius=args.nose_radius,
        tool_table=args.tool_table,
        apply=args.apply,
    )
    return run_job(
        args.study,
        options,
        part=args.part,
        progress=False if console.quiet else console.step,
    )


def write_report(res, out: Path, console, written: list) -> None:
    """Write ``report.html`` and ``report.pdf`` of `res` into `out`."""
    from ..export.report import report_files
    from ..io import write_bytes_atomic, write_text_atomic

    console.step("drawing the report figures, then writing report.html and report.pdf")
    text, pdf = report_files(res)
    inputs = [f.path for f in res.inputs]
    written.append(write_text_atomic(out / "report.html", text, protect=inputs))
    written.append(write_bytes_atomic(out / "report.pdf", pdf, protect=inputs))
    console.step(f"wrote the report ({len(pdf) / 1e6:.1f} MB PDF)")


def cmd_report(args, console) -> int:
    res = run_job_from_args(args, console)
    out = out_dir(args, res.study)
    written: list[Path] = []
    write_report(res, out, console, written)
    for step, why in res.unavailable.items():
        console.say(f"{step}: not available: {why}")
    console.say(
        f"route to the machine: {res.apply} ({res.apply_why}); `piecs-bayes demo` or "
        "`compensate` writes its files"
    )
    finish(console, out, written)
    return 0


def cmd_demo(args, console) -> int:
    """The main job end to end: every results table, the machine files of one route
    and the report."""
    from ..export.tables import decisions_csv, decisions_json, decisions_text, path_csv

    console.say(f"piecs-bayes demo on {args.study}")
    res = run_job_from_args(args, console)
    study, fit = res.study, res.fit
    out = out_dir(args, study)
    console.step(f"writing the results to {out}")
    print_fit(fit, console)
    written: list[Path] = []
    write_fit(out, study, fit, console, written)
    if res.bayes is not None:
        write_bayes(out, study, res.bayes, console, written)
        console.say(res.bayes.posterior.summary())
    machine = _machine_files(args, res, out, console)
    written += machine.written
    if res.decisions is not None:
        doc = decisions_json(res.decisions, apply=machine.as_dict())
        write(out, "decisions.json", doc, study, console, written)
        write(out, "decisions.csv", decisions_csv(res.decisions), study, console, written)
        console.say(decisions_text(res.decisions))
    if res.path is not None:
        write(out, "toolpath.csv", path_csv(res.path), study, console, written)
    if res.uncertainty is not None:
        write_unc(out, study, res.uncertainty, console, written)
    write_report(res, out, console, written)
    for step, why in res.unavailable.items():
        console.say(f"{step}: not available: {why}")
    finish(console, out, written, machine)
    return 0


def _machine_files(args, res, out: Path, console):
    """The chosen route's machine files (and the alternatives, on request)."""
    from ..export.machine import write_machine_files
    from ..jobs import APPLY_ROUTES, machine_data

    unavailable, data = {}, None
    if "program" in res.unavailable:
        unavailable["program"] = res.unavailable["program"]
    if res.errspec is None:
        why = res.unavailable.get("errspec", "the job made no error spec")
        unavailable.update(errspec=why, tool_offset=why)
    else:
        routes = APPLY_ROUTES if args.alternatives else (res.apply,)
        data = machine_data(res.study, res.fit, gain=dict(res.gains), routes=routes)
    machine = write_machine_files(
        res.study, data, out, route=res.apply, why=res.apply_why,
        alternatives=args.alternatives, program=res.program, unavailable=unavailable,
        protect=[f.path for f in res.inputs],
    )  # fmt: skip
    if "program" in machine.files:
        console.say(res.program.diff)
    for line in machine.lines():
        console.say(line)
    return machine
