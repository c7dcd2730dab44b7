"""Rows of a tool-path uncertainty: vertex bounds, the band along the contour, the
budget (`ToolpathUncertainty.rows`, `band_rows`, `budget_rows`).

The one source of `export.bounds_csv`, `band_csv`, `budget_csv` and of
`ToolpathUncertainty.to_dataframe()`. Part frame, mm, X as a radius; the unit is in
each column's name, or in a `unit` column where rows mix units.
"""

from __future__ import annotations

import numpy as np

from ..geometry import Profile


def vertex_rows(tpu) -> list[dict]:
    """One row per vertex of the adjusted path: position and standard uncertainties."""
    rows = []
    for j, (v, c) in enumerate(zip(tpu.vertices, tpu.vertex_cov, strict=True)):
        sx, sz = float(np.sqrt(max(c[0, 0], 0.0))), float(np.sqrt(max(c[1, 1], 0.0)))
        rows.append(
            {
                "vertex": j,
                "x_radius_mm": float(v[0]),
                "z_mm": float(v[1]),
                "u_x_radius_mm": sx,
                "u_z_mm": sz,
                "corr_xz": float(c[0, 1] / (sx * sz)) if sx > 0 and sz > 0 else 0.0,
                "method": tpu.method,
            }
        )
    return rows


def band_rows(tpu, profile: Profile) -> list[dict]:
    """One row per grid point along the nominal contour: the adjusted path's normal
    offset from nominal, its standard uncertainty and the `p` bands."""
    b, g = tpu.bands, tpu.grid
    return [
        {
            "feature": profile.features[int(g.feature[i])].id,
            "t": float(g.t[i]),
            "nominal_x_radius_mm": float(g.points[i, 0]),
            "nominal_z_mm": float(g.points[i, 1]),
            "normal_x": float(g.normals[i, 0]),
            "normal_z": float(g.normals[i, 1]),
            "offset_mm": float(tpu.offset[i]),
            "u_offset_mm": float(tpu.offset_sd[i]),
            "pointwise_lower_mm": float(b.pointwise_lower[i]),
            "pointwise_upper_mm": float(b.pointwise_upper[i]),
            "simultaneous_lower_mm": float(b.simultaneous_lower[i]),
            "simultaneous_upper_mm": float(b.simultaneous_upper[i]),
        }
        for i in range(len(g))
    ]


def budget_rows(tpu, profile: Profile) -> list[dict]:
    """Long uncertainty budget (linearised): per output (feature parameter, vertex
    coordinate) one row per source and a `total` row: the source's share of the
    variance and its standard uncertainty `u` in the output's `unit`."""
    if tpu.deviation_budget is None or tpu.vertex_budget is None:
        raise ValueError(f"no uncertainty budget in a {tpu.method} result (linearised only)")
    sources = [k for k in tpu.deviation_budget if k != "total"]
    outputs = []  # (output, unit, {source: variance})
    i = 0
    for f in profile.features:
        for name, unit in zip(f.param_names, f.param_units, strict=True):
            var = {s: tpu.deviation_budget[s][i] for s in [*sources, "total"]}
            outputs.append((f"{f.id}.{name}", unit, var))
            i += 1
    for j in range(tpu.vertex_budget["total"].shape[0]):
        for k, axis in enumerate(("x_radius", "z")):
            var = {s: tpu.vertex_budget[s][j, k] for s in [*sources, "total"]}
            outputs.append((f"vertex{j}.{axis}", "mm", var))
    rows = []
    for output, unit, var in outputs:
        total = float(var["total"])
        for s in [*sources, "total"]:
            v = float(var[s])
            rows.append(
                {
                    "output": output,
                    "unit": unit,
                    "source": s,
                    "u": float(np.sqrt(max(v, 0.0))),
                    "variance_share": v / total if total > 0 else 0.0,
                }
            )
    return rows
