"""Job-level decisions: is compensation justified, what is the process capable of,
and what to hand the machine (error-spec files, LinuxCNC tables, tool offsets).

This module composes the pure pieces (`compensate.decide`, `compensate.capability`,
`export` writers) with studies and fits; the CLI (`decide`, `capability`,
`compensate`) and notebooks call it.

**The characteristic of a feature** is its *normal deviation*: the distance from a
nominal point $q$ of the feature to the fitted feature, along the nominal outward
normal, positive outside the material (more material on a shaft, a larger
diameter):

$$\\delta(q) = -d_\\text{signed}(q;\\ \\hat\\theta),$$

with $\\hat\\theta$ the fitted deviation parameters. For a line at its nominal
mid-point this is the fitted `offset` (for a diameter: the radius error; the
diameter error is $2\\delta$). Its standard uncertainty is linearised from the fit
covariance $C$: $u_\\text{fit}^2 = g^\\top C g$, $g = \\partial\\delta/\\partial\\theta$
(`jax.jacfwd`). The systematic sources of the study's `[uncertainty]` table that
more probe points do not reduce (ball radius, pretravel, centre-line and Z offsets,
axis scales, rotation) add $u_\\text{sys}^2 = \\sum_s (c_s\\,\\sigma_s)^2$ with the
sensitivities at $q$ (outward normal $n$): ball radius and pretravel 1, `x_centre`
$n_x$, `z_offset` $n_z$, `scale_x` $n_x x_q$, `scale_z` $n_z z_q$, `rotation`
$n\\cdot(z_q, -x_q)$. The probe repeatability is already in $C$; `thermal` needs a
temperature difference and is not used here.

Where $q$ lies (`characteristic`):

- decisions (`[decision] characteristic`, default `"worst"`): the nominal start,
  mid-point or end (lines; nine points along arcs) with the largest $|\\delta|$:
  the tolerance zone applies to the whole feature, and the deviation of a line is
  affine along it, so its worst point is an end (on a taper or a diameter that is
  not cylindrical);
- capability studies (`[capability] characteristic`, default `"mid"`): a fixed
  point, the same on every part (`"mid"`, `"start"` or `"end"`).

Features a decision can be fed from a posterior: [`decide_features`][] takes a
mean and a standard deviation (or draws) per feature.
"""

from __future__ import annotations

import functools
import json
import math
import re
from collections.abc import Callable, Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from types import MappingProxyType

import jax
import jax.numpy as jnp
import numpy as np

from .compensate import (
    CapabilityResult,
    Decision,
    DecisionSettings,
    PredictedCapability,
    StabilityResult,
    capability,
    decide,
    predict_capability,
    settings_from_spec,
    stability_check,
)
from .errors import AnalysisError, InputError
from .export import (
    CompensationTable,
    ErrorSpec,
    OffsetSettings,
    ToolOffsets,
    ToolOffsetUpdate,
    g10_fanuc,
    g10_linuxcnc,
    offsets_from_json,
    offsets_to_json,
    read_errspec,
    to_csv,
    tool_offset_update,
    write_errspec,
    write_linuxcnc_comp,
    write_text_atomic,
)
from .fit import effective_dof
from .fit._features import _arc_distance, _geometry_args, _line_distance
from .geometry import Arc, Line, part_to_machine

__all__ = [
    "CapabilityStudy",
    "Characteristic",
    "CompensationOutputs",
    "DecisionTable",
    "FeatureCapability",
    "capability_from_values",
    "capability_study",
    "characteristics",
    "decide_features",
    "decide_study",
    "decision_settings",
    "error_spec",
    "feature_characteristic",
    "normal_deviation",
    "offset_settings",
    "tool_offsets",
    "write_compensation_outputs",
]

_AT_T = {"start": 0.0, "mid": 0.5, "end": 1.0}
#: a line whose outward normal is within this of an axis is a diameter / a face
_AXIAL = 1.0 - 1e-9
SCHEMA_VERSION = 1


# --------------------------------------------------------------------------- characteristic


def normal_deviation(feature, dev, t):
    """Normal deviation $\\delta$ (mm) of the feature deviated by `dev` at the nominal
    point at fraction(s) `t` of the feature (JAX, differentiable in `dev`)."""
    q = feature.point_at(jnp.asarray(t, dtype=float))
    return -feature.signed_distance(q, jnp.asarray(dev, dtype=float))


@functools.lru_cache(maxsize=4096)
def _nominal(feature, ts: tuple[float, ...]):
    """Nominal points, outward normals and model geometry of `feature` at `ts` (cached)."""
    q = np.asarray(feature.point_at(jnp.asarray(ts, dtype=float)))
    n = np.asarray(feature.outward_normal(jnp.asarray(q)))
    return q, n, _geometry_args(feature)


@functools.partial(jax.jit, static_argnums=0)
def _kind_dev_and_jac(kind, q, geom, dev):
    distance = _line_distance if kind == "line" else _arc_distance

    def f(d):
        return -distance(q, geom, d)

    return f(dev), jax.jacfwd(f)(dev)


def _dev_and_jac(feature, dev, ts):
    r"""$\delta$ at `ts` and its Jacobian with respect to the deviation parameters:
    the fit's own signed-distance model, compiled once per feature kind."""
    q, _, geom = _nominal(feature, tuple(float(t) for t in np.atleast_1d(ts)))
    val, jac = _kind_dev_and_jac(feature.kind, jnp.asarray(q), geom, jnp.asarray(dev, float))
    return np.asarray(val), np.asarray(jac)


def _source_sds(study) -> dict[str, float]:
    """Standard deviations of the study's systematic sources (mm or 1 or rad)."""
    from .fit import prior_from_spec

    out = {}
    for name, spec in study.sources.items():
        if name in ("repeatability", "thermal"):
            continue
        out[name] = float(prior_from_spec(name, dict(spec), file=str(study.path)).sd)
    if "ball_radius" not in out and study.probe.ball_radius_u > 0:
        out["ball_radius"] = float(study.probe.ball_radius_u)
    return out


def _u_systematic(feature, ts, sds: Mapping[str, float]) -> np.ndarray:
    """$u_\\text{sys}$ of $\\delta$ at the nominal points `ts` (see module docstring)."""
    ts = np.atleast_1d(np.asarray(ts, dtype=float))
    if not sds:
        return np.zeros(ts.size)
    q, n, _ = _nominal(feature, tuple(float(t) for t in ts))
    x, z, nx, nz = q[:, 0], q[:, 1], n[:, 0], n[:, 1]
    sens = {
        "ball_radius": np.ones_like(x),
        "pretravel": np.ones_like(x),
        "x_centre": nx,
        "z_offset": nz,
        "scale_x": nx * x,
        "scale_z": nz * z,
        "rotation": nx * z - nz * x,
    }
    var = sum((sens[k] * sd) ** 2 for k, sd in sds.items() if k in sens)
    return np.sqrt(np.asarray(var, dtype=float) + np.zeros(ts.size))


