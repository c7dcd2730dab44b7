r"""Which orders a probe calibration fits, judged where the parts are probed.

[`choose_orders`][] (``orders = "auto"``) compares the candidates `AUTO_ORDERS` by the
standard uncertainty of $r(\theta)$ at the **target directions**, the approach angles
the parts are probed from (a plan's; by default `LATHE_DIRECTIONS`, +X, +Z, -X, -Z).
Each candidate nested in the richest one the directions separate (the reference) is
scored by the u it can honestly state there: its own, plus the shift its omitted terms
make (its estimate minus the reference's) and that shift's u, as an uncorrected
systematic effect (GUM F.2.4.5); the smallest rms u wins, the richer on a tie, at the
declared repeatability with the certificates' u, linearised at the nominal centre.
[`direction_check`][] warns when the directions span 180 degrees or less or leave a
target in a gap over 90 degrees, naming the missing directions, the u of r there and
the artefact that adds them. docs/uncertainty.md, section 5.
"""

from __future__ import annotations

import math

import numpy as np

from ..errors import InputError
from ..io import PER_AXIS, ProbeCalibration
from ._probe_cal_design import (
    CalibrationDesign,
    check_orders,
    model_label,
    model_terms,
    term_basis,
)

#: the candidates of ``orders="auto"``, richest first (ties go to the earlier)
AUTO_ORDERS = ((2, 3), (3,), (2,), PER_AXIS, ())
#: the target directions without a plan: the approaches a lathe probes a part along
#: (degrees: +X as in a bore, +Z, -X as on a diameter, -Z)
LATHE_DIRECTIONS = (0.0, 90.0, 180.0, -90.0)
#: the directions' span at or below which `direction_check` warns (degrees)
MIN_SPAN = 180.0
#: a target inside a gap between the calibration's directions wider than this
#: (degrees) is missing
MAX_GAP = 90.0
_AXIS_NAMES = {0.0: "+X", 90.0: "+Z", 180.0: "-X", -90.0: "-Z"}
_FROM_SIDE = {0.0: "the -X side", 90.0: "the -Z side", 180.0: "the +X side", -90.0: "the +Z side"}


def _candidates(design: CalibrationDesign, sigma_known: bool) -> list:
    """The candidates the directions separate and nested in the richest of them (the
    reference, first)."""
    ok = []
    for spec in AUTO_ORDERS:
        try:
            check_orders(design, spec, sigma_known=sigma_known)
        except InputError:
            if not spec and not ok:
                raise
            continue
        ok.append(spec)
    ref = set(model_terms(ok[0]))
    return [s for s in ok if set(model_terms(s)) <= ref]


def _target_map(design: CalibrationDesign, spec, theta) -> np.ndarray:
    """``(t, n)``: r at the target angles `theta` as a linear map of the data
    (least squares of the linearised model)."""
    x = design.rows(model_terms(spec))
    m = np.linalg.solve(x.T @ x, x.T)
    return term_basis(theta, model_terms(spec)) @ m[len(design.free) :]


def _score(w, w_ref, data, cov_y) -> dict:
    """One candidate's u at the targets (module docstring) from its map `w`."""
    d = w - w_ref
    var = np.einsum("ti,ij,tj->t", w, cov_y, w)
    shift = d @ data
    var_shift = np.einsum("ti,ij,tj->t", d, cov_y, d)
    u = np.sqrt(var + shift**2 + var_shift)
    return {
        "u_mm": float(np.sqrt(np.mean(u**2))), "u_model_mm": float(np.sqrt(np.mean(var))),
        "shift_mm": float(np.max(np.abs(shift))), "u_each_mm": [float(v) for v in u],
    }  # fmt: skip


