"""``piecs-bayes plan STUDY``: where to probe, and the gauging program that does it.

Per feature the least points that reach the tolerance-to-U ratio (``--ratio``,
default ``[plan] ratio`` or 4) or ``--points N``, placed for the characteristic's
uncertainty (``piecs_bayes.jobs._plan``); ``--more FIT_DIR`` plans the extra points
that the "measure more" verdicts of a ``fit``/``decide`` folder ask for, beside the
points that folder's part was probed at. Writes ``plan.json``, the gauging program
(``gauging.ngc`` for LinuxCNC, ``gauging_fanuc.nc`` for Fanuc) and ``plan.png``.
"""

from __future__ import annotations

import argparse
import warnings
from pathlib import Path

from . import _types as T


def register(subparsers) -> None:
    """Add ``plan`` to the CLI's subparsers."""
    p = subparsers.add_parser(
        "plan",
        help="Design the probe points of a study and write the gauging program.",
        description="Design where to probe every feature of a study (for the uncertainty of "
        "the characteristic the decision uses), the safe moves between the points, and the "
        "gauging program for LinuxCNC (G38.2, PROBEOPEN) or Fanuc (G31, DPRNT).",
        epilog="examples:\n  piecs-bayes plan study.toml --out plan\n"
        "  piecs-bayes plan study.toml --points 6 --controller fanuc --out plan\n"
        "  piecs-bayes plan study.toml --more out/demo --out plan_more",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("study", type=Path, help="the study file (.toml)")
    how = p.add_mutually_exclusive_group()
    how.add_argument("--points", type=T.positive_int, default=None, help="points per feature")
    how.add_argument(
        "--ratio",
        type=T.positive_float,
        default=None,
        help="the tolerance-to-U ratio to reach (tolerance span / 2U; default [plan] ratio, 4)",
    )
    how.add_argument(
        "--more",
        type=Path,
        default=None,
        metavar="FIT_DIR",
        help="plan the extra points of the 'measure more' verdicts in FIT_DIR/decisions.json",
    )
    p.add_argument("--controller", choices=("linuxcnc", "fanuc"), default=None)
    p.add_argument(
        "--strict",
        action="store_true",
        help="refuse a plan that leaves a feature out (default: plan the features the probe "
        "reaches and list the others as not measured, with the settings that reach them)",
    )
    p.add_argument("--out", type=Path, default=Path("plan"), help="output folder (default plan)")
    p.add_argument("--quiet", "-q", action="store_true", help="print only errors")
    p.set_defaults(func=cmd_plan)


def cmd_plan(args, console) -> int:
    from ..export.machine import write_plan
    from ..io import load_study, read_more_points
    from ..jobs import plan_more, plan_study

    study = load_study(args.study)
    if args.more is not None:
        more, probed = read_more_points(args.more)
        if not more:
            console.say(f"{args.more}: no 'measure more' verdict with a count: nothing to plan")
            return 0
        plan = plan_more(study, more, probed, controller=args.controller)
    else:
        plan = plan_study(
            study, points=args.points, ratio=args.ratio, controller=args.controller,
            strict=args.strict,
        )  # fmt: skip
    written = write_plan(plan, args.out, protect=[args.study])
    ratio = plan.settings.ratio
    console.say(
        f"{study.name}: {plan.n_points} points, predicted gauging time {plan.time_s:.0f} s "
        f"({plan.travel_mm:.0f} mm of travel)"
        + ("" if args.points or args.more else f"; target ratio {ratio:g}:1")
    )
    console.say(f"  {'feature':<12} {'n':>3} {'u um':>7} {'uniform':>8} {'ratio':>6}")
    for f in plan.features:
        d, u = f.designed, f.uniform
        console.say(
            f"  {f.feature:<12} {d.n:>3} {d.u * 1e3:>7.2f} {u.u * 1e3:>8.2f} {d.ratio:>5.1f}:1"
        )
    for u in plan.unreachable:
        console.say(f"  {u.feature:<12} {'-':>3} not measured (the probe cannot reach it)")
    for u in plan.unreachable:  # on stderr, --quiet or not
        warnings.warn(
            f"{args.study}: not measured: {u.message} (--strict makes this an error)",
            stacklevel=1,
        )
    for p in written:
        console.say(f"wrote {p}")
    return 0
