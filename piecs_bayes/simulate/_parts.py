"""Simulated parts with known truth: the shipped data sets and the tests' oracles.

A process-error model turns machining effects into exact per-feature
deviations (the truth); probe triggers are then drawn on the true features,
offset by the ball radius, perturbed by repeatability noise, moved to machine
coordinates and written as the probe CSV the user would get.

Process effects (all in mm, radius X):

- ``tool_offset_x``, ``tool_offset_z``: tool-setting error, shifts every surface;
- ``deflection``: radial error per mm of overhang from the chuck (part and tool
  bending): diameters far from the chuck come out larger;
- ``wear_rate``: radial error growth per mm of cut along the profile;
- ``nose_radius_error``: actual minus planned tool-nose radius: every surface
  moves into the material by this amount (arcs change radius).
"""

from __future__ import annotations

import json
import math
import numbers
from dataclasses import asdict, dataclass
from typing import NamedTuple

import numpy as np

from ..errors import InputError
from ..geometry import (
    Arc,
    Line,
    MachineTransform,
    Profile,
    make_feature,
    part_to_machine,
    profile_side,
)
from ..io import lobe_basis
from ._files import probe_csv_text, study_toml_text


@dataclass(frozen=True)
class ProcessErrors:
    """Machining error sources of one part (mm; deflection and wear per mm)."""

    tool_offset_x: float = 0.0
    tool_offset_z: float = 0.0
    deflection: float = 0.0
    wear_rate: float = 0.0
    nose_radius_error: float = 0.0
    chuck_z: float = -100.0
    wear_start: float = 0.0


# The demo shaft (radius X, mm): end face, D24, taper to D30, D30, R3 fillet,
# shoulder face, D44. Tolerances as drawn: diameters on the Ø, faces on Z, the taper
# and the fillet along the normal (`geometry.drawn_scale`).
DEMO_FEATURES = [
    dict(id="face_end", p0=(4.0, 0.0), p1=(12.0, 0.0),
         tolerance=(-0.05, 0.05), tolerance_on="length"),
    dict(id="dia_24", p0=(12.0, 0.0), p1=(12.0, -30.0),
         tolerance=(-0.020, 0.020), tolerance_on="diameter"),
    dict(id="taper", p0=(12.0, -30.0), p1=(15.0, -45.0),
         tolerance=(-0.020, 0.020), tolerance_on="normal"),
    dict(id="dia_30", p0=(15.0, -45.0), p1=(15.0, -57.0),
         tolerance=(-0.020, 0.020), tolerance_on="diameter"),
    dict(id="fillet", p0=(15.0, -57.0), p1=(18.0, -60.0), center=(18.0, -57.0), ccw=False,
         tolerance=(-0.05, 0.05), tolerance_on="normal"),
    dict(id="shoulder", p0=(18.0, -60.0), p1=(22.0, -60.0),
         tolerance=(-0.03, 0.03), tolerance_on="length"),
    dict(id="dia_44", p0=(22.0, -60.0), p1=(22.0, -90.0),
         tolerance=(-0.030, 0.030), tolerance_on="diameter"),
]  # fmt: skip


def demo_profile() -> Profile:
    """The demo stepped shaft as a :class:`Profile` (external)."""
    side = profile_side(DEMO_FEATURES)
    return Profile(tuple(make_feature(s, side) for s in DEMO_FEATURES))


def _line_deviation(f: Line, q0, q1) -> np.ndarray:
    d = np.asarray(f.direction)
    n = np.asarray(f.normal)
    dq = (np.asarray(q1) - np.asarray(q0)) / np.linalg.norm(np.asarray(q1) - np.asarray(q0))
    # drawing-frame angle from d to dq (CCW positive); (x, z) -> drawing (z, x)
    cross = d[1] * dq[0] - d[0] * dq[1]
    theta = math.atan2(cross, float(np.dot(d, dq)))
    c, s = math.cos(theta), math.sin(theta)
    n_rot = np.array([c * n[0] + s * n[1], -s * n[0] + c * n[1]])
    m = np.asarray(f.midpoint)
    e = float(np.dot(np.asarray(q0) - m, n_rot) / np.dot(n, n_rot))
    return np.array([e, theta])