@dataclass(frozen=True)
class Characteristic:
    """The normal deviation of one feature at one nominal point, with its uncertainty.

    `mean` (mm) and `sd` $= \\sqrt{u_\\text{fit}^2 + u_\\text{sys}^2}$ are what a
    decision needs (a posterior can replace them); `at` says where: `"start"`,
    `"mid"`, `"end"` or `"t=0.25"` (fraction of the nominal feature), `point` and
    `normal` the nominal point and outward normal (part frame, radius X).
    """

    feature: str
    at: str
    t: float
    point: tuple[float, float]
    normal: tuple[float, float]
    mean: float
    u_fit: float
    u_systematic: float
    tolerance: tuple[float, float]
    n_points: int | None = None
    dof_fit: float = math.inf

    @property
    def sd(self) -> float:
        return math.hypot(self.u_fit, self.u_systematic)

    @property
    def dof(self) -> float:
        """Welch-Satterthwaite effective degrees of freedom of `sd`: `u_fit` carries the
        probe sigma's `dof_fit`, the systematic sources are Type B (infinite)."""
        return float(effective_dof(self.sd, self.u_fit, self.dof_fit))

    def __repr__(self) -> str:
        return (
            f"Characteristic({self.feature!r} at {self.at}: {self.mean * 1e3:+.2f} um, "
            f"u {self.sd * 1e3:.2f} um (fit {self.u_fit * 1e3:.2f}, systematic "
            f"{self.u_systematic * 1e3:.2f}), tolerance [{self.tolerance[0] * 1e3:+g}, "
            f"{self.tolerance[1] * 1e3:+g}] um)"
        )


def _at_label(t: float) -> str:
    for k, v in _AT_T.items():
        if t == v:
            return k
    return f"t={t:.3g}"


def feature_characteristic(
    fit,
    *,
    at: str = "mid",
    sources: Mapping[str, float] | None = None,
    dof: float = math.inf,
) -> Characteristic:
    """The [`Characteristic`][] of one `FeatureFit`.

    **Arguments:**

    - `fit`: a `FeatureFit` (values and covariance).
    - `at`: `"mid"`, `"start"`, `"end"` or `"worst"` (see the module docstring).
    - `sources`: standard deviations of the systematic sources by name (mm, 1, rad),
      e.g. from the study; `None`: none.
    - `dof`: degrees of freedom of the probe sigma the fit covariance was scaled by
      (`ProfileFit.sigma.dof`; `inf` when known).
    """
    f = fit.feature
    if at == "worst":
        ts = np.array([0.0, 0.5, 1.0]) if isinstance(f, Line) else np.linspace(0.0, 1.0, 9)
    elif at in _AT_T:
        ts = np.array([_AT_T[at]])
    else:
        raise InputError(
            f"characteristic must be 'worst', 'mid', 'start' or 'end', got {at!r}", value=at
        )
    val, jac = _dev_and_jac(f, fit.values, ts)
    i = int(np.argmax(np.abs(val))) if at == "worst" else 0
    cov = fit.covariance
    if cov is None:
        raise AnalysisError(
            f"feature {f.id!r}: the fit has no covariance (too few points or a singular fit); "
            "no uncertainty, no decision"
        )
    g = jac[i]
    u_fit = float(math.sqrt(max(float(g @ np.asarray(cov) @ g), 0.0)))
    u_sys = float(_u_systematic(f, ts[i : i + 1], sources or {})[0])
    qs, ns, _ = _nominal(f, tuple(float(t) for t in ts))
    q, n = qs[i], ns[i]
    used = int(fit.n - len(fit.outliers))
    return Characteristic(
        feature=f.id,
        at=_at_label(float(ts[i])),
        t=float(ts[i]),
        point=(float(q[0]), float(q[1])),
        normal=(float(n[0]), float(n[1])),
        mean=float(val[i]),
        u_fit=u_fit,
        u_systematic=u_sys,
        tolerance=tuple(map(float, f.tolerance)),
        n_points=used,
        dof_fit=float(dof),
    )


def characteristics(study, fit, *, at: str = "mid") -> dict[str, Characteristic]:
    """[`Characteristic`][]s of every fitted feature of `fit` (profile order), with the
    study's systematic uncertainty sources."""
    sds = _source_sds(study)
    dof = fit.sigma.dof if getattr(fit, "sigma", None) is not None else math.inf
    return {f.id: feature_characteristic(f, at=at, sources=sds, dof=dof) for f in fit}


# --------------------------------------------------------------------------- decisions


def decision_settings(study) -> DecisionSettings:
    """[`DecisionSettings`][piecs_bayes.compensate.DecisionSettings] from the study's
    `[decision]` table; `max_correction` defaults to `compensation.max_correction`."""
    spec = {k: v for k, v in study.decision.items() if k not in ("characteristic", "run_index")}
    spec.setdefault("max_correction", study.compensation.max_correction)
    return settings_from_spec(spec, file=str(study.path))


@dataclass(frozen=True, eq=False)
class DecisionTable:
    """Per-feature verdicts of one part with every number behind them.

    `decisions` are [`Decision`][piecs_bayes.compensate.Decision]s (profile order);
    `estimates` the characteristics they were made from (or `None` per feature
    when fed from elsewhere, e.g. a posterior); `gains` the gain per feature to
    pass to `adjusted_path` / [`error_spec`][] (0 unless the verdict is
    "compensate").
    """

    study: str
    part: str | None
    method: str
    characteristic: str
    decisions: tuple[Decision, ...]
    estimates: tuple[Characteristic | None, ...]
    settings: DecisionSettings
    unmeasured: tuple[str, ...] = ()

    def __getitem__(self, feature: str) -> Decision:
        for d in self.decisions:
            if d.feature == feature:
                return d
        raise KeyError(feature)

    @property
    def gains(self) -> dict[str, float]:
        return {d.feature: d.gain for d in self.decisions}

    @property
    def verdicts(self) -> dict[str, str]:
        return {d.feature: d.verdict for d in self.decisions}

    def rows(self) -> list[dict]:
        """One flat row per feature (CSV / DataFrame)."""
        out = []
        for d, c in zip(self.decisions, self.estimates, strict=True):
            row = {"part": self.part or "", **d.as_row()}
            row["tolerance_lower_mm"], row["tolerance_upper_mm"] = d.tolerance
            row["at"] = c.at if c is not None else ""
            row["u_fit_mm"] = c.u_fit if c is not None else math.nan
            row["u_systematic_mm"] = c.u_systematic if c is not None else math.nan
            out.append(row)
        return out

    def to_csv(self) -> str:
        return to_csv(self.rows())

    def to_json(self) -> str:
        feats = []
        for d, c in zip(self.decisions, self.estimates, strict=True):
            row = {k: v for k, v in d.as_row().items() if k != "reasons"}
            row["tolerance_mm"] = list(d.tolerance)
            row["characteristic"] = None if c is None else _clean(asdict(c))
            row["conformance_before"] = _clean(asdict(d.conformance_before))
            row["conformance_after"] = _clean(asdict(d.conformance_after))
            row["actions"] = [_clean(asdict(a)) for a in d.actions]
            row["reasons"] = list(d.reasons)
            feats.append(row)
        doc = {
            "schema": "piecs_bayes.decisions",
            "version": SCHEMA_VERSION,
            "study": self.study,
            "part": self.part,
            "method": self.method,
            "characteristic": self.characteristic,
            "units": {"length": "mm", "x": "radius"},
            "settings": _clean(asdict(self.settings)),
            "features": [_clean(f) for f in feats],
            "unmeasured": list(self.unmeasured),
        }
        return json.dumps(doc, indent=2) + "\n"

    def text(self) -> str:
        """A fixed-width verdict table (um), then the reasons per feature."""
        head = (
            f"{'feature':<11}{'at':<7}{'dev um':>8}{'u um':>7}{'tol um':>13}"
            f"{'P(>band)':>9}  {'conformance':<17}{'verdict':<18}{'gain':>5}{'corr um':>9}"
        )
        lines = [
            f"Decisions for {self.study!r}, part {self.part or '-'} ({self.method}; deviation "
            f"along the outward normal at the {self.characteristic} point; u = standard "
            "uncertainty)",
            head,
            "-" * len(head),
        ]
        for d, c in zip(self.decisions, self.estimates, strict=True):
            lo, hi = d.tolerance
            verdict = d.verdict.upper() if d.verdict == "compensate" else d.verdict
            if d.verdict == "measure more" and d.more_points is not None:
                verdict += f" +{d.more_points}"
            lines.append(
                f"{d.feature:<11}{(c.at if c else '-'):<7}{d.estimate * 1e3:>+8.2f}"
                f"{d.u_estimate * 1e3:>7.2f}{f'[{lo * 1e3:+g},{hi * 1e3:+g}]':>13}"
                f"{d.p_exceed:>9.3f}  {d.conformance_before.state:<17}{verdict:<18}"
                f"{d.gain:>5.2f}{d.correction * 1e3:>+9.2f}"
            )
        if self.unmeasured:
            lines.append(f"not measured (no decision): {', '.join(self.unmeasured)}")
        lines.append("")
        for d in self.decisions:
            lines.append(f"{d.feature}: {d.verdict}")
            lines += [f"  - {r}" for r in d.reasons]
        return "\n".join(lines)

    def __repr__(self) -> str:
        return self.text()


