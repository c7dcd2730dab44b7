"""``piecs-bayes calibrate-probe CAL --out probe_cal.json``: a probe's effective radius
by approach direction from a calibration run on a certified artefact."""

from __future__ import annotations

import math
import warnings
from pathlib import Path

from ..errors import InputError
from ._common import subcommand

EXAMPLE = "piecs-bayes calibrate-probe data/cal/calibration.toml --out probe_cal.json"


def register(sub) -> None:
    """Add ``calibrate-probe`` to the CLI's subparsers."""
    p = subcommand(
        sub,
        "calibrate-probe",
        "Fit the probe's effective radius r(theta) = r0 + orders 2, 3 on a certified sphere, "
        "ring, diameter or face pair; write probe_cal.json. With orders auto, the orders "
        "are chosen by the uncertainty of r(theta) they give at the directions the parts "
        "are probed from (--plan, --directions; default the lathe's +X, +Z, -X, -Z).",
        EXAMPLE,
    )
    p.add_argument("cal", type=Path, help="the calibration file (TOML, docs/formats.md)")
    p.add_argument("--out", type=Path, required=True, help="the probe_cal.json to write")
    p.add_argument(
        "--method", choices=("lsq", "bayes"), default="lsq",
        help="lsq: Huber least squares (default); bayes: the posterior (emcee)",
    )  # fmt: skip
    p.add_argument(
        "--orders", default=None,
        help="auto, 0 (one radius), a2 (one radius per axis: r0 + a2 cos 2 theta, e.g. a ring "
        "with a face pair), 2, 3 or 2,3 (default: the file's)",
    )  # fmt: skip
    p.add_argument(
        "--plan", type=Path, default=None,
        help="auto: a probe plan of the parts (plan.json, `piecs-bayes plan`); its points' "
        "approach directions are where the orders are judged",
    )  # fmt: skip
    p.add_argument(
        "--directions", default=None, metavar="DEG,DEG,...",
        help="auto: the approach angles (degrees, atan2(a_z, a_x) of the ball's travel: 180 a "
        "diameter from +X, 90 and -90 faces, 0 a bore) where the orders are judged "
        "(default: 0,90,180,-90, the lathe's axis approaches)",
    )  # fmt: skip
    p.add_argument("--seed", type=int, default=0, help="bayes: the sampler's seed")
    p.add_argument("--quiet", "-q", action="store_true", help="print only errors")
    p.set_defaults(func=cmd_calibrate_probe)


def _um(v: float) -> str:
    return f"{v * 1e3:8.2f}"


def cmd_calibrate_probe(args, console) -> int:
    from ..fit import direction_check, repeatability_check
    from ..io import read_calibration_file, write_text_atomic
    from ..jobs import calibrate_probe, parse_directions_option, parse_orders_option

    orders = parse_orders_option(args.orders)
    directions = parse_directions_option(args.directions, args.plan)
    spec = read_calibration_file(args.cal)
    protect = [args.cal, *spec.inputs]
    if any(Path(args.out).resolve() == Path(p).resolve() for p in protect):
        raise InputError("--out is an input of the calibration: refusing to write over it",
                         file=str(args.out))  # fmt: skip
    cal = calibrate_probe(args.cal, method=args.method, orders=orders, seed=args.seed,
                          directions=directions)  # fmt: skip
    path = write_text_atomic(args.out, cal.to_json_text(), protect=protect)
    _summary(cal, args.method, spec.repeatability, console)
    for msg in (direction_check(cal, directions), repeatability_check(cal, spec.repeatability)):
        if msg:
            warnings.warn(f"{args.cal}: {msg}", stacklevel=1)
    console.say(f"wrote {path}")
    return 0


def _summary(cal, method: str, repeatability: float, console) -> None:
    """The coefficients, how auto chose the orders, the probing error, the residual sd."""
    import numpy as np  # not at import: `--help` stays light

    sd = [math.sqrt(max(v, 0.0)) for v in cal.cov.diagonal()]
    model = "r0 + a2 cos 2 theta (one radius per axis)" if cal.fixed else (
        f"orders {list(cal.orders) or 'none'}")  # fmt: skip
    console.say(f"{cal.probe}: {cal.n_points} points, {model} ({method}), dof {cal.dof:g}")
    if cal.orders_choice:
        _choice(cal.orders_choice, console)
    console.say(f"  {'coefficient':<12} {'value mm':>10} {'u um':>8}")
    for name, v, u in zip(cal.names, cal.coefficients, sd, strict=True):
        value = f"{v:10.5f}" if name == "r0" else f"{v * 1e3:7.2f} um"
        held = "  (held at 0)" if name in cal.fixed else ""
        console.say(f"  {name:<12} {value:>10} {_um(u)}{held}")
    if cal.fixed:
        x, z = cal.radius(np.radians([0.0, 90.0])), cal.radius_u(np.radians([0.0, 90.0]))
        console.say(f"  r along X    {x[0]:10.5f} {_um(z[0])}")
        console.say(f"  r along Z    {x[1]:10.5f} {_um(z[1])}")
    console.say(f"  probing error {_um(cal.probing_error)} um (range of r over the directions)")
    console.say(f"  residual sd   {_um(cal.residual_sd)} um (declared {_um(repeatability)})")


def _choice(choice: dict, console) -> None:
    """Why auto chose the orders: each candidate's u of r at the targets."""
    import numpy as np

    deg, count = np.unique(np.round(choice["targets_deg"], 2), return_counts=True)
    shown = [f"{d:g}" + (f" (x{c})" if c > 1 else "") for d, c in zip(deg, count, strict=True)]
    more = ", ..." if len(shown) > 12 else ""
    console.say(f"  orders auto: the u of r(theta) at {', '.join(shown[:12])}{more} degrees "
                f"({choice['targets_from']}), at the declared repeatability:")  # fmt: skip
    console.say(f"    {'model':<44} {'u um':>8} {'own u':>8} {'shift':>8}")
    for row in choice["candidates"]:
        mark = "  <- chosen" if row["orders"] == choice["chosen"] else ""
        console.say(f"    {row['model']:<44} {_um(row['u_mm'])} {_um(row['u_model_mm'])} "
                    f"{_um(row['shift_mm'])}{mark}")  # fmt: skip
    console.say("    (u: rms over the targets, with the shift of the terms a model omits and "
                "its u; own u: if the model held)")  # fmt: skip