def process_deviations(profile: Profile, errors: ProcessErrors) -> dict[str, np.ndarray]:
    """Exact per-feature deviations that the process errors produce.

    Lines: the error field moves both end points (the field is affine along each
    line, so the result is exactly a line). Arcs: the centre moves with the
    field at the centre; the radius changes by the nose-radius error.
    """
    out = {}
    s_path = errors.wear_start

    def field_at(p, s):
        ex = (
            errors.tool_offset_x
            + errors.deflection * (p[1] - errors.chuck_z)
            + errors.wear_rate * s
        )
        return np.array([ex, errors.tool_offset_z])

    for f in profile.features:
        s0, s1 = s_path, s_path + f.length
        if isinstance(f, Line):
            n = np.asarray(f.normal)
            q0 = np.array(f.p0) + field_at(f.p0, s0) - errors.nose_radius_error * n
            q1 = np.array(f.p1) + field_at(f.p1, s1) - errors.nose_radius_error * n
            out[f.id] = _line_deviation(f, q0, q1)
        else:
            dc = field_at(f.center, 0.5 * (s0 + s1))
            out[f.id] = np.array([dc[0], dc[1], -f.sense * errors.nose_radius_error])
        s_path = s1
    return out


def simulate_probe(
    profile: Profile,
    deviations: dict[str, np.ndarray],
    *,
    ball_radius: float,
    transform: MachineTransform = MachineTransform(),
    points: int | dict[str, int] = 8,
    noise_sd: float = 0.001,
    rng: np.random.Generator | int = 0,
    outliers: tuple[tuple[str, int, float], ...] = (),
    margin: float = 0.1,
) -> dict[str, np.ndarray]:
    """Probe triggers (ball centres, machine frame, radius X) on the true part.

    **Arguments:**

    - `deviations`: true deviation per feature id (missing = as drawn).
    - `points`: triggers per feature (int or dict by id; 0 skips a feature), or by id
      the fractions of the feature to probe (a probe plan's).
    - `noise_sd`: probe repeatability (isotropic, mm).
    - `outliers`: ``(feature, index, size)``: that trigger is pushed out along the
      outward normal by ``size`` mm (a chip under the stylus).
    - `margin`: fraction of each feature left unprobed at both ends.

    **Returns:** dict with ``feature``, ``points`` (machine), ``approach``,
    ``surface`` (true contact points, part frame).
    """
    rng = np.random.default_rng(rng)
    feats, pts, app, surf = [], [], [], []
    for f in profile.features:
        t = _fractions(points, f.id, margin)
        k = t.size
        if k <= 0:
            continue
        dev = np.asarray(deviations.get(f.id, np.zeros(f.nparams)), dtype=float)
        s, n = f.drawn_at(t, dev)  # NumPy: no JAX program per feature and count
        c = s + ball_radius * n + rng.normal(0.0, noise_sd, size=s.shape)
        for feat, idx, size in outliers:
            if feat == f.id and 0 <= idx < k:
                c[idx] += size * n[idx]
        feats += [f.id] * k
        pts.append(c)
        app.append(-n)
        surf.append(s)
    part = np.vstack(pts)
    return {
        "feature": np.array(feats),
        "points": np.asarray(part_to_machine(part, transform)),
        "approach": np.vstack(app),
        "surface": np.vstack(surf),
    }


#: machine error sources `simulate_parts` can draw per part (as `[uncertainty]` names them)
SIMULATED_SOURCES = ("ball_radius", "x_centre", "z_offset", "scale_x", "scale_z")