def _estimate(feature, est):
    """(mean, sd, samples, n_points, u_sys, characteristic, dof) from one estimate."""
    if isinstance(est, Characteristic):
        return est.mean, est.sd, None, est.n_points, est.u_systematic, est, est.dof
    if isinstance(est, Mapping):
        unknown = set(est) - {"mean", "sd", "samples", "n_points", "u_systematic", "dof"}
        if unknown:
            raise InputError(
                f"estimate keys must be mean, sd, samples, n_points, u_systematic, dof; got "
                f"{sorted(unknown)}",
                feature=feature,
            )
        return (
            est.get("mean"),
            est.get("sd"),
            est.get("samples"),
            est.get("n_points"),
            float(est.get("u_systematic", 0.0)),
            None,
            est.get("dof", math.inf),
        )
    if isinstance(est, tuple) and len(est) == 2:
        return float(est[0]), float(est[1]), None, None, 0.0, None, math.inf
    try:
        arr = np.asarray(est, dtype=float)
    except (TypeError, ValueError):
        arr = np.zeros(0)
    if arr.ndim == 1 and arr.size >= 2:
        return None, None, arr, None, 0.0, None, math.inf
    raise InputError(
        f"an estimate is a Characteristic, (mean, sd), a mapping with mean/sd or samples, "
        f"or 1-D posterior draws; got {est!r}",
        feature=feature,
    )


def decide_features(
    estimates: Mapping[str, object],
    tolerances: Mapping[str, tuple[float, float]],
    *,
    settings: DecisionSettings | None = None,
    run_index: int = 1,
    study: str = "",
    part: str | None = None,
    method: str = "",
    characteristic: str = "",
    unmeasured: Sequence[str] = (),
) -> DecisionTable:
    """Decide per feature from estimates of its normal deviation (mm).

    **Arguments:**

    - `estimates`: by feature id, a [`Characteristic`][], a `(mean, sd)` pair, a
      mapping with `mean`, `sd` (or `samples`) and optionally `n_points`,
      `u_systematic`, `dof`, or 1-D posterior draws: what a Bayesian fit hands over.
    - `tolerances`: `(lower, upper)` limit deviations by feature id (mm).
    - `settings`, `run_index`: see `compensate.decide`.
    - `study`, `part`, `method`, `characteristic`, `unmeasured`: labels kept in the table.

    **Returns:** a [`DecisionTable`][].
    """
    decisions, chars = [], []
    for fid, est in estimates.items():
        if fid not in tolerances:
            raise InputError(f"no tolerance for feature {fid!r}", feature=fid)
        mean, sd, samples, n_pts, u_sys, char, dof = _estimate(fid, est)
        if samples is not None and u_sys:
            u_sys = min(u_sys, float(np.std(samples, ddof=1)))
        elif sd is not None:
            u_sys = min(u_sys, float(sd))
        decisions.append(
            decide(
                tolerance=tolerances[fid],
                mean=mean,
                sd=sd,
                samples=samples,
                settings=settings,
                n_points=n_pts,
                u_systematic=u_sys,
                run_index=run_index,
                feature=fid,
                dof=dof,
            )
        )
        chars.append(char)
    return DecisionTable(
        study=study,
        part=part,
        method=method,
        characteristic=characteristic,
        decisions=tuple(decisions),
        estimates=tuple(chars),
        settings=settings if settings is not None else DecisionSettings(),
        unmeasured=tuple(unmeasured),
    )


def decide_study(
    study,
    fit=None,
    *,
    estimates: Mapping[str, object] | None = None,
    settings: DecisionSettings | None = None,
    characteristic: str | None = None,
    run_index: int | None = None,
) -> DecisionTable:
    """The decision table of one part of a study.

    **Arguments:**

    - `study`: the study (tolerances, `[decision]` settings, uncertainty sources).
    - `fit`: its `ProfileFit`; the characteristics are computed from it.
    - `estimates`: instead of (or overriding features of) `fit`, estimates by feature
      id as [`decide_features`][] takes them, e.g. posterior means and sds.
    - `settings`, `characteristic`, `run_index`: override the study's `[decision]`.
    """
    if fit is None and estimates is None:
        raise InputError("give a fit or estimates to decide on")
    settings = settings if settings is not None else decision_settings(study)
    at = characteristic or study.decision.get("characteristic", "worst")
    run_index = run_index or int(study.decision.get("run_index", 1))
    est: dict[str, object] = {}
    if fit is not None:
        est.update(characteristics(study, fit, at=at))
    if estimates is not None:
        for fid in estimates:
            if fid not in study.profile.ids:
                raise InputError(
                    f"unknown feature id {fid!r}; the profile has {', '.join(study.profile.ids)}",
                    feature=fid,
                )
        est.update(estimates)
    ordered = {fid: est[fid] for fid in study.profile.ids if fid in est}
    tolerances = {f.id: f.tolerance for f in study.profile.features}
    return decide_features(
        ordered,
        tolerances,
        settings=settings,
        run_index=run_index,
        study=study.name,
        part=None if fit is None else fit.part,
        method="posterior" if fit is None else fit.method,
        characteristic=at,
        unmeasured=tuple(fid for fid in study.profile.ids if fid not in ordered),
    )


# --------------------------------------------------------------------------- capability