def choose_orders(
    design: CalibrationDesign, sigma: float, *, targets_deg=None, sigma_known: bool = False
):
    """``orders = "auto"`` (module docstring): `(spec, choice)`, the chosen model and a
    JSON object of the targets and each candidate's score (u in mm: `u_mm` its rms
    over the targets, `u_model_mm` what it states if its model holds, `shift_mm` the
    largest shift of its omitted terms)."""
    given = targets_deg is not None
    targets = np.asarray(LATHE_DIRECTIONS if not given else targets_deg, dtype=float).ravel()
    if targets.size == 0 or not np.all(np.isfinite(targets)):
        raise InputError(f"target directions: expected finite angles (degrees), got "
                         f"{targets.tolist()}", value=targets.tolist())  # fmt: skip
    cands = _candidates(design, sigma_known)
    theta = np.radians(targets)
    onehot = design.size_onehot()
    cov_y = sigma**2 * np.eye(len(design)) + onehot @ np.diag(design.size_u**2) @ onehot.T
    data = design.nominal_data()
    w_ref = _target_map(design, cands[0], theta)
    rows = []
    for spec in cands:
        score = _score(_target_map(design, spec, theta), w_ref, data, cov_y)
        rows.append({"orders": _spec_json(spec), "model": model_label(spec)} | score)
    best = min(range(len(rows)), key=lambda i: (round(rows[i]["u_mm"] / rows[0]["u_mm"], 9), i))
    choice = {
        "rule": "the smallest rms u of r(theta) at the targets, each candidate's u with the "
        "shift of the terms it omits (against the richest the directions separate)",
        "targets_deg": [float(t) for t in targets],
        "targets_from": "given" if given else "the lathe's axis approaches (+X, +Z, -X, -Z)",
        "sigma_mm": float(sigma), "candidates": rows, "chosen": rows[best]["orders"],
    }  # fmt: skip
    return cands[best], choice


def _spec_json(spec):
    return spec if spec == PER_AXIS else list(spec)


def _wrap(deg):
    """Angles into (-180, 180] degrees."""
    return 180.0 - (180.0 - np.asarray(deg, dtype=float)) % 360.0


def _gaps(deg: np.ndarray) -> list[tuple[float, float]]:
    """The empty arcs ``(start, width)`` between the sorted distinct directions."""
    d = np.unique(np.round(np.asarray(deg, dtype=float) % 360.0, 6))
    nxt = np.r_[d[1:], d[0] + 360.0]
    return [(float(a), float(b - a)) for a, b in zip(d, nxt, strict=True)]


def _missing(deg, wanted) -> list[float]:
    """The `wanted` directions inside a gap wider than `MAX_GAP` (more than 1 degree
    from its ends)."""
    out = []
    for w in wanted:
        for start, width in _gaps(deg):
            inside = (w - start) % 360.0
            if width > MAX_GAP and 1.0 < inside < width - 1.0:
                out.append(float(_wrap(w)))
                break
    return list(dict.fromkeys(out))


def _name(deg: float) -> str:
    axis = _AXIS_NAMES.get(float(deg))
    if axis is None:
        return f"{deg:g} degrees"
    return f"{axis} ({deg:g} degrees: the ball travelling {axis}, from {_FROM_SIDE[deg]})"


def _advice(missing) -> str:
    along_x = any(abs(math.cos(math.radians(d))) >= abs(math.sin(math.radians(d))) for d in missing)
    along_z = any(abs(math.cos(math.radians(d))) < abs(math.sin(math.radians(d))) for d in missing)
    out = []
    if along_x:
        out.append("a ring gauge, probed from inside along +X and -X, adds the X approaches")
    if along_z:
        out.append("a face pair ([artefact.face]: two faces of a ring or diameter, probed "
                   "along +Z and -Z) adds the Z approaches")  # fmt: skip
    return "; ".join(out)


def direction_check(cal: ProbeCalibration, targets_deg=None) -> str | None:
    """A warning when `cal`'s approach directions span `MIN_SPAN` degrees or less or
    miss a target (module docstring); None otherwise or without directions. The
    targets: `targets_deg`, else those `auto` used, else `LATHE_DIRECTIONS`."""
    deg = np.asarray(cal.directions, dtype=float)
    if deg.size == 0:
        return None
    if targets_deg is None and cal.orders_choice:
        targets_deg = cal.orders_choice.get("targets_deg")
    targets = [float(t) for t in _wrap(LATHE_DIRECTIONS if targets_deg is None else targets_deg)]
    start, gap = max(_gaps(deg), key=lambda g: g[1])
    span = 360.0 - gap
    missing = _missing(deg, list(LATHE_DIRECTIONS) + targets)
    missed_targets = [t for t in targets if t in _missing(deg, targets)]
    if span > MIN_SPAN + 1e-6 and not missed_targets:
        return None
    lo = float(_wrap(start + gap))
    text = (f"the calibration's approach directions span {span:g} degrees ({lo:g} to "
            f"{lo + span:g})")  # fmt: skip
    if not missing:
        return text + ": the probe's lobing is confounded with the artefact's centre"
    u = cal.radius_u(np.radians(targets)) * 1e3
    at = ", ".join(f"{t:g}: {v:.2f}" for t, v in zip(targets, u, strict=True))
    return (f"{text}: none along {'; '.join(_name(m) for m in missing)}. There r(theta) "
            f"rests on the model alone; u(r) at the targets (degrees: um) {at}. "
            f"{_advice(missing)[0].upper()}{_advice(missing)[1:]}")  # fmt: skip