def _fractions(points, fid: str, margin: float) -> np.ndarray:
    """The fractions probed on feature `fid`: `points` is a count for every feature,
    a count per feature id, or the fractions themselves per id (a probe plan)."""
    k = points.get(fid, 0) if isinstance(points, dict) else int(points)
    if np.ndim(k):
        return np.asarray(k, dtype=float)
    return np.linspace(margin, 1.0 - margin, int(k)) if k > 0 else np.zeros(0)


@dataclass(frozen=True)
class SimulatedProbing:
    """How the simulated parts are probed (as `simulate_probe` takes them).

    - `ball_radius`: the probe's ball radius (mm); `transform`: the nominal part-to-machine
      transform.
    - `points`: triggers per feature (int, or by id), or by id the fractions of the
      feature to probe (e.g. a probe plan's); `margin` applies to counts only.
    - `noise_sd`: probe repeatability (isotropic, mm), >= 0.
    """

    ball_radius: float
    transform: MachineTransform = MachineTransform()
    points: int | dict = 8
    noise_sd: float = 0.001
    margin: float = 0.1

    def __post_init__(self):
        sd = self.noise_sd
        if isinstance(sd, bool) or not isinstance(sd, numbers.Real) or not sd >= 0:
            raise ValueError(f"noise_sd must be a number >= 0, got {sd!r}")


def simulate_parts(
    profile: Profile,
    deviations: dict[str, np.ndarray],
    n_parts: int,
    *,
    probing: SimulatedProbing,
    source_sd: dict[str, float] | None = None,
    rng: np.random.Generator | int = 0,
    probe=None,
    probe_error: bool = False,
) -> dict:
    """`n_parts` probed parts at once (vectorised `simulate_probe`), each with its own
    probe noise and its own draw of the machine error sources.

    **Arguments:**

    - `deviations`: true deviation per feature id, `(k,)` (every part) or `(n_parts, k)`.
    - `probing`: the ball radius, transform, points, noise and margin (a
      [`SimulatedProbing`][]).
    - `source_sd`: standard deviations of normal per-part errors of the sources in
      `SIMULATED_SOURCES` (the ball radius is off by `d`, the real transform is
      `transform` plus the drawn errors); the fits should use the nominal values.
    - `probe`: a lobing probe (`io.ProbeCalibration`: the true r(theta)); each
      centre is recorded r(theta) from the surface at its approach angle (the
      inward normal) instead of `ball_radius`. With `probe_error`, each part's probe
      differs from it by a draw of its covariance (what a part fitted with that
      calibration sees of the calibration's own error; in `errors` as
      ``"probe_coefficients"`` ``(n_parts, p)``).
    - `rng`: as `simulate_probe`.

    **Returns:** `dict(part (str ids), feature, points (machine, radius X), errors
    {source: (n_parts,)})`, points part by part, features in profile order.
    """
    ball_radius, transform, points = probing.ball_radius, probing.transform, probing.points
    noise_sd, margin = probing.noise_sd, probing.margin
    rng = np.random.default_rng(rng)
    source_sd = dict(source_sd or {})
    for name in source_sd:
        if name not in SIMULATED_SOURCES:
            raise ValueError(f"cannot simulate source {name!r}; expected {SIMULATED_SOURCES}")
    errors = {n: rng.normal(0.0, sd, n_parts) for n, sd in source_sd.items()}
    rb = ball_radius + errors.get("ball_radius", np.zeros(n_parts))
    if probe is not None:
        coef = np.tile(probe.coefficients, (n_parts, 1))
        if probe_error:
            coef = coef + rng.multivariate_normal(np.zeros(coef.shape[1]), probe.cov, n_parts)
            errors["probe_coefficients"] = coef - probe.coefficients
    cents, feats = [], []
    for f in profile.features:
        t = _fractions(points, f.id, margin)
        k = t.size
        if k <= 0:
            continue
        dev = np.asarray(deviations.get(f.id, np.zeros(f.nparams)), dtype=float)
        dev = np.broadcast_to(dev, (n_parts, f.nparams))
        q, nrm = f.drawn_at(t, dev)  # (P, k, 2) each
        r = np.broadcast_to(rb[:, None], q.shape[:2])
        if probe is not None:  # the radius at each approach angle (the inward normal)
            basis = lobe_basis(np.arctan2(-nrm[..., 1], -nrm[..., 0]).ravel(), probe.orders)
            r = r - ball_radius + np.einsum("pkj,pj->pk", basis.reshape(*q.shape[:2], -1), coef)
        cents.append(q + r[..., None] * nrm + rng.normal(0.0, noise_sd, size=q.shape))
        feats += [f.id] * k
    part_pts = np.concatenate(cents, axis=1)  # (P, n, 2), part frame
    base = transform.as_numpy()
    tr = np.tile(base, (n_parts, 1))
    for j, name in enumerate(("x_centre", "z_offset", "scale_x", "scale_z")):
        if name in errors:
            tr[:, j] += errors[name]
    machine = part_to_machine(part_pts, tr)  # NumPy, one transform per part
    n = part_pts.shape[1]
    width = len(str(n_parts))
    names = np.array([f"p{i:0{width}d}" for i in range(n_parts)])
    return {
        "part": np.repeat(names, n),
        "feature": np.tile(np.array(feats), n_parts),
        "points": machine.reshape(-1, 2),
        "errors": errors,
    }