@dataclass(frozen=True, eq=False)
class FeatureCapability:
    """Capability of one feature's characteristic over the parts of a run.

    `values` (mm) in production order with their measurement uncertainties `u`;
    `capability` (Cp, Cpk, Pp, Ppk with confidence intervals, Bayesian credible
    intervals), `stability` (individuals / moving-range chart), `predicted` the
    capability after shifting the mean by `-gain * (mean - target)` with the
    overall spread kept, `predicted_within` the same with the within-part
    (moving-range) spread, i.e. if compensation also removed the drift and steps.
    """

    feature: str
    tolerance: tuple[float, float]
    characteristic: str
    parts: tuple[str, ...]
    values: np.ndarray
    u: np.ndarray
    capability: CapabilityResult
    stability: StabilityResult
    predicted: PredictedCapability
    predicted_within: PredictedCapability
    gain: float
    notes: tuple[str, ...] = ()

    @property
    def step_part(self) -> str | None:
        """The first part after the most likely step, when the step is clear (|t| > 4)."""
        s = self.stability
        if s.step_index is None or abs(s.step_t) <= 4.0:
            return None
        return self.parts[s.step_index]

    def findings(self) -> list[str]:
        """The stability check's findings, by part id (production order)."""
        s, ids = self.stability, self.parts
        out = []
        if s.beyond_limits:
            out.append(
                f"{len(s.beyond_limits)} part(s) beyond the 3-sigma limits "
                f"[{s.lcl * 1e3:+.2f}, {s.ucl * 1e3:+.2f}] um: {_spans(s.beyond_limits, ids)}"
            )
        for a, b in s.runs:
            out.append(
                f"run of {b - a + 1} parts on one side of the centre line: {ids[a]}..{ids[b]}"
            )
        for a, b in s.trends:
            out.append(f"trend of {b - a + 1} parts steadily rising or falling: {ids[a]}..{ids[b]}")
        if s.mr_beyond:
            out.append(f"moving range above its limit at {_spans(s.mr_beyond, ids)}")
        if self.step_part:
            out.append(
                f"likely step of {s.step_size * 1e3:+.2f} um before {self.step_part} "
                f"(t = {s.step_t:.1f})"
            )
        return out

    def flags(self, i: int) -> str:
        s = self.stability
        out = []
        if i in s.beyond_limits:
            out.append("beyond 3 sigma")
        if i in s.run_points:
            out.append("run")
        if i in s.trend_points:
            out.append("trend")
        if i in s.mr_beyond:
            out.append("moving range")
        return "; ".join(out)

    def summary(self) -> dict:
        c, b, s = self.capability, self.capability.bayes, self.stability
        row = {
            "feature": self.feature,
            "at": self.characteristic,
            "n": c.n,
            "lsl_mm": c.lsl,
            "usl_mm": c.usl,
            "mean_mm": c.mean,
            "sigma_within_mm": c.sigma_within,
            "sigma_overall_mm": c.sigma_overall,
            "gauge_sd_mm": float(np.sqrt(np.mean(self.u**2))),
        }
        for name in ("cp", "cpk", "pp", "ppk"):
            ci = getattr(c, f"{name}_ci")
            row[name], row[f"{name}_lower"], row[f"{name}_upper"] = getattr(c, name), *ci
        if b is not None:
            row["bayes_cpk"] = b.cpk
            row["bayes_cpk_lower"], row["bayes_cpk_upper"] = b.cpk_interval
            row["bayes_cp"] = b.cp
            row["bayes_cp_lower"], row["bayes_cp_upper"] = b.cp_interval
            row["p_cpk_above"] = b.p_cpk_above
        row["in_control"] = s.in_control
        row["n_out_of_control"] = len(s.out_of_control)
        row["step_part"] = self.step_part or ""
        row["step_mm"] = s.step_size if self.step_part else math.nan
        row["step_t"] = s.step_t
        row["gain"] = self.gain
        for tag, p in (("after", self.predicted), ("after_within", self.predicted_within)):
            row[f"cpk_{tag}"] = p.cpk
            row[f"cpk_{tag}_lower"], row[f"cpk_{tag}_upper"] = p.cpk_ci
            row[f"bayes_cpk_{tag}"] = p.cpk_bayes
            row[f"bayes_cpk_{tag}_lower"], row[f"bayes_cpk_{tag}_upper"] = p.cpk_bayes_interval
        return row

    def __repr__(self) -> str:
        c, s = self.capability, self.stability
        state = "in control" if s.in_control else "NOT in control"
        step = f", step before {self.step_part}" if self.step_part else ""
        return (
            f"FeatureCapability({self.feature!r} at {self.characteristic}, n={c.n}, "
            f"Cp {c.cp:.2f} {c.cp_ci!r}, Cpk {c.cpk:.2f} {c.cpk_ci!r}, Ppk {c.ppk:.2f}, "
            f"{state}{step}, Cpk after compensation {self.predicted.cpk:.2f})"
        )


@dataclass(frozen=True, eq=False)
class CapabilityStudy:
    """Capability of every feature over a run of parts (see [`capability_study`][])."""

    study: str
    parts: tuple[str, ...]
    method: str
    features: Mapping[str, FeatureCapability]
    confidence: float
    notes: tuple[str, ...] = ()

    def __getitem__(self, feature: str) -> FeatureCapability:
        return self.features[feature]

    @property
    def steps(self) -> dict[str, tuple[str, ...]]:
        """Clear steps found by the stability checks: `{first part after: features}`."""
        out: dict[str, list] = {}
        for f in self.features.values():
            if f.step_part:
                out.setdefault(f.step_part, []).append(f.feature)
        return {p: tuple(v) for p, v in out.items()}

    def summary_rows(self) -> list[dict]:
        return [f.summary() for f in self.features.values()]

    def index_rows(self) -> list[dict]:
        """One row per feature and index (value, confidence and credible intervals)."""
        out = []
        for f in self.features.values():
            for r in f.capability.table():
                out.append({"feature": f.feature, **r})
            for tag, p in (("after", f.predicted), ("after_within", f.predicted_within)):
                lo_b, hi_b = p.cpk_bayes_interval
                out.append(
                    {
                        "feature": f.feature,
                        "index": f"cpk_{tag}",
                        "value": p.cpk,
                        "lower": p.cpk_ci.lower,
                        "upper": p.cpk_ci.upper,
                        "bayes_median": p.cpk_bayes,
                        "bayes_lower": lo_b,
                        "bayes_upper": hi_b,
                    }
                )
        return out

    def part_rows(self) -> list[dict]:
        """One row per part and feature: value, uncertainty, control-chart flags."""
        out = []
        for f in self.features.values():
            s = f.stability
            for i, (p, v, u) in enumerate(zip(f.parts, f.values, f.u, strict=True)):
                out.append(
                    {
                        "part": p,
                        "feature": f.feature,
                        "value_mm": float(v),
                        "u_mm": float(u),
                        "moving_range_mm": float(abs(v - f.values[i - 1])) if i else math.nan,
                        "center_mm": s.center,
                        "lcl_mm": s.lcl,
                        "ucl_mm": s.ucl,
                        "flags": f.flags(i),
                    }
                )
        return out

    def to_json(self) -> str:
        feats = []
        for f in self.features.values():
            s = f.stability
            feats.append(
                {
                    **f.summary(),
                    "indices": f.capability.table(),
                    "sigma_method": f.capability.sigma_method,
                    "df_within": f.capability.df_within,
                    "stability": {
                        "center_mm": s.center,
                        "sigma_mm": s.sigma,
                        "lcl_mm": s.lcl,
                        "ucl_mm": s.ucl,
                        "mr_ucl_mm": s.mr_ucl,
                        "beyond_limits": [f.parts[i] for i in s.beyond_limits],
                        "runs": [[f.parts[a], f.parts[b]] for a, b in s.runs],
                        "trends": [[f.parts[a], f.parts[b]] for a, b in s.trends],
                        "moving_range_beyond": [f.parts[i] for i in s.mr_beyond],
                        "step_before_part": f.step_part,
                        "step_mm": s.step_size,
                        "step_t": s.step_t,
                        "findings": f.findings(),
                    },
                    "predicted": _clean(asdict(f.predicted)),
                    "predicted_within": _clean(asdict(f.predicted_within)),
                    "notes": list(f.notes),
                    "values": [
                        {"part": p, "value_mm": float(v), "u_mm": float(u)}
                        for p, v, u in zip(f.parts, f.values, f.u, strict=True)
                    ],
                }
            )
        doc = {
            "schema": "piecs_bayes.capability",
            "version": SCHEMA_VERSION,
            "study": self.study,
            "method": self.method,
            "confidence": self.confidence,
            "units": {"length": "mm", "x": "radius"},
            "parts": list(self.parts),
            "steps": {p: list(v) for p, v in self.steps.items()},
            "notes": list(self.notes),
            "features": [_clean(f) for f in feats],
        }
        return json.dumps(doc, indent=2) + "\n"

    def text(self) -> str:
        """Two fixed-width tables (indices; stability and prediction), then the findings."""
        lvl = f"{self.confidence:.0%}"
        h1 = (
            f"{'feature':<10}{'n':>3}{'mean um':>9}{'s_w um':>8}{'s_o um':>8}"
            f"{'Cp':>7}{f'[{lvl} CI]':>15}{'Cpk':>7}{f'[{lvl} CI]':>15}"
            f"{'Pp':>7}{f'[{lvl} CI]':>15}{'Ppk':>7}{f'[{lvl} CI]':>15}"
        )
        lines = [
            f"Capability of {self.study!r}: {len(self.parts)} parts, fits {self.method}; "
            "values: normal deviation (um) at each feature's characteristic point",
            h1,
            "-" * len(h1),
        ]
        for f in self.features.values():
            c = f.capability
            lines.append(
                f"{f.feature:<10}{c.n:>3}{c.mean * 1e3:>+9.2f}{c.sigma_within * 1e3:>8.2f}"
                f"{c.sigma_overall * 1e3:>8.2f}{c.cp:>7.2f}{_ci(c.cp_ci):>15}{c.cpk:>7.2f}"
                f"{_ci(c.cpk_ci):>15}{c.pp:>7.2f}{_ci(c.pp_ci):>15}{c.ppk:>7.2f}"
                f"{_ci(c.ppk_ci):>15}"
            )
        h2 = (
            f"{'feature':<10}{'Bayes Cp':>9}{f'[{lvl} CrI]':>15}{'Bayes Cpk':>10}"
            f"{f'[{lvl} CrI]':>15}{'P(>1.33)':>9}  {'stability':<25}{'Cpk after':>10}"
            f"{f'[{lvl} CI]':>15}{'if stable':>10}{f'[{lvl} CI]':>15}"
        )
        lines += ["", h2, "-" * len(h2)]
        for f in self.features.values():
            b, p, pw, s = f.capability.bayes, f.predicted, f.predicted_within, f.stability
            if s.in_control:
                stab = "in control"
            else:
                stab = f"{len(s.out_of_control)}/{s.n} flagged"
                stab += f", step@{f.step_part}" if f.step_part else ""
            bayes = (
                f"{b.cp:>9.2f}{_ci(b.cp_interval):>15}{b.cpk:>10.2f}{_ci(b.cpk_interval):>15}"
                f"{b.p_cpk_above:>9.3f}"
                if b is not None
                else f"{'-':>58}"
            )
            lines.append(
                f"{f.feature:<10}{bayes}  {stab:<25}{p.cpk:>10.2f}{_ci(p.cpk_ci):>15}"
                f"{pw.cpk:>10.2f}{_ci(pw.cpk_ci):>15}"
            )
        lines += [
            "",
            "Cp, Cpk: within sigma (moving range), chi-square and Bissell intervals; Pp, Ppk: "
            "overall sigma. Bayes: i.i.d. normal values, prior 1/sigma (overall spread: compare "
            "with Pp, Ppk), equal-tailed credible intervals. 'Cpk after': the mean moved to the "
            "target by the compensation (gain "
            + ", ".join(sorted({f"{f.gain:g}" for f in self.features.values()}))
            + "), overall spread kept; 'if stable': with the within spread, i.e. if compensation "
            "also removed the drift and steps (per-part PIECS).",
        ]
        for part, feats in sorted(self.steps.items(), key=lambda kv: -len(kv[1])):
            if len(feats) > 1:
                lines.append(
                    f"STEP before {part} on {len(feats)} of {len(self.features)} features "
                    f"({', '.join(feats)}): a change of tool or setup there; the parts on either "
                    "side are different processes (do not pool them for a capability claim)"
                )
            else:
                lines.append(
                    f"step before {part} on {feats[0]} only: a drift can look like a step there"
                )
        for f in self.features.values():
            reasons = f.findings()
            if reasons or f.notes:
                lines.append(f"{f.feature}:")
                lines += [f"  - {r}" for r in reasons]
                lines += [f"  - {n}" for n in f.notes]
        if self.notes:
            lines.append("notes:")
            lines += [f"  - {n}" for n in self.notes]
        return "\n".join(lines)

    def __repr__(self) -> str:
        return self.text()


