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
        "ring, diameter or face pair; write probe_cal.json.",
        EXAMPLE,
    )
    p.add_argument("cal", type=Path, help="the calibration file (TOML, docs/formats.md)")
    p.add_argument("--out", type=Path, required=True, help="the probe_cal.json to write")
    p.add_argument(
        "--method", choices=("lsq", "bayes"), default="lsq",
        help="lsq: Huber least squares (default); bayes: the posterior (emcee)",
    )  # fmt: skip
    p.add_argument(
        "--orders", default=None, help="auto, 0 (one radius), 2 or 2,3 (default: the file's)"
    )
    p.add_argument("--seed", type=int, default=0, help="bayes: the sampler's seed")
    p.add_argument("--quiet", "-q", action="store_true", help="print only errors")
    p.set_defaults(func=cmd_calibrate_probe)


def _um(v: float) -> str:
    return f"{v * 1e3:8.2f}"


def cmd_calibrate_probe(args, console) -> int:
    from ..fit import repeatability_check
    from ..io import read_calibration_file, write_text_atomic
    from ..jobs import calibrate_probe, parse_orders_option

    orders = parse_orders_option(args.orders)
    spec = read_calibration_file(args.cal)
    protect = [args.cal, *spec.inputs]
    if any(Path(args.out).resolve() == Path(p).resolve() for p in protect):
        raise InputError("--out is an input of the calibration: refusing to write over it",
                         file=str(args.out))  # fmt: skip
    cal = calibrate_probe(args.cal, method=args.method, orders=orders, seed=args.seed)
    path = write_text_atomic(args.out, cal.to_json_text(), protect=protect)
    sd = [math.sqrt(max(v, 0.0)) for v in cal.cov.diagonal()]
    console.say(f"{cal.probe}: {cal.n_points} points, orders {list(cal.orders) or 'none'} "
                f"({args.method}), dof {cal.dof:g}")  # fmt: skip
    console.say(f"  {'coefficient':<12} {'value mm':>10} {'u um':>8}")
    for name, v, u in zip(cal.names, cal.coefficients, sd, strict=True):
        value = f"{v:10.5f}" if name == "r0" else f"{v * 1e3:7.2f} um"
        console.say(f"  {name:<12} {value:>10} {_um(u)}")
    console.say(f"  probing error {_um(cal.probing_error)} um (range of r over the directions)")
    console.say(f"  residual sd   {_um(cal.residual_sd)} um (declared {_um(spec.repeatability)})")
    msg = repeatability_check(cal, spec.repeatability)
    if msg:
        warnings.warn(msg, stacklevel=1)
    console.say(f"wrote {path}")
    return 0
