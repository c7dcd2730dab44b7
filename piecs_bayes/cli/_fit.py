"""``piecs-bayes fit``, ``compensate`` and ``simulate``: one part's fit and adjusted
tool path, and the simulated data sets."""

from __future__ import annotations

from pathlib import Path

from . import _types as T
from ._common import add_common, fit_from_args, out_dir, subcommand, write
from ._outputs import bayes_from_args, print_fit, write_bayes, write_bounds, write_fit

__all__ = ["register"]

EXAMPLES = {
    "fit": "piecs-bayes fit data/demo/study.toml --out reports/fit --method robust",
    "compensate": "piecs-bayes compensate data/demo/study.toml --out reports/comp",
    "simulate": "piecs-bayes simulate demo --out data/demo --seed 20261123",
}


def register(sub) -> None:
    """Add ``fit``, ``compensate`` and ``simulate`` to the CLI's subparsers."""
    p = subcommand(
        sub,
        "fit",
        "Fit each feature's deviation from the probe points; write JSON and CSV.",
        EXAMPLES["fit"],
    )
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
    add_common(p)
    p.set_defaults(func=cmd_fit)

    p = subcommand(
        sub,
        "compensate",
        "Fit, mirror the deviations and write the adjusted tool-path vertices.",
        EXAMPLES["compensate"],
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
    add_common(p)
    p.set_defaults(func=cmd_compensate)

    p = subcommand(
        sub,
        "simulate",
        "Write simulated data sets with known truth (demo part, batch run).",
        EXAMPLES["simulate"],
    )
    p.add_argument("which", choices=("demo", "batch"), help="which data set")
    p.add_argument("--parts", type=T.positive_int, default=36, help="batch: number of parts")
    add_common(p)
    p.set_defaults(func=cmd_simulate)


def cmd_fit(args, console) -> int:
    study, probe, fit = fit_from_args(args, console)
    out = out_dir(args, study)
    written: list[Path] = []
    write_fit(out, study, fit, console, written)
    print_fit(fit, console)
    if (args.method or study.fit.method) == "bayes":
        bayes = bayes_from_args(args, study, probe, fit, console)
        write_bayes(out, study, bayes, console, written)
        console.say(bayes.posterior.summary())
    for p in written:
        console.say(f"wrote {p}")
    return 0


def cmd_compensate(args, console) -> int:
    from ..export import path_csv, write_compensation_outputs
    from ..jobs import compensate_study

    study, probe, fit = fit_from_args(args, console)
    path = compensate_study(study, fit, gain=args.gain)
    console.step(f"adjusted tool path: {path!r}")
    out = out_dir(args, study)
    written: list[Path] = []
    write_fit(out, study, fit, console, written)
    write(out, "toolpath.csv", path_csv(path), study, console, written)
    bayes = None
    if (args.method or study.fit.method) == "bayes":
        bayes = bayes_from_args(args, study, probe, fit, console)
        write_bayes(out, study, bayes, console, written)
    gain = study.compensation.gain if args.gain is None else args.gain
    write_bounds(out, study, probe, fit, bayes, gain, console, written)
    files = write_compensation_outputs(  # error spec, LinuxCNC tables, tool offsets
        study, fit, out, gain=args.gain, protect=[study.path, *study.probe_files]
    )
    written += files.written
    for line in files.lines():
        console.say(line)
    if args.program_out is not None:
        from ..jobs import adjust_study_program

        adj = adjust_study_program(study, path, nose_radius=args.nose_radius)
        console.step(f"adjusted program: {adj!r}")
        write(args.program_out.parent, args.program_out.name, adj.text, study, console, written)
        diff = args.program_out.with_name(args.program_out.name + ".diff")
        write(diff.parent, diff.name, adj.diff, study, console, written)
    for p in written:
        console.say(f"wrote {p}")
    return 0


def cmd_simulate(args, console) -> int:
    from ..jobs import simulate

    out = args.out or Path("data") / args.which
    if args.which == "demo":
        simulate.write_demo(out, seed=args.seed or 20261123)
    else:
        simulate.write_batch(out, n_parts=args.parts, seed=args.seed or 7)
    console.say(f"wrote simulated {args.which} data to {out}")
    return 0
