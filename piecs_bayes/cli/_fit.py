"""``piecs-bayes fit``, ``compensate`` and ``simulate``: one part's fit and adjusted
tool path, and the simulated data sets."""

from __future__ import annotations

from pathlib import Path

from ..errors import InputError
from . import _types as T
from ._common import add_apply, add_common, finish, fit_from_args, out_dir, subcommand, write
from ._outputs import bayes_from_args, print_fit, write_bayes, write_bounds, write_fit

EXAMPLES = {
    "fit": "piecs-bayes fit data/demo/study.toml --out reports/fit --method robust",
    "compensate": "piecs-bayes compensate data/demo/study.toml --out reports/comp",
    "simulate": "piecs-bayes simulate demo --out data/demo --seed 20261123\n"
    "  piecs-bayes simulate gauge reports/plan/gauging.ngc --study data/demo/study.toml "
    "--truth data/demo/truth.json --out probe_points.txt\n"
    "  piecs-bayes simulate calibration --out data/cal --seed 3",
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
        help="default: the study's fit.method; bayes: robust fit, then the posterior (MCMC)",
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
        "Fit, mirror the deviations and write the adjusted tool-path vertices and the "
        "machine files of one route (--apply).",
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
        help="route 'program': write the adjusted part program here (and FILE.diff) instead "
        "of OUT/<stem>_adjusted<suffix>; never the input",
    )
    p.add_argument(
        "--nose-radius",
        type=T.positive_mm,
        default=None,
        help="tool-nose radius (mm) for the gouge check (default: the study's [program])",
    )
    add_apply(p)
    add_common(p)
    p.set_defaults(func=cmd_compensate)

    p = subcommand(
        sub,
        "simulate",
        "Write simulated data sets with known truth (demo part, batch run, probe "
        "calibration on a sphere), or run a "
        "gauging program on a simulated machine (gauge) and write the control's probe file.",
        EXAMPLES["simulate"],
    )
    p.add_argument(
        "which", choices=("demo", "batch", "gauge", "calibration"), help="which data set"
    )
    p.add_argument("program", nargs="?", type=Path, default=None, help="gauge: the gauging program")
    p.add_argument("--study", type=Path, default=None, help="gauge: the study (TOML)")
    p.add_argument(
        "--truth", type=Path, default=None, help="gauge: the truth (deviations, as truth.json)"
    )
    p.add_argument(
        "--repeatability",
        type=T.nonneg_mm,
        default=None,
        help="gauge, calibration: the probe's repeatability sd along the move (mm; default: "
        "the study's; calibration: 0.0015)",
    )
    p.add_argument(
        "--pretravel",
        type=T.mm_or_file,
        default=None,
        metavar="MM|PROBE_CAL",
        help="gauge: the trigger comes this much further along the move (mm; default 0), or "
        "a lobing probe: a probe_cal.json whose r(theta) the simulated probe has (its "
        "pretravel is the study's ball radius minus r(theta) at each approach)",
    )
    p.add_argument(
        "--fanuc-x-mode",
        choices=("diameter", "radius"),
        default=None,
        help="gauge, Fanuc: the control's X mode (default: the study's [plan] x_mode)",
    )
    p.add_argument(
        "--log-out",
        type=Path,
        default=None,
        help="gauge, LinuxCNC: also write the (LOGOPEN,...) file of the program's LOG lines",
    )
    p.add_argument(
        "--full-circle",
        action="store_true",
        help="calibration: probe the sphere from all around (24 directions over 360 "
        "degrees); default: the half a lathe reaches on a sphere on the spindle axis, from "
        "+X and both sides along Z (24 directions from -90 to +90 degrees about +X)",
    )
    p.add_argument("--parts", type=T.positive_int, default=36, help="batch: number of parts")
    p.add_argument(
        "--points",
        type=T.positive_int,
        default=None,
        help="batch: probe points per feature (default: 6-10 per feature, as the demo part; "
        "e.g. 512 for a scanning probe)",
    )
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
    from ..export.tables import path_csv
    from ..jobs import apply_route, compensate_study

    study, probe, fit = fit_from_args(args, console)
    route, why = apply_route(study, args.apply)
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
    console.step("tool-path uncertainty (GUM" + (", Monte Carlo)" if bayes else ")"))
    write_bounds(out, study, probe, fit, bayes, gain, console, written)
    machine = _machine_files(args, study, fit, path, out, route, why, console)
    written += machine.written
    finish(console, out, written, machine)
    return 0