DEMO_ERRORS = ProcessErrors(
    tool_offset_x=0.012,
    tool_offset_z=-0.008,
    deflection=0.00015,
    wear_rate=0.00004,
    nose_radius_error=0.004,
    chuck_z=-100.0,
)
DEMO_TRANSFORM = MachineTransform(x_centre=0.0021, z_offset=-312.4873)
DEMO_POINTS = {
    "face_end": 6,
    "dia_24": 10,
    "taper": 8,
    "dia_30": 8,
    "fillet": 7,
    "shoulder": 5,
    "dia_44": 10,
}

DEMO_EXTRA = """
[uncertainty]                 # error sources, each with a distribution (lengths in mm)
repeatability = { dist = "half_normal", sd = 0.002 }
ball_radius = { dist = "normal", mean = 0.0, sd = 0.0005 }
scale_x = { dist = "normal", mean = 0.0, sd = 5e-6 }
scale_z = { dist = "normal", mean = 0.0, sd = 5e-6 }
x_centre = { dist = "normal", mean = 0.0, sd = 0.001 }

[fit]
method = "robust"
loss = "huber"
bayes_steps = 8000             # MCMC steps per ensemble (4 ensembles; 50 tau)

[compensation]
gain = 1.0
max_correction = 0.1

[program]
nose_radius = 0.4             # finish tool T0202: nose radius for the gouge check (mm)
"""


def _demo_program(profile: Profile) -> str:
    """A finish-cut program for the demo profile (diameter mode, nose comp)."""
    lines = [
        "%",
        "O1001 (DEMO SHAFT FINISH CUT)",
        "N10 G18 G7 G21 G90 G40",
        "N20 T0202 (FINISH TOOL R0.4)",
        "N30 G96 S180 M3",
        "N40 G0 X10.000 Z2.000",
        "N50 G42 G1 X8.000 Z0.000 F0.08",
    ]
    n = 60
    for f in profile.features:
        x, z = f.p1[0] * 2.0, f.p1[1]
        if isinstance(f, Arc):
            i = f.center[0] - f.p0[0]  # I is a radius even in diameter mode (LinuxCNC G7)
            k = f.center[1] - f.p0[1]
            word = "G3" if f.ccw else "G2"
            lines.append(f"N{n} {word} X{x:.3f} Z{z:.3f} I{i:.3f} K{k:.3f}")
        else:
            lines.append(f"N{n} G1 X{x:.3f} Z{z:.3f}")
        n += 10
    lines += [
        f"N{n} G1 X48.000",
        f"N{n + 10} G40 G0 X60.000",
        f"N{n + 20} G0 Z50.000",
        f"N{n + 30} M30",
        "%",
    ]
    return "\n".join(lines) + "\n"