def _spans(idx, ids) -> str:
    """Indices as part-id ranges: `part01..part04, part09`."""
    idx = sorted(idx)
    out, start = [], None
    for k, i in enumerate(idx):
        if start is None:
            start = i
        if k + 1 == len(idx) or idx[k + 1] != i + 1:
            out.append(ids[start] if start == i else f"{ids[start]}..{ids[i]}")
            start = None
    return ", ".join(out)


def _ci(iv) -> str:
    lo, hi = iv
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return "-"
    return f"[{lo:.2f}, {hi:.2f}]"


def capability_from_values(
    values: Mapping[str, Sequence[float]],
    tolerances: Mapping[str, tuple[float, float]],
    *,
    parts: Mapping[str, Sequence[str]] | Sequence[str] | None = None,
    u: Mapping[str, Sequence[float]] | None = None,
    u_systematic: Mapping[str, float] | None = None,
    characteristic: str = "mid",
    gain: float = 1.0,
    confidence: float = 0.95,
    threshold: float = 1.33,
    sigma_method: str = "auto",
    subtract_gauge: bool = False,
    n_draws: int = 100_000,
    run_length: int = 8,
    trend_length: int = 7,
    seed: int = 0,
    study: str = "",
    method: str = "",
    notes: Sequence[str] = (),
) -> CapabilityStudy:
    """Capability, stability and predicted capability from per-part values (pure).

    **Arguments:**

    - `values`: by feature id, one value per part in production order (mm), e.g.
      normal deviations or posterior means.
    - `tolerances`: `(lower, upper)` by feature id; the target is the mid-point.
    - `parts`: part ids (one list for all features, or by feature).
    - `u`: per-part measurement uncertainties by feature (the gauge spread; subtracted
      from the variances only with `subtract_gauge`).
    - `u_systematic`: uncertainty of the realised mean shift by feature (mm).
    - `gain`: fraction of the mean error the predicted compensation removes.
    - the rest: see `compensate.capability` and `compensate.stability_check`.
    """
    feats = {}
    notes = list(notes)
    for fid, vals in values.items():
        y = np.asarray(vals, dtype=float)
        if isinstance(parts, Mapping):
            pid = tuple(parts[fid])
        elif parts is not None:
            pid = tuple(parts)
        else:
            pid = tuple(f"{i + 1}" for i in range(y.size))
        if len(pid) != y.size:
            raise InputError(f"{len(pid)} part ids for {y.size} values", feature=fid)
        uu = np.zeros(y.size) if u is None or fid not in u else np.asarray(u[fid], dtype=float)
        if y.size < 3:
            notes.append(f"{fid}: only {y.size} value(s); no capability")
            continue
        lo, hi = tolerances[fid]
        gauge = float(np.sqrt(np.mean(uu**2))) if subtract_gauge else 0.0
        try:
            cap = capability(
                y,
                lo,
                hi,
                sigma_method="mr" if sigma_method == "auto" else sigma_method,
                confidence=confidence,
                gauge_sd=gauge,
                threshold=threshold,
                n_draws=n_draws,
                seed=seed,
            )
        except AnalysisError as e:
            notes.append(f"{fid}: no capability: {e}")
            continue
        stab = stability_check(y, run_length=run_length, trend_length=trend_length)
        u_off = float((u_systematic or {}).get(fid, 0.0))
        kw = dict(u_offset=u_off, gain=gain, threshold=threshold, n_draws=n_draws, seed=seed)
        pred = predict_capability(cap, sigma="overall", **kw)
        pred_w = predict_capability(cap, sigma="within", **kw)
        fnotes = []
        if not stab.in_control:
            fnotes.append(
                "not in statistical control: Cp/Cpk (within sigma) describe what the "
                "process could do if stable; Pp/Ppk describe this run"
            )
        feats[fid] = FeatureCapability(
            feature=fid,
            tolerance=(float(lo), float(hi)),
            characteristic=characteristic,
            parts=pid,
            values=y,
            u=uu,
            capability=cap,
            stability=stab,
            predicted=pred,
            predicted_within=pred_w,
            gain=float(gain),
            notes=tuple(fnotes),
        )
    all_parts = tuple(dict.fromkeys(p for f in feats.values() for p in f.parts))
    return CapabilityStudy(
        study=study,
        parts=all_parts,
        method=method,
        features=MappingProxyType(feats),
        confidence=confidence,
        notes=tuple(notes),
    )


