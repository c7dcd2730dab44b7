"""Fit every feature of a profile from one part's probe points."""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from ..errors import InputError
from ..geometry import Profile
from ..io import rows_to_dataframe
from ._features import FeatureFit, fit_feature
from ._sigma import DECLARED_DOF, ProbeSigma, pooled_residuals, probe_sigma

__all__ = ["ProfileFit", "fit_profile"]


@dataclass(frozen=True, eq=False)
class ProfileFit:
    """Per-feature fits of one part. ``unmeasured`` lists features without points;
    ``sigma`` the probe sigma every covariance is scaled by (see `_sigma`)."""

    profile: Profile
    fits: dict
    method: str
    unmeasured: tuple[str, ...] = ()
    part: str | None = None
    sigma: ProbeSigma | None = None

    def __getitem__(self, feature_id: str) -> FeatureFit:
        try:
            return self.fits[feature_id]
        except KeyError:
            raise KeyError(
                f"no fit for feature {feature_id!r}; fitted: {', '.join(self.fits)}"
            ) from None

    def __iter__(self):
        return iter(self.fits.values())

    @property
    def deviations(self) -> dict[str, np.ndarray]:
        return {fid: f.values for fid, f in self.fits.items()}

    @property
    def covariances(self) -> dict[str, np.ndarray | None]:
        return {fid: f.covariance for fid, f in self.fits.items()}

    def rows(self) -> list[dict]:
        """One row per fitted parameter (fit.csv, `to_dataframe()`): `value` and
        `std_error` in the row's `unit` (mm, or rad for a line's rotation)."""
        out = []
        for f in self.fits.values():
            se = f.std_errors if f.std_errors is not None else [float("nan")] * len(f.values)
            units = f.feature.param_units
            for name, unit, v, s in zip(f.param_names, units, f.values, se, strict=True):
                out.append(
                    {
                        "part": self.part or "",
                        "feature": f.id,
                        "type": f.feature.kind,
                        "parameter": name,
                        "unit": unit,
                        "value": float(v),
                        "std_error": float(s),
                        "n_points": f.n,
                        "residual_sd_mm": f.residual_sd,
                        "residual_dof": f.residual_dof,
                        **self._sigma_row(),
                        "n_outliers": len(f.outliers),
                        "method": f.method,
                    }
                )
        return out

    def residual_rows(self) -> list[dict]:
        """One row per probe point (residuals.csv): the ball centre, its residual, robust
        weight, outlier flag, nearest nominal point and error vector (measured surface
        point - nominal); part frame, mm, X as a radius."""
        out = []
        for f in self.fits.values():
            outliers = {int(i) for i in f.outliers}
            for i in range(f.n):
                out.append(
                    {
                        "part": self.part or "",
                        "feature": f.id,
                        "line": int(f.lines[i]),
                        "ball_x_radius_mm": float(f.points[i, 0]),
                        "ball_z_mm": float(f.points[i, 1]),
                        "residual_mm": float(f.residuals[i]),
                        "weight": float(f.weights[i]),
                        "outlier": int(i in outliers),
                        "nominal_x_radius_mm": float(f.nominal_points[i, 0]),
                        "nominal_z_mm": float(f.nominal_points[i, 1]),
                        "error_x_radius_mm": float(f.error_vectors[i, 0]),
                        "error_z_mm": float(f.error_vectors[i, 1]),
                    }
                )
        return out

    def to_dataframe(self, table: str = "parameters"):
        """The fit as a `pandas.DataFrame`: `table="parameters"` (`rows()`, fit.csv)
        or `"residuals"` (`residual_rows()`, residuals.csv); docs/formats.md has the
        columns."""
        tables = {"parameters": self.rows, "residuals": self.residual_rows}
        if table not in tables:
            raise ValueError(f"unknown table {table!r}; expected one of {', '.join(tables)}")
        return rows_to_dataframe(tables[table]())

    def _sigma_row(self) -> dict:
        s = self.sigma
        if s is None:
            return {"sigma_mm": float("nan"), "sigma_source": "", "sigma_dof": float("nan")}
        return {"sigma_mm": s.value, "sigma_source": s.source, "sigma_dof": s.dof}

    def __repr__(self) -> str:
        lines = [f"ProfileFit({self.method}, part={self.part!r})"]
        if self.sigma is not None:
            lines.append(f"  probe sigma {self.sigma.describe()}")
        for f in self.fits.values():
            lines.append(f"  {f!r}")
        if self.unmeasured:
            lines.append(f"  not measured: {', '.join(self.unmeasured)}")
        return "\n".join(lines)


