"""``piecs-bayes simulate calibration``: a probe calibration run on a certified sphere
with its truth.

The ball travels toward the sphere's nominal centre from `n_directions` directions in
the XZ plane: by default (`directions="lathe"`) the half a lathe reaches on a sphere
on the spindle axis, from +X and both sides along Z (approach angles 90 to 270
degrees, ends included), or the full circle (`"full"`). It stops where its centre is
at the effective radius r(theta) from the true sphere (centre off the nominal by
`centre_offset`, unknown to the fit), plus a normal error of sd `repeatability` along
the travel. The truth r(theta): r0 = `ball_radius` + `R0_OFFSET` and a 3-lobe term of
`lobe3` (1.5 um: a kinematic seat), no order 2; the sphere's diameter is the
certified one. Writes ``calibration.toml``, ``cal_points.csv`` (X as a radius, no
approach columns) and ``truth.json``.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from ..io import coefficient_names, lobe_basis, write_text_atomic

TRUTH_ORDERS = (2, 3)
#: `directions`: the half circle a lathe reaches, or the full circle
SPHERE_DIRECTIONS = ("lathe", "full")


def approach_angles(directions: str, n: int) -> np.ndarray:
    """The approach angles (rad) of `n` probe moves toward a sphere (module docstring)."""
    if directions == "lathe":
        return np.radians(180.0 + np.linspace(-90.0, 90.0, n))
    if directions == "full":
        return np.radians(np.arange(n) * 360.0 / n)
    raise ValueError(f"directions {directions!r}; expected one of {SPHERE_DIRECTIONS}")


R0_OFFSET = 0.004
"""mm: the simulated probe's r0 above its ball radius (its mean pretravel)."""


def simulate_calibration(
    *, seed: int = 0, n_directions: int = 24, diameter: float = 25.0004,
    centre=(0.0, -40.0), centre_offset=(0.012, -0.008), ball_radius: float = 3.0,
    lobe3: float = 0.0015, phase3_deg: float = 20.0,
    repeatability: float = 0.0015, directions: str = "lathe",
) -> dict:  # fmt: skip
    """The points and the truth (module docstring): ``{"points" (n, 2), "approach"
    (n, 2), "theta" (n,), "coefficients" (orders (2, 3)), "centre_true", ...}``."""
    rng = np.random.default_rng(seed)
    theta = approach_angles(directions, n_directions)
    a = np.c_[np.cos(theta), np.sin(theta)]
    ph = math.radians(phase3_deg)
    coef = np.array([ball_radius + R0_OFFSET, 0.0, 0.0, lobe3 * math.cos(ph), lobe3 * math.sin(ph)])
    r = lobe_basis(theta, TRUTH_ORDERS) @ coef
    c0 = np.asarray(centre, float)
    c = c0 + np.asarray(centre_offset, float)
    # ball centre on the line c0 - t a: |c0 - t a - c| = R + r(theta), the t before c0
    d = c0 - c
    b = a @ d
    rad = diameter / 2.0 + r
    t = b + np.sqrt(b * b - (d @ d) + rad * rad)
    t += rng.normal(0.0, repeatability, n_directions)
    points = c0 - t[:, None] * a
    return {
        "points": points, "approach": a, "theta": theta, "orders": TRUTH_ORDERS,
        "coefficients": coef, "centre_nominal": c0, "centre_true": c, "diameter": diameter,
        "repeatability": repeatability, "seed": seed, "directions": directions,
    }  # fmt: skip


def _toml(sim: dict, *, expanded: float, k: float) -> str:
    c = sim["centre_nominal"]
    return (
        "# a simulated probe calibration on a sphere (piecs-bayes simulate calibration)\n"
        "[calibration]\n"
        'probe = "T9 simulated probe"\nunits = "mm"\nfeed = 200.0\ndate = "2026-11-30"\n'
        f'orders = "auto"\nrepeatability = {sim["repeatability"]!r}\n\n'
        "[artefact]\n"
        f'kind = "sphere"\ndiameter = {sim["diameter"]!r}\n'
        f"expanded_uncertainty = {expanded!r}\ncoverage_factor = {k!r}\n"
        f"centre = [{float(c[0])!r}, {float(c[1])!r}]\n\n"
        '[[probe_files]]\nfile = "cal_points.csv"\nformat = "csv"\nx_mode = "radius"\n'
    )


def write_calibration_sim(
    out, *, seed: int = 0, n_directions: int = 24, repeatability: float = 0.0015,
    expanded_uncertainty: float = 0.0005, coverage_factor: float = 2.0, protect=None,
    directions: str = "lathe",
) -> list[Path]:  # fmt: skip
    """Write the data set of `simulate_calibration` into folder `out`; returns the
    paths written."""
    out = Path(out)
    sim = simulate_calibration(seed=seed, n_directions=n_directions, repeatability=repeatability,
                               directions=directions)  # fmt: skip
    csv = "feature,x,z\n" + "".join(f"sphere,{x:.6f},{z:.6f}\n" for x, z in sim["points"])
    names = coefficient_names(sim["orders"])
    truth = {
        "what": "piecs-bayes simulate calibration: the truth of cal_points.csv",
        "orders": list(sim["orders"]),
        "coefficients": dict(zip(names, map(float, sim["coefficients"]), strict=True)),
        "centre_true": [float(v) for v in sim["centre_true"]],
        "diameter_true_mm": sim["diameter"], "repeatability_mm": repeatability,
        "n_directions": n_directions, "directions": directions,
        "approach_deg": [float(v) for v in np.degrees(sim["theta"])], "seed": seed,
    }  # fmt: skip
    toml = _toml(sim, expanded=expanded_uncertainty, k=coverage_factor)
    return [
        write_text_atomic(out / "calibration.toml", toml, protect=protect),
        write_text_atomic(out / "cal_points.csv", csv, protect=protect),
        write_text_atomic(out / "truth.json", json.dumps(truth, indent=2) + "\n", protect=protect),
    ]
