"""What the process is capable of over a run of parts: capability, stability and the
capability predicted after compensation, per feature.

Per part and feature the value is the characteristic (normal deviation $\\delta$ at a
fixed nominal point, `piecs_bayes.uncertainty.feature_characteristic`); the parts are
fitted in batches ([`capability_values`][piecs_bayes.jobs.capability_values], also
on Dask) or, for joint fits, one by one. The study works on each feature's deviation
**as drawn** (`tolerance_on`: $2\\delta$ on a diameter, $\\pm\\delta$ on Z for a face,
$\\delta$ along the normal for tapers and arcs; `geometry.drawn_scale`), with the
tolerance as drawn: the values, limits, means, sigmas, control limits and steps are
lengths on that coordinate. Cp, Cpk, Pp, Ppk are invariant to the conversion (a scale
$k$ multiplies the values and the limits alike; with $k < 0$, a bore's diameter or a
face facing -Z, the lower and upper limits trade places, and so do Cpl and Cpu).
`export.capability_json` and `capability_text` render the study.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from types import MappingProxyType

import numpy as np

from ..capability import (
    CapabilityOptions,
    CapabilityResult,
    PredictedCapability,
    StabilityResult,
    capability,
    predict_capability,
    stability_check,
)
from ..decide import ConformityRisk, GuardBand, ProcessPrior, conformity_risk
from ..errors import AnalysisError, InputError
from ..fit import CHUNK_PARTS
from ..geometry import drawn_scale
from ..io import rows_to_dataframe
from ..uncertainty import feature_characteristic
from ._batch import capability_values
from ._fit import fit_study, load_probe_data
from ._options import source_sds


@dataclass(frozen=True, eq=False)
class FeatureCapability:
    """Capability of one feature's characteristic over the parts of a run.

    `values` (mm) in production order with their measurement uncertainties `u`;
    `capability` (Cp, Cpk, Pp, Ppk with confidence intervals, Bayesian credible
    intervals), `stability` (individuals / moving-range chart), `predicted` the
    capability after shifting the mean by `-gain * (mean - target)` with the
    overall spread kept, `predicted_within` the same with the within-part
    (moving-range) spread, i.e. if compensation also removed the drift and steps.

    The measuring process (VDA 5 / ISO 22514-7): one measured value's standard
    uncertainty `u_mp` combines the parts' fit uncertainties (rms of `u`: probe
    repeatability and form, the part's own scatter about its model) with
    `u_systematic` (the study's budget: calibration, machine, temperature), and
    `q_mp = 2 k u_mp / T` must not exceed `q_mp_limit` for the process to be called
    capable ([`verdict`][]). `corrected` holds the indices with the measurement's
    random share taken off the spread (observed = process + measurement:
    $\\sigma_p^2 = \\sigma^2 - \\bar u^2$, $\\bar u$ the rms of `u`); None when the
    measurement's variance is not below the observed one.

    Every length (`values`, `u`, `tolerance` and those of `capability`, `stability`,
    `predicted`) is as drawn: on `coordinate` (`"diameter"`, `"radius"`, `"length"`
    or `"normal"`), `scale` times the normal deviation; `normal_values`,
    `normal_u` and `normal_tolerance` give them back as normal deviations.
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
    coordinate: str = "normal"
    scale: float = 1.0
    u_systematic: float = 0.0
    corrected: CapabilityResult | None = None
    threshold: float = 1.33
    q_mp_limit: float = 0.30
    coverage_factor: float = 2.0

    @property
    def normal_values(self) -> np.ndarray:
        """The values as normal deviations (mm): `values / scale`."""
        return self.values / self.scale

    @property
    def normal_u(self) -> np.ndarray:
        """The measurement uncertainties of the normal deviations (mm)."""
        return self.u / abs(self.scale)

    @property
    def normal_tolerance(self) -> tuple[float, float]:
        """The tolerance as limits of the normal deviation (mm), ordered."""
        lo, hi = sorted(v / self.scale for v in self.tolerance)
        return float(lo), float(hi)

    @property
    def drawn_as(self) -> str:
        """The coordinate in words: "on the diameter", "on Z", "along the normal", ..."""
        return _ON_WORDS.get(self.coordinate, f"on the {self.coordinate}")

    def as_normal(self, x: float) -> float:
        """A length as drawn (a value, mean or step) as a normal deviation."""
        return float(x) / self.scale

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
        out, on = [], self.drawn_as
        if s.beyond_limits:
            out.append(
                f"{len(s.beyond_limits)} part(s) beyond the 3-sigma limits "
                f"[{s.lcl * 1e3:+.2f}, {s.ucl * 1e3:+.2f}] um {on}: "
                f"{_spans(s.beyond_limits, ids)}"
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
                f"likely step of {s.step_size * 1e3:+.2f} um {on} before {self.step_part} "
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

    @property
    def u_gauge(self) -> float:
        """The measurement's random share of the spread (as drawn): the rms of `u`."""
        return float(np.sqrt(np.mean(self.u**2)))

    @property
    def u_mp(self) -> float:
        """Standard uncertainty of one measured value (as drawn, mm): the rms of the
        parts' `u` combined with `u_systematic`."""
        return math.hypot(self.u_gauge, self.u_systematic)

    @property
    def U_mp(self) -> float:  # noqa: N802 - the symbol of the standard
        """Expanded uncertainty of the measuring process, `coverage_factor * u_mp`."""
        return self.coverage_factor * self.u_mp

    @property
    def q_mp(self) -> float:
        """Capability ratio of the measuring process, $Q_{MP} = 2 U_{MP} / T$."""
        lo, hi = self.tolerance
        return 2.0 * self.U_mp / (hi - lo)

    @property
    def measuring_process_capable(self) -> bool:
        """True when `q_mp` is within `q_mp_limit`."""
        return self.q_mp <= self.q_mp_limit

    @property
    def judged_by(self) -> tuple[str, float]:
        """The index the verdict reads: `("Cpk", cpk)` for a process in statistical
        control, else `("Ppk", ppk)` (an unstable process has no capability to
        speak of, only this run's performance; AIAG SPC manual)."""
        c = self.capability
        return ("Cpk", c.cpk) if self.stability.in_control else ("Ppk", c.ppk)

    @property
    def verdict(self) -> str:
        """`"capable"` (the index of `judged_by` at least `threshold`), `"not capable"`,
        or, when the measuring process is not capable of the tolerance (`q_mp` above
        its limit), `"measuring process not capable"`: the spread measured is then as
        much the gauge's as the process's, and no capability is claimed either way."""
        if not self.measuring_process_capable:
            return "measuring process not capable"
        return "capable" if self.judged_by[1] >= self.threshold else "not capable"

    def verdict_reason(self) -> str:
        """The verdict in one sentence with its numbers (µm as drawn)."""
        q, lim = self.q_mp, self.q_mp_limit
        if not self.measuring_process_capable:
            return (
                f"Q_MP = {q:.0%} > {lim:.0%}: the measuring process (U_MP = "
                f"{self.U_mp * 1e3:.2f} um, k = {self.coverage_factor:g}) takes too much of "
                f"the tolerance to judge the process; improve or qualify the measurement "
                f"first (VDA 5)"
            )
        name, v = self.judged_by
        rel = ">=" if v >= self.threshold else "<"
        why = "" if name == "Cpk" else " (not in statistical control: this run's performance)"
        return f"{name} {v:.2f} {rel} {self.threshold:g}{why}, Q_MP = {q:.0%} <= {lim:.0%}"

    def risks(self, target: float = 0.02) -> tuple[ConformityRisk, ConformityRisk] | None:
        """The global conformity risks of judging this run's parts by their measured
        values (JCGM 106, 9.5; as drawn): the process prior N(mean, sigma_p) with the
        measurement's share taken off the overall spread, sigma_p^2 = sigma_overall^2 -
        u_gauge^2 (u_gauge: the rms of the parts' u), and the measurement N(0, u_gauge).
        First with the tolerance as the acceptance zone, then with the guard band at
        which the global consumer's risk is `target`. None when the gauge's u is not
        below the overall spread (the process cannot be told from the gauge)."""
        c = self.capability
        gauge = self.u_gauge
        var = c.sigma_overall**2 - gauge**2
        if not (gauge > 0.0 and var > 0.0 and math.isfinite(var)):
            return None
        prior = ProcessPrior(c.mean, math.sqrt(var))
        tol = (c.lsl, c.usl)
        kw = dict(process=prior, u_measurement=gauge)
        plain = conformity_risk(tol, **kw)
        return plain, conformity_risk(tol, guard_band=GuardBand("target", target=target), **kw)

    def summary(self) -> dict:
        """One row: the coordinate, the lengths as drawn (`*_drawn_mm`), the indices,
        stability and prediction, then the lengths as normal deviations (`*_mm`)."""
        c, b, s = self.capability, self.capability.bayes, self.stability
        k = abs(self.scale)
        gauge = self.u_gauge
        row = {
            "feature": self.feature,
            "at": self.characteristic,
            "coordinate": self.coordinate,
            "n": c.n,
            "lsl_drawn_mm": c.lsl,
            "usl_drawn_mm": c.usl,
            "mean_drawn_mm": c.mean,
            "sigma_within_drawn_mm": c.sigma_within,
            "sigma_overall_drawn_mm": c.sigma_overall,
            "gauge_sd_drawn_mm": gauge,
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
        risks = self.risks()
        row["process_sd_drawn_mm"] = risks[0].process.sd if risks else math.nan
        row["global_consumer_risk"] = risks[0].global_consumer_risk if risks else math.nan
        row["global_producer_risk"] = risks[0].global_producer_risk if risks else math.nan
        row["guard_band_2pct_drawn_mm"] = risks[1].guard_band if risks else math.nan
        row["u_mp_drawn_mm"] = self.u_mp
        row["U_mp_drawn_mm"] = self.U_mp
        row["q_mp"] = self.q_mp
        row["q_mp_limit"] = self.q_mp_limit
        row["measuring_process_capable"] = self.measuring_process_capable
        cc = self.corrected
        for name in ("cp", "cpk", "pp", "ppk"):
            row[f"{name}_corrected"] = math.nan if cc is None else getattr(cc, name)
        row["verdict"] = self.verdict
        row["in_control"] = s.in_control
        row["n_out_of_control"] = len(s.out_of_control)
        row["step_part"] = self.step_part or ""
        step = s.step_size if self.step_part else math.nan
        row["step_drawn_mm"] = step
        row["step_t"] = s.step_t
        row["gain"] = self.gain
        for tag, p in (("after", self.predicted), ("after_within", self.predicted_within)):
            row[f"cpk_{tag}"] = p.cpk
            row[f"cpk_{tag}_lower"], row[f"cpk_{tag}_upper"] = p.cpk_ci
            row[f"bayes_cpk_{tag}"] = p.cpk_bayes
            row[f"bayes_cpk_{tag}_lower"], row[f"bayes_cpk_{tag}_upper"] = p.cpk_bayes_interval
        row["lsl_mm"], row["usl_mm"] = self.normal_tolerance
        row["mean_mm"] = self.as_normal(c.mean)
        row["sigma_within_mm"] = c.sigma_within / k
        row["sigma_overall_mm"] = c.sigma_overall / k
        row["gauge_sd_mm"] = gauge / k
        row["step_mm"] = self.as_normal(step) if self.step_part else math.nan
        return row

    def __repr__(self) -> str:
        c, s = self.capability, self.stability
        state = "in control" if s.in_control else "NOT in control"
        step = f", step before {self.step_part}" if self.step_part else ""
        return (
            f"FeatureCapability({self.feature!r} at {self.characteristic} on "
            f"{self.coordinate}, n={c.n}, "
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
        """One row per feature: limits, mean, sigmas (as drawn), indices, stability,
        prediction, then the lengths as normal deviations."""
        return [f.summary() for f in self.features.values()]

    def to_dataframe(self, table: str = "summary"):
        """A `pandas.DataFrame` of `table`: "summary" (`summary_rows()`,
        capability_summary.csv), "indices" (`index_rows()`, capability.csv) or "parts"
        (`part_rows()`, capability_parts.csv); docs/formats.md has the columns."""
        tables = {"summary": self.summary_rows, "indices": self.index_rows,
                  "parts": self.part_rows}  # fmt: skip
        if table not in tables:
            raise ValueError(f"unknown table {table!r}; expected one of {', '.join(tables)}")
        return rows_to_dataframe(tables[table]())

    def index_rows(self) -> list[dict]:
        """One row per feature and index (value, confidence and credible intervals);
        Cpl and Cpu are those of the lower and upper limits as drawn."""
        out = []
        for f in self.features.values():
            for r in f.capability.table():
                out.append({"feature": f.feature, "coordinate": f.coordinate, **r})
            for tag, p in (("after", f.predicted), ("after_within", f.predicted_within)):
                lo_b, hi_b = p.cpk_bayes_interval
                out.append(
                    {
                        "feature": f.feature,
                        "coordinate": f.coordinate,
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
        """One row per part and feature: value, uncertainty, moving range and control
        limits as drawn (`*_drawn_mm`), the flags, then the same as normal deviations."""
        out = []
        for f in self.features.values():
            s, k = f.stability, f.scale
            lcl, ucl = sorted((s.lcl / k, s.ucl / k))
            for i, (p, v, u) in enumerate(zip(f.parts, f.values, f.u, strict=True)):
                mr = float(abs(v - f.values[i - 1])) if i else math.nan
                out.append(
                    {
                        "part": p,
                        "feature": f.feature,
                        "coordinate": f.coordinate,
                        "value_drawn_mm": float(v),
                        "u_drawn_mm": float(u),
                        "moving_range_drawn_mm": mr,
                        "center_drawn_mm": s.center,
                        "lcl_drawn_mm": s.lcl,
                        "ucl_drawn_mm": s.ucl,
                        "flags": f.flags(i),
                        "value_mm": f.as_normal(v),
                        "u_mm": float(u) / abs(k),
                        "moving_range_mm": mr / abs(k),
                        "center_mm": f.as_normal(s.center),
                        "lcl_mm": lcl,
                        "ucl_mm": ucl,
                    }
                )
        return out

    def __repr__(self) -> str:
        return (
            f"CapabilityStudy({self.study!r}: {len(self.parts)} parts, "
            f"{len(self.features)} features, fits {self.method})"
        )


#: the coordinate of a drawn length, in words
_ON_WORDS = {"diameter": "on the diameter", "radius": "on the radius", "length": "on Z",
             "normal": "along the normal"}  # fmt: skip


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


def capability_from_values(
    values: Mapping[str, Sequence[float]],
    tolerances: Mapping[str, tuple[float, float]] | None = None,
    *,
    profile=None,
    parts: Mapping[str, Sequence[str]] | Sequence[str] | None = None,
    u: Mapping[str, Sequence[float]] | None = None,
    u_systematic: Mapping[str, float] | None = None,
    options: CapabilityOptions = CapabilityOptions(),
    study: str = "",
    method: str = "",
    notes: Sequence[str] = (),
) -> CapabilityStudy:
    """Capability, stability and predicted capability from per-part values (pure).

    **Arguments:**

    - `values`: by feature id, one value per part in production order (mm), e.g.
      normal deviations or posterior means.
    - `tolerances`: `(lower, upper)` by feature id; the target is the mid-point.
      With `profile` they limit the normal deviation (`Feature.tolerance`, the
      default), else the values as given.
    - `profile`: the study's profile (features by id): `values`, `u`, `u_systematic`
      and `tolerances` are normal deviations and are studied as drawn, each on its
      feature's `tolerance_on` (`geometry.drawn_scale`: twice the value on a
      diameter, ...). Without it they are studied as given (coordinate `"normal"`).
    - `parts`: part ids (one list for all features, or by feature).
    - `u`: per-part measurement uncertainties by feature (the gauge spread; subtracted
      from the variances only with `options.subtract_gauge`).
    - `u_systematic`: uncertainty of the realised mean shift by feature (mm).
    - `options`: a [`CapabilityOptions`][piecs_bayes.capability.CapabilityOptions]:
      the `characteristic` the values are of, the `gain` of the predicted compensation
      (fraction of the mean error it removes), and the settings of
      `capability.capability` and `capability.stability_check`.
    - `study`, `method`, `notes`: the study's name, the fit method of the values and
      notes, kept with the result.
    """
    if tolerances is None and profile is None:
        raise InputError("capability_from_values needs the tolerances or the profile")
    feats = {}
    notes = list(notes)
    for fid, vals in values.items():
        on, k, tol = _drawn(fid, profile, tolerances)
        y = k * np.asarray(vals, dtype=float)
        if isinstance(parts, Mapping):
            pid = tuple(parts[fid])
        elif parts is not None:
            pid = tuple(parts)
        else:
            pid = tuple(f"{i + 1}" for i in range(y.size))
        if len(pid) != y.size:
            raise InputError(f"{len(pid)} part ids for {y.size} values", feature=fid)
        uu = abs(k) * (np.zeros(y.size) if u is None or fid not in u else np.asarray(u[fid]))
        if y.size < 3:
            notes.append(f"{fid}: only {y.size} value(s); no capability")
            continue
        try:
            feats[fid] = _feature_capability(
                fid, y, pid, uu, tol, abs(k) * float((u_systematic or {}).get(fid, 0.0)),
                coordinate=on, scale=k, options=options,
            )  # fmt: skip
        except AnalysisError as e:
            notes.append(f"{fid}: no capability: {e}")
    all_parts = tuple(dict.fromkeys(p for f in feats.values() for p in f.parts))
    return CapabilityStudy(
        study=study,
        parts=all_parts,
        method=method,
        features=MappingProxyType(feats),
        confidence=options.confidence,
        notes=tuple(notes),
    )


def _drawn(fid: str, profile, tolerances) -> tuple[str, float, tuple[float, float]]:
    """`(coordinate, scale, tolerance as drawn)` of feature `fid` (see
    [`capability_from_values`][]); without a profile the values are taken as given."""
    if profile is None:
        if fid not in tolerances:
            raise InputError("no tolerance for this feature", feature=fid)
        return "normal", 1.0, tuple(float(v) for v in tolerances[fid])
    try:
        feat = profile[fid]
    except (KeyError, ValueError, IndexError):
        raise InputError("not a feature of the profile", feature=fid) from None
    k = drawn_scale(feat)
    lo, hi = tolerances[fid] if tolerances and fid in tolerances else feat.tolerance
    return feat.tolerance_on, k, tuple(sorted((k * float(lo), k * float(hi))))


def _feature_capability(
    fid, y, pid, uu, tolerance, u_off, *, coordinate, scale, options: CapabilityOptions
) -> FeatureCapability:
    """One feature's capability, stability and predicted capability (see
    [`capability_from_values`][]) of the values `y` as drawn (on `coordinate`, `scale`
    times the normal deviation); `AnalysisError` when the indices cannot be had."""
    lo, hi = tolerance
    u_rms = float(np.sqrt(np.mean(uu**2)))
    if options.sigma_method == "auto":  # individuals: the moving range
        options = replace(options, sigma_method="mr")
    cap = capability(y, lo, hi, gauge_sd=u_rms if options.subtract_gauge else 0.0,
                     options=options)  # fmt: skip
    fnotes = []
    corrected = cap if options.subtract_gauge else None
    if corrected is None and u_rms > 0.0:
        try:
            corrected = capability(y, lo, hi, gauge_sd=u_rms, options=replace(options, bayes=False))
        except AnalysisError as e:
            fnotes.append(f"no indices corrected for measurement variation: {e}")
    elif corrected is None:
        corrected = cap
    stab = stability_check(y, run_length=options.run_length, trend_length=options.trend_length)
    kw = dict(u_offset=u_off, options=options)
    if not stab.in_control:
        fnotes.append(
            "not in statistical control: Cp/Cpk (within sigma) describe what the "
            "process could do if stable; Pp/Ppk describe this run"
        )
    return FeatureCapability(
        feature=fid,
        tolerance=(float(lo), float(hi)),
        characteristic=options.characteristic,
        parts=pid,
        values=y,
        u=uu,
        capability=cap,
        stability=stab,
        predicted=predict_capability(cap, sigma="overall", **kw),
        predicted_within=predict_capability(cap, sigma="within", **kw),
        gain=float(options.gain),
        notes=tuple(fnotes),
        coordinate=coordinate,
        scale=float(scale),
        u_systematic=float(u_off),
        corrected=corrected,
        threshold=float(options.threshold),
        q_mp_limit=float(options.q_mp_limit),
        coverage_factor=float(options.coverage_factor),
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
      (one compiled call per feature kind; see `piecs_bayes.jobs.capability_values`), in this
      process or, with `scheduler` (a Dask scheduler address or `distributed.Client`),
      on a Dask cluster. Joint fits (`fit.free_transform`) are fitted part by part.
    - `seed`, `overrides`: fields of the
      [`CapabilityOptions`][piecs_bayes.capability.CapabilityOptions] (default: the
      study's `[capability]` table; its `gain`, the study's `[compensation] gain`).

    **Returns:** a [`CapabilityStudy`][], each feature as drawn (its `tolerance_on`).
    """
    probe = probe if probe is not None else load_probe_data(study, files)
    options = CapabilityOptions(
        **{"gain": study.compensation.gain, **study.capability, **overrides, "seed": seed}
    )
    at = options.characteristic
    sds = source_sds(study)
    parts = probe.parts
    if len(parts) < 3:
        raise InputError(
            f"a capability study needs at least 3 parts, got {len(parts)} in {probe.file_text}"
        )
    notes = []
    used = method or study.fit.method
    if used == "bayes":
        used = "robust"
        notes.append("per-part values from the robust fits (the study asks for bayes)")
    if not study.fit.free_transform:
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
    elif scheduler is not None:
        raise InputError("--scheduler: joint fits (fit.free_transform) run in-process only")
    else:
        values, us, pids, usys, more = _joint_values(study, probe, used, at, sds, progress)
    notes += more
    ordered = [fid for fid in study.profile.ids if fid in values]
    return capability_from_values(
        {fid: values[fid] for fid in ordered},
        {f.id: f.tolerance for f in study.profile.features},
        profile=study.profile,
        parts={fid: pids[fid] for fid in ordered},
        u={fid: us[fid] for fid in ordered},
        u_systematic=usys,
        options=options,
        study=study.name,
        method=used,
        notes=notes,
    )


def _joint_values(study, probe, used: str, at: str, sds, progress):
    """Per-part characteristics of joint fits (`fit.free_transform`), part by part, in
    the form `capability_values` returns them. A failed fit is retried with plain
    least squares; a part that fails both is left out (said in the notes)."""
    values: dict[str, list] = {}
    us: dict[str, list] = {}
    pids: dict[str, list] = {}
    usys: dict[str, float] = {}
    notes: list[str] = []
    parts = probe.parts
    for i, p in enumerate(parts):
        fit = _fit_or_retry(study, probe.for_part(p), p, used, notes)
        for f in () if fit is None else fit:
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
    return values, us, pids, usys, notes


def _fit_or_retry(study, data, part: str, used: str, notes: list):
    try:
        return fit_study(study, data, method=used)
    except AnalysisError as e:
        if used == "lsq":
            notes.append(f"{part}: left out, the fit failed: {e}")
            return None
        try:
            fit = fit_study(study, data, method="lsq")
        except AnalysisError as e2:
            notes.append(f"{part}: left out, the fit failed: {e2}")
            return None
        notes.append(f"{part}: {used} fit failed ({e}); fitted with plain least squares")
        return fit