def _machine_files(args, study, fit, path, out, route, why, console):
    """The route's machine files (and the alternatives, on request); the adjusted
    program only when the route or the alternatives need it."""
    from ..errors import PiecsError
    from ..export.machine import write_machine_files
    from ..jobs import APPLY_ROUTES, adjust_study_program, machine_data

    adj, unavailable = None, {}
    if study.program is None:
        unavailable["program"] = "the study names no part program (study.part_program)"
    elif route == "program" or args.alternatives:
        try:
            output = None if args.program_out is None else str(args.program_out)
            adj = adjust_study_program(study, path, nose_radius=args.nose_radius, output=output)
        except PiecsError as exc:
            if route == "program":
                raise
            unavailable["program"] = str(exc)
        else:
            console.step(f"adjusted program: {adj!r}")
    inputs = [study.path, *study.probe_files] + ([study.program] if study.program else [])
    routes = APPLY_ROUTES if args.alternatives else (route,)
    data = machine_data(study, fit, gain=args.gain, routes=routes)
    machine = write_machine_files(
        study, data, out, route=route, why=why, alternatives=args.alternatives, program=adj,
        program_path=args.program_out, unavailable=unavailable, protect=inputs,
    )  # fmt: skip
    for line in machine.lines():
        console.say(line)
    return machine


def cmd_simulate(args, console) -> int:
    from .. import simulate

    if args.which == "gauge":
        return _simulate_gauge(args, console)
    if args.program is not None:
        raise InputError(
            f"simulate {args.which} takes no program (got {str(args.program)!r}); "
            "did you mean 'simulate gauge'?"
        )
    out = args.out or Path("data") / args.which
    if args.which == "calibration":
        from ..simulate import write_calibration_sim

        rep = 0.0015 if args.repeatability is None else args.repeatability
        circle = "full" if args.full_circle else "lathe"
        for p in write_calibration_sim(out, seed=args.seed, repeatability=rep, directions=circle):
            console.say(f"wrote {p}")
        return 0
    if args.which == "demo":
        simulate.write_demo(out, seed=args.seed or 20261123)
    else:
        simulate.write_batch(out, n_parts=args.parts, seed=args.seed or 7, points=args.points)
    console.say(f"wrote simulated {args.which} data to {out}")
    return 0


def _simulate_gauge(args, console) -> int:
    from ..io import load_study, read_probe_calibration
    from ..simulate import simulate_gauge

    for value, what in ((args.program, "PROGRAM"), (args.study, "--study STUDY"),
                        (args.truth, "--truth TRUTH"), (args.out, "--out FILE")):  # fmt: skip
        if value is None:
            raise InputError(f"simulate gauge needs {what}")
    for path, what in ((args.program, "gauging program"), (args.truth, "truth file")):
        if not path.is_file():
            raise InputError(f"{what} not found" if not path.exists() else "is a folder, "
                             f"not a {what}", file=str(path))  # fmt: skip
    study = load_study(args.study)
    console.step(f"read {study!r}")
    rep = study.probe.repeatability if args.repeatability is None else args.repeatability
    pretravel = args.pretravel
    if isinstance(pretravel, Path):
        from ..jobs import lobing_pretravel

        pretravel = lobing_pretravel(read_probe_calibration(pretravel), study.probe.ball_radius)
    run = simulate_gauge(
        args.program, study, args.truth, repeatability=rep, seed=args.seed,
        pretravel=pretravel, x_mode_fanuc=args.fanuc_x_mode,
    )  # fmt: skip
    console.step(f"ran {run!r}")
    keep = [args.program, args.truth, study.path]
    path = run.write(args.out, protect=keep)
    console.say(f"wrote {path}")
    if args.log_out is not None:
        if not run.log_file:
            raise InputError("the program opens no log ((LOGOPEN,...)): --log-out has nothing "
                             "to write", file=str(args.program))  # fmt: skip
        console.say(f"wrote {run.write_log(args.log_out, protect=[*keep, args.out])}")
    return 0