def write_demo(out_dir, *, seed: int = 20261123) -> dict:
    """Write ``study.toml``, ``probe_part01.csv``, ``finish.ngc`` and ``truth.json``
    for the demo shaft into ``out_dir``; return the truth."""
    from pathlib import Path

    from ..io import write_text_atomic

    out = Path(out_dir)
    profile = demo_profile()
    truth = process_deviations(profile, DEMO_ERRORS)
    ball_radius, noise = 1.0, 0.0015
    sim = simulate_probe(
        profile,
        truth,
        ball_radius=ball_radius,
        transform=DEMO_TRANSFORM,
        points=DEMO_POINTS,
        noise_sd=noise,
        rng=seed,
        outliers=(("dia_30", 5, 0.150),),
    )
    header = (
        f"Simulated by piecs_bayes.simulate.write_demo(seed={seed}).\n"
        "Ball-centre machine coordinates; X is a diameter (mm). "
        "One chip under the stylus on dia_30."
    )
    write_text_atomic(
        out / "probe_part01.csv", probe_csv_text(sim, x_mode="diameter", header=header)
    )
    write_text_atomic(
        out / "study.toml",
        study_toml_text(
            profile,
            name="Demo stepped shaft",
            probe_files=["probe_part01.csv"],
            program="finish.ngc",
            ball_radius=ball_radius,
            ball_radius_u=0.0005,
            repeatability=noise,
            transform=DEMO_TRANSFORM,
            extra=DEMO_EXTRA,
        ),
    )
    write_text_atomic(out / "finish.ngc", _demo_program(profile))
    doc = {
        "description": "True per-feature deviations of the simulated demo part (mm, rad).",
        "seed": seed,
        "process_errors": asdict(DEMO_ERRORS),
        "probe": {"ball_radius": ball_radius, "repeatability": noise},
        "outliers": [{"feature": "dia_30", "index": 5, "size_mm": 0.150}],
        "deviations": {
            fid: dict(zip(profile[fid].param_names, map(float, dev), strict=True))
            for fid, dev in truth.items()
        },
    }
    write_text_atomic(out / "truth.json", json.dumps(doc, indent=2) + "\n")
    return truth


def write_batch(
    out_dir,
    *,
    n_parts: int = 36,
    tool_change_at: int = 21,
    seed: int = 7,
    points: int | None = None,
) -> list[dict]:
    """A production run of ``n_parts`` demo shafts for a capability study.

    The process (radius X, mm), chosen to look like a real finish cut:

    - part and tool deflection ``8e-5`` per mm of overhang (D24 ~ +7 um,
      D44 ~ +2 um), a nose radius 2 um larger than in the tool table;
    - the first insert is set 2 um large in X and 8 um short in Z; its flank wear
      grows the diameters by 0.3 um (radius) per part, also within a part (the
      wear is proportional to the length of cut);
    - part-to-part scatter (material, temperature) of 0.8 um in X and Z;
    - a **tool change** before part ``tool_change_at``: the new insert sits 6 um
      small in X and 3 um long in Z, and its wear starts from zero (a step of
      about -12 um on every diameter: the stability check must find it); in a run
      longer than ``2 (tool_change_at - 1)`` parts every insert lasts
      ``tool_change_at - 1`` parts, each new one set as the second.

    Probe noise 1.5 um, 6-10 points per feature (as the demo part), or ``points``
    per feature (dense probing, e.g. a scanning probe: ``--points 512``). Writes one
    probe file per part (``partNN.csv``, zero-padded to sort in production order,
    with a ``part`` column), ``study.toml`` and ``truth.json`` (the process errors
    and the exact deviations per part).
    """
    from pathlib import Path

    from ..io import write_text_atomic

    out = Path(out_dir)
    rng = np.random.default_rng(seed)
    profile = demo_profile()
    if points is not None and int(points) < 3:  # a circle needs 3
        raise InputError(f"points per feature must be at least 3, got {points}", value=points)
    pts = DEMO_POINTS if points is None else int(points)
    run = _Run(profile, tool_change_at, seed, pts, max(2, len(str(n_parts))))
    truths = [_batch_part(out, k, run, rng) for k in range(1, n_parts + 1)]
    write_text_atomic(
        out / "study.toml",
        study_toml_text(
            profile,
            name="Demo shaft batch (tool wear, tool change)",
            probe_files=["part*.csv"],
            program=None,
            ball_radius=1.0,
            ball_radius_u=0.0005,
            repeatability=0.0015,
            transform=DEMO_TRANSFORM,
            extra=DEMO_EXTRA,
        ),
    )
    doc = {
        "description": "Simulated production run of the demo shaft: exact per-part deviations "
        "(mm, rad) and the process errors that made them.",
        "seed": seed,
        "tool_change_at": tool_change_at,
        "tool_change_part": run.name(tool_change_at),
        "wear_per_part_mm": BATCH_WEAR_PER_PART,
        "part_to_part_sd_mm": 0.0008,
        "probe": {"ball_radius": 1.0, "repeatability": 0.0015},
        "parts": truths,
    }
    if points is not None:
        doc["points_per_feature"] = int(points)
    changes = [t["part"] for t in truths if t["tool_change"]]
    if len(changes) > 1:  # a long run: every insert lasts tool_change_at - 1 parts
        doc["tool_change_parts"] = changes
    write_text_atomic(out / "truth.json", json.dumps(doc, indent=2) + "\n")
    return truths


