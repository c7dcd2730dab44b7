"""The result of one part's profile fit: [`ProfileFit`][] (the per-part loop, the batch
kernel's one-part path and the joint fit all return it)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import Profile
from ..io import rows_to_dataframe
from ._features import FeatureFit
from ._sigma import ProbeSigma


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
