"""The user's jobs composed from the public API: what the CLI and notebooks call.

``study -> probe data -> fits -> adjusted path``; each step returns plain,
immutable results that print well and that the writers in :mod:`.export` read.
"""

from __future__ import annotations

import numpy as np

from .compensate import AdjustedPath, adjusted_path
from .errors import InputError
from .fit import ProfileFit, fit_profile, fit_profile_joint
from .fit._features import to_part_frame
from .fit._robust import TUNING
from .io import ProbeData, Study, load_study, read_probe_csv

__all__ = ["load_probe_data", "fit_study", "compensate_study", "load_study", "robust_scale"]


def load_probe_data(study: Study, files=None) -> ProbeData:
    """Read the study's probe files (or ``files``) into one :class:`ProbeData`.

    Rows of several files are concatenated; each file's rows get the file stem
    as part id unless the file has a ``part`` column.
    """
    files = list(files) if files is not None else list(study.probe_files)
    if not files:
        raise InputError("the study lists no probe files (study.probe_files)", file=str(study.path))
    datas = [
        read_probe_csv(f, units=study.units, x_mode=study.probe.x_mode, features=study.profile.ids)
        for f in files
    ]
    if len(datas) == 1:
        return datas[0]

    def cat(attr):
        vals = [getattr(d, attr) for d in datas]
        return None if any(v is None for v in vals) else np.concatenate(vals)

    return ProbeData(
        file=",".join(d.file for d in datas),
        feature=cat("feature"),
        points=cat("points"),
        lines=cat("lines"),
        part=cat("part"),
        approach=cat("approach"),
        time=cat("time"),
        temperature=cat("temperature"),
    )


def robust_scale(study: Study) -> float:
    """Loss scale of robust fits: the study's ``fit.scale`` (a standard deviation,
    mm), else the probe's known repeatability, times the loss's tuning constant.

    A MAD from the handful of points on one feature can collapse towards zero
    and flag good points (seen on a 7-point fillet: 0.15 um against 1.5 um of
    noise), so the known repeatability is the better robust scale.
    """
    sd = study.fit.scale if study.fit.scale is not None else study.probe.repeatability
    return TUNING.get(study.fit.loss, 1.0) * sd


def fit_study(
    study: Study,
    probe: ProbeData | None = None,
    *,
    method: str | None = None,
    part: str | None = None,
) -> ProfileFit:
    """Fit one part of a study (``method``: ``"lsq"`` or ``"robust"``, default from the study).

    With several parts in the probe data, ``part`` chooses one (default: the first).
    """
    probe = load_probe_data(study) if probe is None else probe
    parts = probe.parts
    if part is None:
        part = parts[0]
    elif part not in parts:
        raise InputError(
            f"no part {part!r} in the probe data; parts are {', '.join(parts)}", file=probe.file
        )
    data = probe.for_part(part) if len(parts) > 1 else probe
    method = method or study.fit.method
    if method == "bayes":
        method = "robust"  # the Bayesian fit starts from the robust one; see fit.bayes
    loss = "linear" if method == "lsq" else study.fit.loss
    sigma = study.probe.repeatability if study.fit.known_sigma else None
    if study.fit.free_transform:
        return fit_profile_joint(
            study.profile,
            data.feature,
            data.points,
            ball_radius=study.probe.ball_radius,
            transform=study.transform,
            free_transform=study.fit.free_transform,
            fix=study.fit.fix,
            loss=loss,
            scale=robust_scale(study) if loss != "linear" else None,
            sigma=sigma,
            lines=data.lines,
            part=part,
        )
    fix: dict[str, list] = {}
    for item in study.fit.fix:
        fid, _, name = item.partition(".")
        fix.setdefault(fid, []).append(name)
    centres = to_part_frame(study.transform, data.points)
    return fit_profile(
        study.profile,
        data.feature,
        centres,
        ball_radius=study.probe.ball_radius,
        method=method,
        loss=study.fit.loss,
        scale=robust_scale(study),
        sigma=sigma,
        fix=fix,
        lines=data.lines,
        min_points={"line": study.fit.min_points_line, "arc": study.fit.min_points_arc},
        file=data.file,
        part=part,
    )


def compensate_study(study: Study, fit: ProfileFit, *, gain=None) -> AdjustedPath:
    """Mirror a fit into the adjusted tool path, with the study's gain and limit."""
    return adjusted_path(
        study.profile,
        fit.deviations,
        gain=study.compensation.gain if gain is None else gain,
        max_correction=study.compensation.max_correction,
    )