def capability_study(
    study,
    probe=None,
    *,
    files: Sequence | None = None,
    method: str | None = None,
    seed: int = 0,
    progress: Callable[[int, int, str], None] | None = None,
    scheduler=None,
    chunk_parts: int | None = None,
    **overrides,
) -> CapabilityStudy:
    """Fit every part of a run and study each feature's capability.

    **Arguments:**

    - `study`: the study; its probe files (one per part, or a `part` column) or
      `files` (paths) or `probe` (a `ProbeData`) give the parts in production order.
    - `method`: fit method (default the study's). A part whose fit fails is refitted
      with plain least squares and the note says so; a part that fails both is left out.
    - `progress`: called as `progress(i, n, part)` after each part (after each chunk of
      parts when the fits are batched).
    - `scheduler`, `chunk_parts`: the parts are fitted in batches of `chunk_parts`
      (one compiled call per feature kind; see `piecs_bayes._distributed`), in this
      process or, with `scheduler` (a Dask scheduler address or `distributed.Client`),
      on a Dask cluster. Joint fits (`fit.free_transform`) are fitted part by part.
    - `overrides`: any keyword of [`capability_from_values`][] (default: the study's
      `[capability]` table).

    **Returns:** a [`CapabilityStudy`][].
    """
    from .pipeline import fit_study, load_probe_data

    probe = probe if probe is not None else load_probe_data(study, files)
    cfg = {**study.capability, **overrides}
    at = cfg.pop("characteristic", "mid")
    cfg.setdefault("gain", study.compensation.gain)
    sds = _source_sds(study)
    parts = probe.parts
    if len(parts) < 3:
        raise InputError(
            f"a capability study needs at least 3 parts, got {len(parts)} in {probe.file}"
        )
    values: dict[str, list] = {}
    us: dict[str, list] = {}
    pids: dict[str, list] = {}
    usys: dict[str, float] = {}
    notes = []
    used = method or study.fit.method
    if used == "bayes":
        used = "robust"
        notes.append("per-part values from the robust fits (the study asks for bayes)")
    if not study.fit.free_transform:
        from ._distributed import CHUNK_PARTS, capability_values

        values, us, pids, usys, more = capability_values(
            study,
            probe,
            method=used,
            at=at,
            sources=sds,
            progress=progress,
            scheduler=scheduler,
            chunk_parts=chunk_parts or CHUNK_PARTS,
        )
        notes += more
        parts = ()  # fitted above; the loop below is for joint fits
    elif scheduler is not None:
        raise InputError("--scheduler: joint fits (fit.free_transform) run in-process only")
    for i, p in enumerate(parts):
        data = probe.for_part(p)
        try:
            fit = fit_study(study, data, method=used)
        except AnalysisError as e:
            if used == "lsq":
                notes.append(f"{p}: left out, the fit failed: {e}")
                continue
            try:
                fit = fit_study(study, data, method="lsq")
                notes.append(f"{p}: {used} fit failed ({e}); fitted with plain least squares")
            except AnalysisError as e2:
                notes.append(f"{p}: left out, the fit failed: {e2}")
                continue
        for f in fit:
            try:
                c = feature_characteristic(f, at=at, sources=sds)
            except AnalysisError as e:
                notes.append(f"{p}: {f.id} left out: {e}")
                continue
            values.setdefault(f.id, []).append(c.mean)
            us.setdefault(f.id, []).append(c.u_fit)
            pids.setdefault(f.id, []).append(p)
            usys[f.id] = c.u_systematic
        if progress is not None:
            progress(i + 1, len(parts), p)
    ordered = [fid for fid in study.profile.ids if fid in values]
    return capability_from_values(
        {fid: values[fid] for fid in ordered},
        {f.id: f.tolerance for f in study.profile.features},
        parts={fid: pids[fid] for fid in ordered},
        u={fid: us[fid] for fid in ordered},
        u_systematic=usys,
        characteristic=at,
        seed=seed,
        study=study.name,
        method=used,
        notes=notes,
        **cfg,
    )


# --------------------------------------------------------------------------- error spec


def _table_name(prefix: str, fid: str) -> str:
    return f"{prefix}_{re.sub(r'[^A-Za-z0-9_.-]', '_', fid)}"


def _axial(f) -> str | None:
    """ "x" for a diameter (outward normal along X), "z" for a face, else None."""
    if not isinstance(f, Line):
        return None
    n = np.asarray(f.normal)
    if abs(n[0]) >= _AXIAL:
        return "x"
    if abs(n[1]) >= _AXIAL:
        return "z"
    return None


def _gain_of(gain, fid) -> float:
    g = gain.get(fid, 0.0) if isinstance(gain, Mapping) else gain
    g = float(g)
    if not (math.isfinite(g) and 0.0 <= g <= 1.0):
        raise InputError(f"gain must be in [0, 1], got {g!r}", feature=fid, value=g)
    return g


def error_spec(study, fit, *, gain=None, points_per_feature: int | None = None) -> ErrorSpec:
    """The error specification (PIECS option 1) of one fitted part.

    Corrections are $-g\\,e$ with $e$ the error along the corrected machine axis (mm),
    machine positions, X as radius:

    - `x_<feature>` for every line that is not a face (diameters, tapers): the X
      correction (radius) as a function of Z along the feature, `points_per_feature`
      rows; on a taper the X move that restores the surface is $\\delta/n_x$;
    - `z_<feature>` for every face: the Z correction as a function of X;
    - `x_radius`: the X correction at each diameter's nominal radius as a function of
      X (diameter errors across diameters: an error that depends on the axis' own
      position, what a LinuxCNC joint table can hold);
    - `z_position`: the Z correction at each face's Z (idem for Z).

    Arcs get no table: their error is not along one axis; the adjusted program
    carries them. Standard uncertainties: $g\\sqrt{u_\\text{fit}^2 + u_\\text{sys}^2}
    /|n_\\text{axis}|$.

    **Arguments:** `gain` a number or a mapping by feature id (default the study's
    `compensation.gain`; e.g. `DecisionTable.gains`); `points_per_feature` (default the
    study's `[errspec]`, else 11).
    """
    gain = study.compensation.gain if gain is None else gain
    k = int(points_per_feature or study.errspec.get("points_per_feature", 11))
    ts = np.linspace(0.0, 1.0, k)
    sds = _source_sds(study)
    tables = []
    axis_rows: dict[str, list] = {"x": [], "z": []}
    for f in fit:
        feat = f.feature
        if not isinstance(feat, Line):
            continue
        g = _gain_of(gain, feat.id)
        n = np.asarray(feat.normal)
        axis = "z" if _axial(feat) == "z" else "x"
        pos_axis = "x" if axis == "z" else "z"
        na = n[0] if axis == "x" else n[1]
        val, jac = _dev_and_jac(feat, f.values, ts)
        cov = np.zeros((2, 2)) if f.covariance is None else np.asarray(f.covariance)
        u_fit = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jac, cov, jac), 0.0))
        u = np.hypot(u_fit, _u_systematic(feat, ts, sds))
        err = val / na  # error along the corrected axis
        q = _nominal(feat, tuple(float(t) for t in ts))[0]
        qm = np.asarray(part_to_machine(jnp.asarray(q), study.transform))
        pos = qm[:, 0] if pos_axis == "x" else qm[:, 1]
        corr = -g * err
        u_corr = g * u / abs(na)
        what = "radius" if axis == "x" else "position"
        tables.append(
            CompensationTable(
                name=_table_name(axis, feat.id),
                axis=axis,
                position_axis=pos_axis,
                position=pos,
                correction=corr,
                u_correction=u_corr,
                feature=(feat.id,) * k,
                description=f"{axis.upper()} correction ({what}) along {feat.id!r} as a function "
                f"of machine {pos_axis.upper()}, gain {g:g}",
            )
        )
        kind = _axial(feat)
        if kind is not None:  # the error at the mid-point, at the axis position
            mv, mj = _dev_and_jac(feat, f.values, [0.5])
            mv, mj = float(mv[0]), mj[0]
            u_mid = math.hypot(
                math.sqrt(max(float(mj @ cov @ mj), 0.0)),
                float(_u_systematic(feat, [0.5], sds)[0]),
            )
            qmid = np.asarray(part_to_machine(feat.midpoint[None], study.transform))[0]
            pos_mid = float(qmid[0] if kind == "x" else qmid[1])
            axis_rows[kind].append((pos_mid, -g * mv / na, g * u_mid, feat.id))
    for axis, rows in axis_rows.items():
        if not rows:
            continue
        pos, corr, u, ids = zip(*rows, strict=True)
        tables.append(
            CompensationTable(
                name="x_radius" if axis == "x" else "z_position",
                axis=axis,
                position_axis=axis,
                position=pos,
                correction=corr,
                u_correction=u,
                feature=ids,
                description=(
                    "X correction (radius) at each diameter's nominal radius: diameter errors "
                    "across diameters"
                    if axis == "x"
                    else "Z correction at each face's nominal Z: face errors across Z"
                ),
            )
        )
    return ErrorSpec(
        tables=tuple(tables),
        description=f"{study.name}: PIECS error specification from the fit of part "
        f"{fit.part or '-'} ({fit.method})",
        source={
            "study": str(study.path),
            "part": fit.part,
            "method": fit.method,
            "gain": dict(gain) if isinstance(gain, Mapping) else float(gain),
            "piecs_bayes": _version(),
        },
    )


