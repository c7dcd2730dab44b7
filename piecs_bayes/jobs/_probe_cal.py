"""``calibrate-probe``'s job: read a calibration file and its probe files, fit the
effective radius r(theta) and return the `ProbeCalibration` with its inputs.

Approach directions come from the probe files when they carry them (a control
format's plan, a CSV's ``approach_x``, ``approach_z``), else from the nominal
artefact: toward its nominal centre (sphere), outward along +-X (ring), inward along
-+X (diameter), toward the face along -+Z (face pair). With a face pair, the points
of feature ``face`` are the faces'; the others the bore's or the diameter's.
"""

from __future__ import annotations

import dataclasses
import hashlib

import numpy as np

from ..errors import InputError
from ..fit import CALIBRATION_SAMPLING, CalibrationOptions, fit_probe_calibration
from ..io import (
    PER_AXIS,
    CalibrationFile,
    ProbeCalibration,
    parse_orders,
    read_bytes,
    read_calibration_file,
    read_control_probe,
    read_plan_points,
    read_probe_csv,
)


def parse_orders_option(text: str | None):
    """``--orders``: None (the file's), ``auto``, ``0`` (one radius), ``a2`` (one
    radius per axis), ``2``, ``3`` or ``2,3``."""
    if text is None:
        return None
    text = text.strip()
    if text in ("auto", PER_AXIS):
        return text
    if text == "0":
        return ()
    try:
        ks = [int(k) for k in text.split(",")]
    except ValueError:
        raise InputError(f"--orders: expected auto, 0, a2, 2, 3 or 2,3, got {text!r}") from None
    return parse_orders(ks, "--orders")


def parse_directions_option(text: str | None, plan=None):
    """The target directions of ``orders = "auto"`` (degrees): ``--directions``
    (``180,90,-90``) or the approach angles of a probe plan's points (``--plan``,
    `io.read_plan_points`); None when neither is given."""
    if text is not None and plan is not None:
        raise InputError("--directions and --plan both give the target directions: give one")
    if plan is not None:
        a = read_plan_points(plan).approach
        return np.degrees(np.arctan2(a[:, 1], a[:, 0]))
    if text is None:
        return None
    try:
        deg = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError(f"--directions: expected angles in degrees separated by commas "
                         f"(e.g. 180,90,-90), got {text!r}", value=text) from None  # fmt: skip
    if not all(np.isfinite(deg)):
        raise InputError(f"--directions: expected finite angles, got {text!r}", value=text)
    return np.asarray(deg)


def _nominal_approach(cal: CalibrationFile, points, face) -> np.ndarray:
    """The approach directions of the module docstring, from the nominal artefact."""
    art = cal.artefact
    d = points - np.asarray(art.centre)
    if art.kind == "sphere":
        return -d / np.maximum(np.linalg.norm(d, axis=1), 1e-300)[:, None]
    out = np.zeros_like(points)
    inward = -1.0 if art.kind == "diameter" else 1.0
    out[:, 0] = inward * np.sign(d[:, 0])
    out[face, 0] = 0.0
    out[face, 1] = -np.sign(d[face, 1])
    if np.any(np.linalg.norm(out, axis=1) == 0):
        raise InputError("a point at the artefact's nominal centre: no approach direction",
                         file=str(cal.path))  # fmt: skip
    return out


def calibration_points(cal: CalibrationFile):
    """`(centres (n, 2), approach (n, 2), face (n,) bool)` of every probe file (mm,
    radius X)."""
    pts, app, face = [], [], []
    for f in cal.probe_files:
        if f.format == "csv":
            data = read_probe_csv(f.file, units="mm", x_mode=f.x_mode)
        else:
            plan = read_plan_points(f.plan)
            xm = f.x_mode if f.format == "fanuc-dprnt" else None
            data = read_control_probe(f.file, f.format, plan, x_mode=xm)
        on_face = np.asarray(data.feature == "face") & (cal.artefact.face_width is not None)
        a = data.approach
        if a is None:
            a = _nominal_approach(cal, data.points, on_face)
        pts.append(data.points)
        app.append(a)
        face.append(on_face)
    return np.concatenate(pts), np.concatenate(app), np.concatenate(face)


def _sha256(path) -> str:
    return hashlib.sha256(read_bytes(path, what="file")).hexdigest()


def calibrate_probe(
    path, *, method: str = "lsq", orders=None, seed: int = 0, progress=False, directions=None
) -> ProbeCalibration:
    """Calibrate a probe from the calibration file `path` (`io.read_calibration_file`).

    `method` ``"lsq"`` or ``"bayes"``; `orders` overrides the file's (``"auto"``,
    ``"a2"``, a tuple, ``()``); `seed`, `progress`: the sampler's; `directions`: the
    approach angles (degrees) the parts are probed from, where ``"auto"`` judges the
    orders (default: the lathe's +X, +Z, -X, -Z). Returns the `ProbeCalibration` with
    probe, date, feed and the SHA-256 of every input."""
    cal = read_calibration_file(path)
    centres, approach, face = calibration_points(cal)
    options = CalibrationOptions(
        orders=cal.orders if orders is None else orders, sigma_dof=cal.repeatability_dof,
        sigma_known=cal.sigma == "known", method=method,
    )  # fmt: skip
    fit = fit_probe_calibration(
        cal.artefact, centres, approach, sigma_declared=cal.repeatability, options=options,
        face=face if cal.artefact.face_width is not None else None,
        sampling=dataclasses.replace(CALIBRATION_SAMPLING, seed=seed, progress=progress),
        directions=directions,
    )  # fmt: skip
    inputs = tuple({"file": str(p), "sha256": _sha256(p)} for p in (cal.path, *cal.inputs))
    return dataclasses.replace(fit, probe=cal.probe, date=cal.date, feed=cal.feed, inputs=inputs)
