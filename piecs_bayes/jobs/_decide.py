"""Is compensation justified for each feature of one part: the decision table.

The characteristic of each feature (its normal deviation at a nominal point with
its uncertainty: `piecs_bayes.uncertainty.feature_characteristic`) goes through
`compensate.decide` with the study's `[decision]` settings. A decision can also be
fed from a posterior: [`decide_features`][] takes a mean and a standard deviation
(or draws) per feature. `export.decisions_json`, `decisions_csv` and
`decisions_text` render the table.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from ..decide import Decision, DecisionSettings, DrawnFeature, decide
from ..errors import InputError
from ..geometry import drawn_scale
from ..io import rows_to_dataframe
from ..uncertainty import Characteristic, feature_characteristic
from ._options import decision_settings, source_sds

#: the verdict a table's rows give a feature without probe points (no decision)
NOT_MEASURED = "not measured"


def characteristics(study, fit, *, at: str = "mid") -> dict[str, Characteristic]:
    """[`Characteristic`][]s of every fitted feature of `fit` (profile order), with the
    study's systematic uncertainty sources."""
    sds = source_sds(study)
    dof = fit.sigma.dof if getattr(fit, "sigma", None) is not None else math.inf
    return {f.id: feature_characteristic(f, at=at, sources=sds, dof=dof) for f in fit}


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
        """One flat row per feature (CSV / DataFrame); a feature without points gets
        the verdict "not measured", no numbers and gain 0."""
        out = []
        for d, c in zip(self.decisions, self.estimates, strict=True):
            row = {"part": self.part or "", **d.as_row()}
            row["tolerance_lower_mm"], row["tolerance_upper_mm"] = d.tolerance
            row["at"] = c.at if c is not None else ""
            row["u_fit_mm"] = c.u_fit if c is not None else math.nan
            row["u_systematic_mm"] = c.u_systematic if c is not None else math.nan
            out.append(row)
        keys = list(out[0]) if out else ["part", "feature", "verdict", "gain", "reasons"]
        for fid in self.unmeasured:
            row = dict.fromkeys(keys)
            row.update(part=self.part or "", feature=fid, verdict=NOT_MEASURED, gain=0.0)
            row["reasons"] = "no probe point on this feature: no decision, left as drawn"
            out.append(row)
        return out

    def to_dataframe(self):
        """The table as a `pandas.DataFrame`, one row per feature: `rows()`, the
        columns of decisions.csv (docs/formats.md)."""
        return rows_to_dataframe(self.rows())

    def __repr__(self) -> str:
        verdicts = ", ".join(
            [f"{d.feature} {d.verdict}" for d in self.decisions]
            + [f"{fid} {NOT_MEASURED}" for fid in self.unmeasured]
        )
        return f"DecisionTable({self.study!r}, part {self.part or '-'}: {verdicts})"


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


def _drawn(fid: str, coordinates) -> DrawnFeature:
    coordinate, scale = (coordinates or {}).get(fid, ("normal", 1.0))
    return DrawnFeature(fid, coordinate, float(scale))


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
    coordinates: Mapping[str, tuple[str, float]] | None = None,
) -> DecisionTable:
    """Decide per feature from estimates of its normal deviation (mm).

    **Arguments:**

    - `estimates`: by feature id, a [`Characteristic`][], a `(mean, sd)` pair, a
      mapping with `mean`, `sd` (or `samples`) and optionally `n_points`,
      `u_systematic`, `dof`, or 1-D posterior draws: what a Bayesian fit hands over.
    - `tolerances`: `(lower, upper)` limit deviations by feature id (mm).
    - `settings`, `run_index`: see `compensate.decide`.
    - `study`, `part`, `method`, `characteristic`, `unmeasured`: labels kept in the table.
    - `coordinates`: by feature id, the coordinate its tolerance is drawn on and the
      drawn deviation per unit of normal deviation (`geometry.drawn_scale`); default
      `("normal", 1.0)`. They change how the decisions are stated, not the verdicts.

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
                dof=dof,
                feature=_drawn(fid, coordinates),
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
        coordinates={f.id: (f.tolerance_on, drawn_scale(f)) for f in study.profile.features},
    )