def _version() -> str:
    from . import __version__

    return __version__


# --------------------------------------------------------------------------- tool offsets


def offset_settings(study) -> OffsetSettings:
    """[`OffsetSettings`][piecs_bayes.export.OffsetSettings] from the study's `[offsets]`."""
    keys = ("null_band", "feedback_gain", "upper_limit", "k_significance", "decimals")
    spec = {k: study.offsets[k] for k in keys if k in study.offsets}
    try:
        return OffsetSettings(**spec)
    except InputError as e:
        raise InputError(f"offsets: {e.reason}", file=str(study.path), value=e.value) from None


def _combine(chars: Sequence[Characteristic], factor) -> tuple[float, float, float]:
    """Inverse-variance mean of `factor * mean` over characteristics, its random
    uncertainty and the (common, not averaged) systematic one."""
    e = np.array([c.mean * fa for c, fa in zip(chars, factor, strict=True)])
    uf = np.array([max(c.u_fit, 1e-12) for c in chars])
    w = 1.0 / uf**2
    mean = float(np.sum(w * e) / np.sum(w))
    u_rand = float(1.0 / math.sqrt(np.sum(w)))
    u_sys = float(np.mean([c.u_systematic for c in chars]))
    return mean, u_rand, u_sys


def tool_offsets(study, fit) -> tuple[ToolOffsetUpdate, tuple[str, ...]]:
    """Wear-offset update (PIECS option c) from one fitted part, and notes.

    - X: the inverse-variance mean radial error of the diameters (cylindrical lines,
      or `[offsets] x_features`) at their mid-points, as a diameter error in
      `x_mode = "diameter"` (default);
    - Z: the mean Z error of the faces (or `z_features`);
    - R: the effective minus the table nose radius from the arcs' radius changes
      ($-s\\,\\Delta r$, $s$ = +1 convex, -1 concave: a larger nose moves every surface
      into the material), used with `nose_radius = "auto"` (default) only when it is
      significant ($|e| > 2u$), always with `"always"`, never with `"off"`. When R
      changes, the X and Z errors it explains are taken off them (this assumes the
      finish cut uses G41/G42 nose-radius compensation).

    Null band, feedback gain and upper limit come from `[offsets]`.
    """
    cfg = study.offsets
    st = offset_settings(study)
    x_mode = cfg.get("x_mode", "diameter")
    tool = int(cfg.get("tool", 1))
    sds = _source_sds(study)
    fitted = {f.id: f for f in fit}
    notes = []

    def pick(key, kind):
        ids = cfg.get(key)
        if ids is None:
            return [fid for fid, f in fitted.items() if _axial(f.feature) == kind]
        missing = [fid for fid in ids if fid not in fitted]
        if missing:
            notes.append(f"{key}: {', '.join(missing)} not measured on this part")
        bad = [fid for fid in ids if fid in fitted and _axial(fitted[fid].feature) != kind]
        if bad:
            raise InputError(
                f"offsets.{key}: {', '.join(bad)} is not a "
                f"{'diameter' if kind == 'x' else 'face'} (a line normal to "
                f"{kind.upper()})",
                file=str(study.path),
                value=bad,
            )
        return [fid for fid in ids if fid in fitted]

    xs = [feature_characteristic(fitted[i], at="mid", sources=sds) for i in pick("x_features", "x")]
    zs = [feature_characteristic(fitted[i], at="mid", sources=sds) for i in pick("z_features", "z")]
    x_err = u_x = z_err = u_z = None
    nx = 1.0
    if xs:
        nxs = [c.normal[0] for c in xs]
        nx = float(np.mean(nxs))
        x_err, ur, us = _combine(xs, nxs)
        u_x = math.hypot(ur, us)
        radial = np.array([c.mean * n for c, n in zip(xs, nxs, strict=True)])
        u_each = np.array([max(c.u_fit, 1e-12) for c in xs])
        dof = len(xs) - 1
        chi2 = float(np.sum(((radial - x_err) / u_each) ** 2))
        if dof > 0 and chi2 > dof + 3.0 * math.sqrt(2.0 * dof):
            each = ", ".join(f"{c.feature} {v * 1e3:+.1f}" for c, v in zip(xs, radial, strict=True))
            notes.append(
                f"the diameters disagree beyond their uncertainties (radial errors {each} um; "
                f"chi2 {chi2:.0f} on {dof} dof): a tool offset corrects only their mean, the "
                "error spec or the adjusted program corrects each"
            )
    nz = 1.0
    if zs:
        nzs = [c.normal[1] for c in zs]
        nz = float(np.mean(nzs))
        z_err, ur, us = _combine(zs, nzs)
        u_z = math.hypot(ur, us)
    # nose radius from the arcs
    r_err = u_r = None
    mode = cfg.get("nose_radius", "auto")
    arcs = [
        f
        for f in fitted.values()
        if isinstance(f.feature, Arc) and "radius" not in f.fixed and f.covariance is not None
    ]
    if mode != "off" and arcs:
        e = np.array([-f.feature.sense * f.values[2] for f in arcs])
        u = np.array([max(math.sqrt(f.covariance[2, 2]), 1e-12) for f in arcs])
        w = 1.0 / u**2
        est, u_est = float(np.sum(w * e) / np.sum(w)), float(1.0 / math.sqrt(np.sum(w)))
        ids = ", ".join(f.id for f in arcs)
        if mode == "always" or abs(est) > 2.0 * u_est:
            r_err, u_r = est, u_est
            notes.append(
                f"nose radius from {ids}: effective minus table radius {est * 1e3:+.2f} "
                f"± {u_est * 1e3:.2f} um"
            )
        else:
            notes.append(
                f"nose radius not updated: the radius change of {ids} gives "
                f"{est * 1e3:+.2f} ± {u_est * 1e3:.2f} um, not significant (|e| <= 2u)"
            )
    xs_factor = 2.0 if x_mode == "diameter" else 1.0

    def update(x_e, z_e):
        return tool_offset_update(
            tool,
            x_error=None if x_e is None else xs_factor * x_e,
            u_x=0.0 if u_x is None else xs_factor * u_x,
            z_error=z_e,
            u_z=0.0 if u_z is None else u_z,
            nose_radius_error=r_err,
            u_r=0.0 if u_r is None else u_r,
            settings=st,
            x_mode=x_mode,
        )

    if x_err is None and z_err is None and r_err is None:
        raise AnalysisError(
            "no tool-offset update: no diameter, face or significant arc was measured"
        )
    upd = update(x_err, z_err)
    if upd.r.applied and not upd.blocked:
        d_r = upd.r.correction  # surfaces move out of the material by this much
        upd = update(
            None if x_err is None else x_err + d_r * nx,
            None if z_err is None else z_err + d_r * nz,
        )
        notes.append(
            f"X and Z errors corrected for the nose-radius change {d_r * 1e3:+.2f} um "
            "(assumes G41/G42 nose-radius compensation in the finish cut)"
        )
    return upd, tuple(notes)