class _Run(NamedTuple):
    """What every part of a simulated batch shares."""

    profile: Profile
    tool_change_at: int
    seed: int
    points: int | dict
    width: int

    def name(self, k: int) -> str:
        return f"part{k:0{self.width}d}"


BATCH_WEAR_PER_PART = 0.0003  # radial, mm


def batch_part_errors(k: int, rng, *, tool_change_at: int = 21) -> tuple[ProcessErrors, bool]:
    """The process errors of part `k` (1, 2, ...) of [`write_batch`][]'s run, and
    whether a tool change comes before it; draws the part's two normals from `rng`
    (the run's law, for a simulation of the study's own process with other seeds)."""
    profile = demo_profile()
    cut_length = sum(f.length for f in profile.features)  # mm of cut per part
    life = max(tool_change_at - 1, 1)  # an insert lasts `tool_change_at - 1` parts
    after = k >= tool_change_at
    parts_on_tool = (k - 1) % life
    err = ProcessErrors(
        deflection=0.00008,
        nose_radius_error=0.002,
        wear_rate=BATCH_WEAR_PER_PART / cut_length,
        chuck_z=-100.0,
        tool_offset_x=(-0.004 if after else 0.002) + rng.normal(0.0, 0.0008),
        tool_offset_z=(0.003 if after else -0.008) + rng.normal(0.0, 0.0008),
        wear_start=cut_length * parts_on_tool,  # mm of cut on this edge before this part
    )
    return err, after and parts_on_tool == 0


def _batch_part(out, k: int, run: _Run, rng) -> dict:
    """Simulate and write part `k` of the batch; its truth record."""
    from ..io import write_text_atomic

    err, change = batch_part_errors(k, rng, tool_change_at=run.tool_change_at)
    truth = process_deviations(run.profile, err)
    sim = simulate_probe(
        run.profile, truth, ball_radius=1.0, transform=DEMO_TRANSFORM, points=run.points,
        noise_sd=0.0015, rng=rng,
    )  # fmt: skip
    text = probe_csv_text(
        sim, part=run.name(k), x_mode="diameter",
        header=f"Simulated batch part {k} (seed {run.seed}).",
    )  # fmt: skip
    write_text_atomic(out / f"{run.name(k)}.csv", text)
    return {
        "part": run.name(k),
        "tool_change": change,
        "process_errors": asdict(err),
        "deviations": {
            fid: dict(zip(run.profile[fid].param_names, map(float, d), strict=True))
            for fid, d in truth.items()
        },
    }
