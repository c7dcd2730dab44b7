"""The probe plan of a study: where to probe every feature, in which order, by which
moves, and what uncertainty it promises (`plan_study` -> [`ProbePlan`][]).

[`plan_study`][] takes the study's `[plan]` settings: per feature the usable window of
the ball (`geometry.probe_window`) and either the given count or the least count that
reaches the tolerance-to-U ratio, placed by `uncertainty.design_fractions` with the
prediction the decision will make ([`FeaturePlan`][]); per point the contact, ball
centre, approach and probe move ([`PlannedPoint`][]); safe moves between stand-offs,
the shortest order found and the predicted time. A feature whose window cannot hold
its least count is left out (`ProbePlan.unreachable`, `_plan_reach`: why, and the
settings that reach it), or refused with `strict`; an undercut stand-off is refused
naming it. [`plan_more`][] places the extra points a "measure more" verdict asks for.

The plan: docs/models/gauging.md, "The probe plan".
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, fields, replace
from numbers import Integral, Real

import numpy as np

from ..errors import InputError
from ..fit import DECLARED_DOF
from ..fit.lsq import normal_variance_factor
from ..geometry import CHORD_ERROR_MM, feature_polyline, path_distance, point_distance
from ..io import parse_fix
from ..uncertainty import (
    DesignSettings,
    FeaturePrediction,
    augment_fractions,
    design_fractions,
    points_for_ratio,
    predict_feature,
    uniform_fractions,
)
from ._options import source_sds
from ._plan_reach import UnreachableFeature, reach, room


@dataclass(frozen=True)
class PlanSettings:
    """The settings of a probe plan: the study's `[plan]` table (docs/formats.md) with
    one default each, the command line's choices and the program's stock (mm, mm/min).

    - `ratio`: the tolerance-to-U ratio the least counts reach; `points`: instead, the
      count for every feature (`None`: by the ratio).
    - `clearance`: of the ball from the stock on every move; `end_clearance`: of the
      contact from a feature's sharp ends; `overtravel`: of the probe target beyond
      the nominal contact; `spacing`: least distance between points; `inside_share`:
      the share of a feature's points spread inside its window.
    - `rapid_feed`: of the moves between points, for the predicted time.
    - `controller` (`"linuxcnc"`, `"fanuc"`), `x_mode` (`"diameter"`, `"radius"`),
      `probe_on`, `probe_off` (G-code words, `None`: none), `probe_file`, `log_file`,
      `program_number`: the gauging program.
    - `stock`: the stock left for the finish cut (`[program] stock`; `None` until a
      plan takes it from its study).

    `as_dict()` is what `plan.json` writes as its `"settings"` (the optional ones only
    when set); `from_mapping` reads that back, or a study's `[plan]` table.
    """

    ratio: float = 4.0
    points: int | None = None
    clearance: float = 1.0
    end_clearance: float = 0.2
    overtravel: float = 0.5
    spacing: float = 0.1
    inside_share: float = 0.2
    rapid_feed: float = 4000.0
    controller: str = "linuxcnc"
    x_mode: str = "diameter"
    probe_on: str | None = None
    probe_off: str | None = None
    probe_file: str = "probe_points.txt"
    log_file: str = "probe_log.txt"
    program_number: int = 9001
    stock: float | None = None

    def __post_init__(self):
        for name, ok, expected in (
            ("ratio", lambda v: v > 0.0, "a number > 0"),
            ("clearance", lambda v: v > 0.0, "a length > 0"),
            ("end_clearance", lambda v: v >= 0.0, "a length >= 0"),
            ("overtravel", lambda v: v > 0.0, "a length > 0"),
            ("spacing", lambda v: v > 0.0, "a length > 0"),
            ("inside_share", lambda v: 0.0 <= v <= 0.5, "a number in [0, 0.5]"),
            ("rapid_feed", lambda v: v > 0.0, "a feed > 0"),
            ("stock", lambda v: v >= 0.0, "a length >= 0"),
        ):
            v = getattr(self, name)
            if v is None and name == "stock":
                continue
            if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v) or not ok(v):
                _refuse(name, expected, v)
            object.__setattr__(self, name, float(v))  # as the study file's numbers are
        for name, lo, hi in (("points", 1, None), ("program_number", 1, 9999)):
            v = getattr(self, name)
            if v is None and name == "points":
                continue
            if isinstance(v, bool) or not isinstance(v, Integral) or v < lo or (hi and v > hi):
                _refuse(name, f"an integer >= {lo}" + (f" and <= {hi}" if hi else ""), v)
        for name, allowed in (("controller", ("linuxcnc", "fanuc")),
                              ("x_mode", ("diameter", "radius"))):  # fmt: skip
            if getattr(self, name) not in allowed:
                _refuse(name, " or ".join(map(repr, allowed)), getattr(self, name))
        for name in ("probe_on", "probe_off", "probe_file", "log_file"):
            v = getattr(self, name)
            if not (isinstance(v, str) and v) and not (v is None and name.startswith("probe_o")):
                _refuse(name, "a text", v)

    def as_dict(self) -> dict:
        """The settings by name, as `plan.json` writes them: `points`, `probe_on`,
        `probe_off` and `stock` only when set."""
        return {
            f.name: getattr(self, f.name)
            for f in fields(self)
            if not (f.name in _UNSET_LEFT_OUT and getattr(self, f.name) is None)
        }

    @classmethod
    def from_mapping(cls, settings: Mapping) -> PlanSettings:
        """The settings of a mapping by name: a study's `[plan]` table, or the
        `"settings"` of a `plan.json` (in millimetres). A name that is not a setting is
        refused, naming it."""
        names = {f.name for f in fields(cls)}
        for key in settings:
            if key not in names:
                raise InputError(
                    f"unknown plan setting {key!r}; expected one of {', '.join(sorted(names))}",
                    value=key,
                )
        return cls(**dict(settings))


#: the settings `as_dict` leaves out while they are `None`
_UNSET_LEFT_OUT = ("points", "probe_on", "probe_off", "stock")


def _refuse(name: str, expected: str, value) -> None:
    raise InputError(f"plan setting {name!r}: expected {expected}, got {value!r}", value=value)


_MAX_POINTS = 60
#: mm: a move that keeps the clearance to this much is safe (the polylines of arcs lie
#: up to CHORD_ERROR_MM inside them)
_SAFE = 3 * CHORD_ERROR_MM


@dataclass(frozen=True)
class PlannedPoint:
    """One probe point (part frame, mm, radius X): its place in the program
    (`index`, from 1), feature and fraction `t`, nominal `contact`, ball `centre` at
    contact, unit `approach` (into the surface), probe move `start` and `target`,
    and whether it belongs to the spread share (`inside`)."""

    index: int
    feature: str
    t: float
    contact: tuple[float, float]
    centre: tuple[float, float]
    approach: tuple[float, float]
    start: tuple[float, float]
    target: tuple[float, float]
    inside: bool


@dataclass(frozen=True)
class FeaturePlan:
    """A feature's window (fractions), its designed fractions, and the predicted
    uncertainty of its characteristic for them and for uniform spacing."""

    feature: str
    window: tuple[float, float]
    fractions: tuple[float, ...]
    designed: FeaturePrediction
    uniform: FeaturePrediction


@dataclass(frozen=True)
class ProbePlan:
    """The study's probe plan: points in program order, the safe path between them
    (`path`: `(kind, end)` with kind `"rapid"` or `"probe"`, starting at `home`),
    per-feature predictions, settings, the predicted gauging time (s), and the
    features it leaves out (`unreachable`: not measured, each with why and the
    settings that reach it)."""

    study: object
    points: tuple[PlannedPoint, ...]
    features: tuple[FeaturePlan, ...]
    home: tuple[float, float]
    path: tuple[tuple[str, tuple[float, float]], ...]
    settings: PlanSettings
    dof: float
    time_s: float
    travel_mm: float
    unreachable: tuple[UnreachableFeature, ...] = ()

    @property
    def n_points(self) -> int:
        return len(self.points)

    def feature(self, fid: str) -> FeaturePlan:
        return next(f for f in self.features if f.feature == fid)


def _settings(study, points, ratio, controller) -> PlanSettings:
    """The plan's settings: the study's `[plan]` table, the stock of its program and the
    choices of the call (a `ratio` without `points` plans by the ratio)."""
    chosen: dict = {"stock": study.program_settings.stock}
    if points is not None:
        chosen["points"] = int(points)
    if ratio is not None:
        chosen["ratio"] = float(ratio)
        if points is None:
            chosen["points"] = None
    if controller is not None:
        chosen["controller"] = controller
    try:
        s = replace(PlanSettings.from_mapping(study.plan), **chosen)
    except InputError as exc:
        raise InputError(exc.reason, file=str(study.path), value=exc.value) from None
    for key, why in (("tool", "the gauging program selects the probe by it"),
                     ("feed", "a calibration holds only at the feed it was made at")):  # fmt: skip
        if getattr(study.probe, key) is None:
            raise InputError(
                f"probe.{key}: missing; a probe plan needs it ({why})", file=str(study.path)
            )
    max_corr = study.compensation.max_correction
    if s.overtravel <= max_corr:
        raise InputError(
            f"plan.overtravel {s.overtravel:g} mm is not beyond [compensation] "
            f"max_correction {max_corr:g} mm: a part off by that much would not be touched",
            file=str(study.path),
            value=s.overtravel,
        )
    return s


def _design_settings(study, dof) -> DesignSettings:
    loss = study.fit.loss if study.fit.method == "robust" else "linear"
    return DesignSettings(
        sigma=study.probe.repeatability,
        kappa=normal_variance_factor(loss),
        at=study.decision.get("characteristic", "worst"),
        sources=tuple(sorted(source_sds(study).items())),
        dof=dof,
        coverage_factor=float(study.decision.get("coverage_factor", 2.0)),
    )


#: points beyond a feature's parameters that a plan gives at least: a robust fit of
#: p + 1 points fails when one point is down-weighted (its effective points fall below
#: p + 1: seen on 3-point lines of the gauged demo), and p + 3 leave it room to find one
EXTRA_POINTS = 3


def _min_points(study, f) -> int:
    least = study.fit.min_points_arc if f.kind == "arc" else study.fit.min_points_line
    return max(int(least), f.nparams + EXTRA_POINTS)


def _reach(study, s):
    """`(windows, unreachable)` of the plan (`_plan_reach.reach`) with the least counts."""
    least = {f.id: _min_points(study, f) for f in study.profile.features}
    windows, unreachable = reach(study, s, least)
    if not windows:
        raise InputError(
            "no feature can be probed: " + "; ".join(u.message for u in unreachable),
            file=str(study.path),
            feature=unreachable[0].feature,
        )
    return windows, unreachable


def _refuse_unreachable(study, unreachable) -> None:
    """`strict`: a plan that leaves a feature out is an error naming each one."""
    if unreachable:
        raise InputError(
            f"the plan would leave {len(unreachable)} feature(s) not measured (strict): "
            + "; ".join(u.message for u in unreachable),
            file=str(study.path),
            feature=unreachable[0].feature,
        )


def _sigma_dof(study, counts: dict) -> float:
    if study.fit.known_sigma:
        return math.inf
    resid = sum(max(n - study.profile[fid].nparams, 0) for fid, n in counts.items() if n > 0)
    prior = study.probe.repeatability_dof if study.probe.repeatability_dof else 0.0
    return float(max(resid, 0) + prior) if resid + prior > 0 else float(DECLARED_DOF)


def _room(f, s, windows) -> int:
    """The most points the window of `f` holds at the spacing."""
    return room(windows[f.id], f.length, s.spacing)


def _feature_designs(study, s, windows, counts):
    """`(plans, dof)` of the features with a window: `(feature, fractions, inside,
    FeaturePlan)` each, by `counts` or, when None, by the ratio."""
    fixed = parse_fix(study.fit.fix)
    planned = [f for f in study.profile.features if f.id in windows]
    if counts is None:  # the least counts for the ratio, at the dof of the least counts
        least = {f.id: _min_points(study, f) for f in planned}
        ds = _design_settings(study, _sigma_dof(study, least))
        ds = _with(ds, s)
        designs = {}
        for f in planned:
            designs[f.id] = points_for_ratio(
                f, windows[f.id], ds, s.ratio, n_min=least[f.id],
                n_max=min(_MAX_POINTS, _room(f, s, windows)), fixed=fixed.get(f.id, ()),
            )  # fmt: skip
        counts = {fid: len(d[0]) for fid, d in designs.items()}
    else:
        designs = None
    ds = _with(_design_settings(study, _sigma_dof(study, counts)), s)
    plans = []
    for f in planned:
        fx = fixed.get(f.id, ())
        if designs is None or len(designs[f.id][0]) != counts[f.id]:
            ts, inside = design_fractions(f, counts[f.id], windows[f.id], ds, fixed=fx)
        else:
            ts, inside = designs[f.id][:2]
        pred = predict_feature(f, ts, ds, fixed=fx)
        uni = predict_feature(f, uniform_fractions(len(ts), windows[f.id]), ds, fixed=fx)
        plans.append(
            (f, ts, inside, FeaturePlan(f.id, windows[f.id], tuple(map(float, ts)), pred, uni))
        )
    return plans, ds.dof


def _with(ds: DesignSettings, s: PlanSettings) -> DesignSettings:
    return replace(ds, inside_share=s.inside_share, spacing=s.spacing)


def _fixed_counts(study, s, windows, counts):
    """The counts asked for (`counts`, or `[plan] points` on every feature; None: by
    the ratio) on the planned features: at least the fit's least points, at most what
    the window holds at the spacing."""
    if counts is None and s.points is not None:
        counts = {f.id: int(s.points) for f in study.profile.features}
    if counts is None:
        return None
    return {
        f.id: min(max(int(counts.get(f.id, 0)), _min_points(study, f)), _room(f, s, windows))
        for f in study.profile.features
        if f.id in windows
    }


def plan_study(study, *, points=None, ratio=None, controller=None, counts=None, strict=False):
    """The [`ProbePlan`][] of `study` (module docstring).

    **Arguments:**

    - `points`: the count for every feature; `ratio`: the tolerance-to-U ratio to
      reach instead (default `[plan] ratio`, 4); `counts`: a count per feature id
      (overrides both); a count is at least the fit's least points for the feature
      (`[fit] min_points_line`/`min_points_arc`) and `EXTRA_POINTS` more than its
      parameters (5 on a line, 6 on an arc: room for the robust fit), and at most
      what its window holds at `[plan] spacing`;
      `controller`: `"linuxcnc"` or `"fanuc"`.
    - `strict`: refuse a plan that leaves a feature out (an `InputError` naming each
      one, why, and the settings that reach it); by default such a feature is left
      out and listed in `ProbePlan.unreachable`.
    """
    s = _settings(study, points, ratio, controller)
    windows, unreachable = _reach(study, s)
    if strict:
        _refuse_unreachable(study, unreachable)
    counts = _fixed_counts(study, s, windows, counts)
    plans, dof = _feature_designs(study, s, windows, counts)
    raw = _points(study, s, plans)
    from ._plan_route import order_and_route

    home, ordered, path, travel, time_s = order_and_route(study, s, raw)
    pts = tuple(PlannedPoint(i + 1, *p) for i, p in enumerate(ordered))
    return ProbePlan(
        study=study, points=pts, features=tuple(p[3] for p in plans if p[3] is not None),
        home=home, path=path, settings=s, dof=dof, time_s=time_s, travel_mm=travel,
        unreachable=unreachable,
    )  # fmt: skip


def feature_fractions(feature, points) -> np.ndarray:
    """The fractions of `feature` nearest to nominal points `(k, 2)` (part frame, mm,
    radius X): where probed points lie along it."""
    t = np.linspace(0.0, 1.0, 4001)
    q = feature.drawn_at(t)[0]
    p = np.atleast_2d(np.asarray(points, dtype=float))
    d = np.sum((p[:, None, :] - q[None]) ** 2, axis=2)
    return t[np.argmin(d, axis=1)]


def plan_more(study, more: dict, probed: dict, *, controller=None):
    """The plan of a "measure more" verdict: for each feature of `more`
    (`{feature: extra points}`), that many new points placed, with the points already
    probed (`probed`: `{feature: nominal points (k, 2)}`, part frame, mm, radius X)
    held fixed, to lower the characteristic's uncertainty most
    (`uncertainty.augment_fractions`). The predictions are for all points together."""
    s = _settings(study, None, None, controller)
    windows, unreachable = _reach(study, s)
    counts = {}
    for fid in more:
        if fid not in study.profile.ids:
            raise InputError(
                f"unknown feature id {fid!r}; the profile has {', '.join(study.profile.ids)}",
                file=str(study.path),
                feature=fid,
            )
    _refuse_unreachable(study, [u for u in unreachable if int(more.get(u.feature, 0)) > 0])
    for f in study.profile.features:
        have = probed.get(f.id)
        counts[f.id] = (0 if have is None else len(have)) + int(more.get(f.id, 0))
    ds = _with(_design_settings(study, _sigma_dof(study, counts)), s)
    fixed = parse_fix(study.fit.fix)
    extra, plans = {}, []
    for f in study.profile.features:
        n_add = int(more.get(f.id, 0))
        if n_add <= 0:
            continue
        have = probed.get(f.id)
        have_t = feature_fractions(f, have) if have is not None and len(have) else np.zeros(0)
        new = augment_fractions(f, have_t, n_add, windows[f.id], ds, fixed=fixed.get(f.id, ()))
        extra[f.id] = new
        both = np.sort(np.concatenate([have_t, new]))
        pred = predict_feature(f, both, ds, fixed=fixed.get(f.id, ()))
        uni = predict_feature(
            f, uniform_fractions(both.size, windows[f.id]), ds, fixed=fixed.get(f.id, ())
        )
        plans.append(FeaturePlan(f.id, windows[f.id], tuple(map(float, new)), pred, uni))
    if not extra:
        raise InputError("no feature asks for more points: nothing to plan", file=str(study.path))
    raw = _points(study, s, _extra_plans(study, s, windows, extra))
    from ._plan_route import order_and_route

    home, ordered, path, travel, time_s = order_and_route(study, s, raw)
    pts = tuple(PlannedPoint(i + 1, *p) for i, p in enumerate(ordered))
    return ProbePlan(
        study=study, points=pts, features=tuple(plans), home=home, path=path, settings=s,
        dof=ds.dof, time_s=time_s, travel_mm=travel,
    )  # fmt: skip


def _extra_plans(study, s, windows, extra):
    plans = []
    for f in study.profile.features:
        ts = np.asarray(extra.get(f.id, ()), dtype=float)
        if ts.size:
            plans.append((f, ts, np.zeros(ts.size, dtype=bool), None))
    return plans


def _points(study, s, plans):
    r = study.probe.ball_radius
    out_dist = s.stock + s.clearance
    raw = []
    for f, ts, inside, _ in plans:
        if len(ts) == 0:
            continue
        q, n = f.drawn_at(np.asarray(ts, dtype=float))
        c = q + r * n
        start = c + out_dist * n
        target = c - s.overtravel * n
        for k in range(len(ts)):
            raw.append((
                f.id, float(ts[k]), _pt(q[k]), _pt(c[k]), _pt(-n[k]), _pt(start[k]),
                _pt(target[k]), bool(inside[k]),
            ))  # fmt: skip
    _check_probe_moves(study, s, raw)
    return raw


def _pt(v) -> tuple[float, float]:
    """`v` as two floats, a negative zero as zero (`+ 0.0`): the sign of a zero
    component depends on how the normal was computed, not on the part."""
    return (float(v[0]) + 0.0, float(v[1]) + 0.0)


def _check_probe_moves(study, s, raw) -> None:
    """The stand-off of every point outside the stock by the clearance, and its probe
    move meeting no other feature before its own."""
    r = study.probe.ball_radius
    polys = {f.id: feature_polyline(f) for f in study.profile.features}
    need = r + s.stock + s.clearance
    for fid, t, _q, c, _a, start, _tg, _i in raw:
        for gid, poly in polys.items():
            d = float(point_distance(np.asarray([start]), poly)[0])
            if d < need - _SAFE:
                raise InputError(
                    f"feature {fid!r} at t={t:.3f}: the probe's stand-off is {d - r:.3f} mm "
                    f"from feature {gid!r}, less than stock + clearance "
                    f"({s.stock + s.clearance:g} mm): the ball cannot approach along "
                    "the normal there (an undercut or a narrow groove)",
                    file=str(study.path),
                    feature=fid,
                )
            if gid != fid and path_distance(start, c, poly) < r - _SAFE:
                raise InputError(
                    f"feature {fid!r} at t={t:.3f}: the probe move meets feature {gid!r} "
                    "before the surface it probes (an undercut)",
                    file=str(study.path),
                    feature=fid,
                )