# --------------------------------------------------------------------------- writing


@dataclass(frozen=True, eq=False)
class CompensationOutputs:
    """What [`write_compensation_outputs`][] wrote and refused, with notes."""

    errspec: ErrorSpec
    offsets: ToolOffsetUpdate | None
    written: tuple[Path, ...]
    refused: tuple[str, ...]
    notes: tuple[str, ...] = ()
    linuxcnc: Mapping[str, Path] = field(default_factory=dict)

    def lines(self) -> list[str]:
        out = [f"error spec: {len(self.errspec.tables)} table(s)"]
        for name, p in self.linuxcnc.items():
            out.append(f"LinuxCNC comp table {p.name}: {name}")
        out += [f"not written as a LinuxCNC table: {r}" for r in _grouped(self.refused)]
        if self.offsets is not None:
            out += [f"tool offsets: {line}" for line in repr(self.offsets).splitlines()]
        out += [f"note: {n}" for n in self.notes]
        return out


def _ini_text(files: Mapping[str, Path], comp_type: int, units: str, refused) -> str:
    joints = {"x": 0, "z": 1}
    lines = [
        "# LinuxCNC joint compensation written by piecs-bayes: copy into the machine's INI.",
        "# Positions and trims in machine units "
        f"({units}), X as radius. Joint numbers assume an XZ",
        "# lathe (trivkins: X = joint 0, Z = joint 1): check yours. BACKLASH is ignored",
        "# when COMP_FILE is set.",
    ]
    for name, p in files.items():
        axis = "x" if name.startswith("x") else "z"
        lines += [
            "",
            f"[JOINT_{joints[axis]}]",
            f"COMP_FILE = {p.name}",
            f"COMP_FILE_TYPE = {comp_type}",
        ]
    if refused:
        lines += ["", "# Not written as LinuxCNC tables (the format cannot express them):"]
        lines += [f"#   {r}" for r in _grouped(refused)]
    return "\n".join(lines) + "\n"


def write_compensation_outputs(study, fit, out, *, gain=None, protect=()) -> CompensationOutputs:
    """Write the error spec (native JSON + CSV), the LinuxCNC table(s) and the
    tool-offset update of one fitted part into folder `out`.

    Files: `compensation.errspec.json` + `compensation.<table>.csv`;
    `linuxcnc_x.comp`, `linuxcnc_z.comp` (`COMP_FILE_TYPE` from `[errspec] comp_type`,
    default 0) and `linuxcnc_comp.ini` (the INI lines, and the tables refused with
    the reason); `tool_offsets.json`, `tool_offsets_fanuc.ngc` (incremental
    `G10 P U W C`, or absolute with the current values) and
    `tool_offsets_linuxcnc.ngc` (`G10 L1`, absolute: only when `[offsets]` gives the
    current values). Every file is re-read and validated after writing. A blocked
    offset update writes only the JSON (which says why).
    """
    out = Path(out)
    protect = list(protect)
    cfg = study.errspec
    comp_type = int(cfg.get("comp_type", 0))
    units = cfg.get("machine_units", "mm")
    decimals = int(cfg.get("decimals", 6))
    spec = error_spec(study, fit, gain=gain)
    written = list(write_errspec(spec, out / "compensation.errspec.json", protect=protect))
    back = read_errspec(out / "compensation.errspec.json")
    if [t.name for t in back.tables] != [t.name for t in spec.tables]:
        raise AnalysisError("the written error spec does not read back as written")
    refused, comp_files = [], {}
    for t in spec.tables:
        try:  # refused before anything is written; re-read by LinuxCNC's rules after
            p = write_linuxcnc_comp(
                out / f"linuxcnc_{t.axis}.comp",
                t,
                comp_type=comp_type,
                decimals=decimals,
                machine_units=units,
                protect=protect,
            )
        except AnalysisError as e:
            refused.append(f"{t.name}: {str(e).split('refused: ', 1)[-1]}")
            continue
        comp_files[t.name] = p
        written.append(p)
    written.append(
        write_text_atomic(
            out / "linuxcnc_comp.ini",
            _ini_text(comp_files, comp_type, units, refused),
            protect=protect,
        )
    )
    notes: list[str] = []
    upd = None
    try:
        upd, onotes = tool_offsets(study, fit)
        notes += onotes
    except AnalysisError as e:
        notes.append(str(e))
    if upd is not None:
        p = write_text_atomic(out / "tool_offsets.json", offsets_to_json(upd), protect=protect)
        offsets_from_json(p.read_text(), file=str(p))  # re-read and validated
        written.append(p)
        if upd.blocked:
            notes.append(f"tool offsets: no G10 written: {upd.reasons[0]}")
        else:
            cur = study.offsets
            current = ToolOffsets(cur.get("current_x"), cur.get("current_z"), cur.get("current_r"))
            has_current = any(v is not None for v in (current.x, current.z, current.r))
            fanuc = g10_fanuc(upd, current=current if has_current else None)
            written.append(
                write_text_atomic(out / "tool_offsets_fanuc.ngc", fanuc, protect=protect)
            )
            try:
                text = g10_linuxcnc(upd, current=current)
            except InputError as e:
                notes.append(
                    f"tool_offsets_linuxcnc.ngc not written: {e.reason} "
                    "([offsets] current_x, current_z, current_r)"
                )
            else:
                written.append(
                    write_text_atomic(out / "tool_offsets_linuxcnc.ngc", text, protect=protect)
                )
    return CompensationOutputs(
        errspec=spec,
        offsets=upd,
        written=tuple(written),
        refused=tuple(refused),
        notes=tuple(notes),
        linuxcnc=MappingProxyType(comp_files),
    )


# --------------------------------------------------------------------------- helpers


def _grouped(refused: Sequence[str]) -> list[str]:
    """'name: why' lines with the same reason merged: 'a, b: why'."""
    by: dict[str, list[str]] = {}
    for r in refused:
        name, _, why = r.partition(": ")
        by.setdefault(why, []).append(name)
    return [f"{', '.join(names)}: {why}" for why, names in by.items()]


def _clean(obj):
    """JSON-safe: NaN/inf -> None, numpy -> Python, tuples -> lists (recursively)."""
    if isinstance(obj, Mapping):
        return {str(k): _clean(v) for k, v in obj.items()}
    if isinstance(obj, list | tuple):
        return [_clean(v) for v in obj]
    if isinstance(obj, np.ndarray):
        return _clean(obj.tolist())
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    return obj