def fit_profile(
    profile: Profile,
    feature_ids,
    centres,
    *,
    ball_radius: float,
    method: str = "lsq",
    loss: str = "huber",
    scale: float | None = None,
    sigma: float | None = None,
    declared: float | None = None,
    declared_dof: float = DECLARED_DOF,
    fix: dict | None = None,
    lines=None,
    min_points: dict | None = None,
    file: str | None = None,
    part: str | None = None,
) -> ProfileFit:
    """Fit each feature of ``profile`` to its points.

    **Arguments:**

    - `feature_ids`: ``(n,)`` feature id of each point.
    - `centres`: ``(n, 2)`` ball centres in the part frame (mm, radius X).
    - `sigma`: the probe sigma, known (every covariance scaled by it, $\\nu = \\infty$).
    - `declared`, `declared_dof`: with `sigma=None` (the default), the covariances
      are scaled by the residual sd **pooled over every feature** of the part,
      combined with the declared repeatability as a prior worth `declared_dof`
      degrees of freedom (`piecs_bayes.fit._sigma`); never by one feature's own
      residuals, which say little with few points.
    - `fix`: ``{feature_id: (param, ...)}`` parameters held at nominal.
    - `min_points`: ``{"line": 3, "arc": 4}``; fewer (but some) points is an error.
    - `file`, `lines`: where the points came from, for messages and reports.

    **Returns:** a :class:`ProfileFit`; features with no points are listed as
    unmeasured (they are left as drawn by compensation).
    """
    feature_ids = np.asarray(feature_ids).astype(str)
    centres = np.asarray(centres, dtype=float)
    lines = np.arange(1, len(centres) + 1) if lines is None else np.asarray(lines)
    min_points = {"line": 3, "arc": 4, **(min_points or {})}
    fix = fix or {}
    for fid in np.unique(feature_ids):
        if fid not in profile.ids:
            first = int(lines[np.flatnonzero(feature_ids == fid)[0]])
            raise InputError(
                f"unknown feature id {fid!r}; the profile has {', '.join(profile.ids)}",
                file=file,
                line=first,
                column="feature",
                feature=fid,
            )
    # the reference sigma of the solves: the known or declared one (it also sets the
    # scale of the stationarity test, so it should be realistic); with neither, a first
    # pass at 1 mm gives the pooled residual sd and the solves are repeated at it
    ref = float(sigma if sigma is not None else (declared if declared is not None else 1.0))
    kw = dict(ball_radius=ball_radius, method=method, loss=loss, scale=scale)
    fits, unmeasured = _fit_features(profile, feature_ids, centres, lines, fix, min_points,
                                     file, ref, kw)  # fmt: skip
    if sigma is None and declared is None and fits:
        ss, dof = pooled_residuals(fits.values())
        if dof > 0 and ss > 0:
            ref = float(np.sqrt(ss / dof))
            fits, _ = _fit_features(profile, feature_ids, centres, lines, fix, min_points,
                                    file, ref, kw)  # fmt: skip
    if not fits:
        raise InputError("no probe point belongs to any profile feature", file=file)
    ss, dof = pooled_residuals(fits.values())
    try:
        ps = probe_sigma(
            ss, dof, declared=declared if sigma is None else sigma,
            declared_dof=declared_dof, known=sigma is not None,
            what=f"part {part!r}" if part is not None else "part",
        )  # fmt: skip
    except InputError as exc:
        raise InputError(str(exc), file=file) from None
    return ProfileFit(
        profile, scale_fits(fits, ps.value / ref), method, tuple(unmeasured), part, sigma=ps
    )


def _fit_features(profile, feature_ids, centres, lines, fix, min_points, file, ref, kw):
    """Every measured feature fitted with covariances at the reference sigma `ref`."""
    fits, unmeasured = {}, []
    for f in profile.features:
        m = feature_ids == f.id
        k = int(m.sum())
        if k == 0:
            unmeasured.append(f.id)
            continue
        need = min_points[f.kind]
        if k < need:
            raise InputError(
                f"{k} point(s) are too few for a {f.kind}: at least {need} are needed",
                file=file,
                feature=f.id,
                value=k,
            )
        fits[f.id] = fit_feature(
            f, centres[m], sigma=ref, fix=tuple(fix.get(f.id, ())), lines=lines[m], **kw
        )
    return fits, unmeasured


def scale_fits(fits: dict, factor: float) -> dict:
    """Feature fits with their covariances multiplied by `factor`**2 (the part's probe
    sigma over the sigma the solves used)."""
    out = {}
    for fid, f in fits.items():
        cov = None if f.covariance is None else np.asarray(f.covariance) * factor**2
        se = None if cov is None else np.sqrt(np.diag(cov))
        out[fid] = dataclasses.replace(f, covariance=cov, std_errors=se)
    return out
