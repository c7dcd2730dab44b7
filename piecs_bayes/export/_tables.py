"""Results tables: pure ``result -> text`` writers (JSON and CSV).

Numbers are written with 10 significant digits (0.1 nm on a 100 mm part);
lengths are mm in the part frame, X as radius, angles in rad.
"""

from __future__ import annotations

import csv
import io
import json

import numpy as np

__all__ = ["fit_json", "fit_csv", "residuals_csv", "path_csv", "to_csv"]

SCHEMA_VERSION = 1


def to_csv(rows: list[dict], columns: list[str] | None = None) -> str:
    """Rows of dicts as CSV text (header first, ``\\n`` line ends)."""
    columns = columns or (list(rows[0]) if rows else [])
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (f"{v:.10g}" if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def fit_json(fit, *, study=None) -> str:
    """Per-feature fitted deviations with standard uncertainties, as JSON.

    ``probe_sigma`` (and, per feature, ``sigma``) say which probe sigma scales the
    standard uncertainties, where it came from (``declared``, ``pooled``,
    ``pooled+declared``, ``prior``) and its degrees of freedom (``null``: known);
    ``residual_sd``/``residual_dof`` are each feature's own residuals, a diagnostic."""
    sigma = None if getattr(fit, "sigma", None) is None else fit.sigma.as_dict()
    features = []
    for f in fit:
        d = f.as_dict()
        if sigma is not None:
            d["sigma"] = {k: sigma[k] for k in ("value_mm", "source", "dof")}
        features.append(d)
    doc = {
        "schema": "piecs_bayes.fit",
        "version": SCHEMA_VERSION,
        "study": None if study is None else str(study.path),
        "part": fit.part,
        "method": fit.method,
        "units": {"length": "mm", "angle": "rad", "x": "radius"},
        "probe_sigma": sigma,
        "features": features,
        "unmeasured": list(fit.unmeasured),
    }
    return json.dumps(doc, indent=2) + "\n"


def fit_csv(fit) -> str:
    """One row per fitted parameter: value and standard uncertainty."""
    return to_csv(fit.rows())


def residuals_csv(fit) -> str:
    """One row per probe point: residual, robust weight, outlier flag, error vector."""
    rows = []
    for f in fit:
        out = set(int(i) for i in f.outliers)
        for i in range(f.n):
            rows.append(
                {
                    "feature": f.id,
                    "line": int(f.lines[i]),
                    "x": float(f.points[i, 0]),
                    "z": float(f.points[i, 1]),
                    "residual": float(f.residuals[i]),
                    "weight": float(f.weights[i]),
                    "outlier": int(i in out),
                    "nominal_x": float(f.nominal_points[i, 0]),
                    "nominal_z": float(f.nominal_points[i, 1]),
                    "error_x": float(f.error_vectors[i, 0]),
                    "error_z": float(f.error_vectors[i, 1]),
                }
            )
    return to_csv(rows)


def path_csv(path, *, bounds=None) -> str:
    """Adjusted tool-path vertices (part frame, radius X) with their moves from nominal.

    ``bounds``, when given, is a mapping of extra per-vertex columns (e.g.
    standard uncertainties) added beside the coordinates.
    """
    nominal = path.nominal.vertices
    ids = path.nominal.ids
    rows = []
    for j, (v, nv) in enumerate(zip(path.vertices, nominal, strict=True)):
        before = ids[j - 1] if j > 0 else ""
        after = ids[j] if j < len(ids) else ""
        row = {
            "vertex": j,
            "between": f"{before}|{after}".strip("|"),
            "junction": path.nominal.junctions[j - 1] if 0 < j < len(ids) else "end",
            "nominal_x": float(nv[0]),
            "nominal_z": float(nv[1]),
            "x": float(v[0]),
            "z": float(v[1]),
            "dx": float(v[0] - nv[0]),
            "dz": float(v[1] - nv[1]),
        }
        for key, col in (bounds or {}).items():
            row[key] = float(np.asarray(col)[j])
        rows.append(row)
    return to_csv(rows)


def bounds_csv(tpu) -> str:
    """Per-vertex standard uncertainties of an adjusted path (one ToolpathUncertainty)."""
    rows = []
    for j, (v, c) in enumerate(zip(tpu.vertices, tpu.vertex_cov, strict=True)):
        sx, sz = float(np.sqrt(max(c[0, 0], 0.0))), float(np.sqrt(max(c[1, 1], 0.0)))
        rows.append(
            {
                "vertex": j,
                "x": float(v[0]),
                "z": float(v[1]),
                "u_x": sx,
                "u_z": sz,
                "corr_xz": float(c[0, 1] / (sx * sz)) if sx > 0 and sz > 0 else 0.0,
                "method": tpu.method,
            }
        )
    return to_csv(rows)


def band_csv(tpu, profile) -> str:
    """The adjusted path's normal offset from nominal along the contour with its
    standard uncertainty and pointwise / simultaneous 95 % bands."""
    b = tpu.bands
    g = tpu.grid
    rows = []
    for i in range(len(g)):
        rows.append(
            {
                "feature": profile.features[int(g.feature[i])].id,
                "t": float(g.t[i]),
                "nominal_x": float(g.points[i, 0]),
                "nominal_z": float(g.points[i, 1]),
                "normal_x": float(g.normals[i, 0]),
                "normal_z": float(g.normals[i, 1]),
                "offset": float(tpu.offset[i]),
                "u_offset": float(tpu.offset_sd[i]),
                "pointwise_lower": float(b.pointwise_lower[i]),
                "pointwise_upper": float(b.pointwise_upper[i]),
                "simultaneous_lower": float(b.simultaneous_lower[i]),
                "simultaneous_upper": float(b.simultaneous_upper[i]),
            }
        )
    return to_csv(rows)


def budget_csv(tpu, profile) -> str:
    """Uncertainty budget (linearised): variance share of each source per
    feature parameter and per vertex coordinate; shares sum to 1."""
    rows = []
    tot_d = tpu.deviation_budget["total"]
    sources = [k for k in tpu.deviation_budget if k != "total"]
    i = 0
    for f in profile.features:
        for name in f.param_names:
            row = {"output": f"{f.id}.{name}", "u": float(np.sqrt(tot_d[i]))}
            for s in sources:
                row[s] = float(tpu.deviation_budget[s][i] / tot_d[i]) if tot_d[i] > 0 else 0.0
            rows.append(row)
            i += 1
    tot_v = tpu.vertex_budget["total"]
    for j in range(tot_v.shape[0]):
        for k, axis in enumerate("xz"):
            row = {"output": f"vertex{j}.{axis}", "u": float(np.sqrt(tot_v[j, k]))}
            for s in sources:
                row[s] = float(tpu.vertex_budget[s][j, k] / tot_v[j, k]) if tot_v[j, k] > 0 else 0.0
            rows.append(row)
    return to_csv(rows)


def bounds_json(results: dict, profile) -> str:
    """Tool-path bounds of every method in one JSON document."""
    doc = {
        "schema": "piecs_bayes.bounds",
        "version": SCHEMA_VERSION,
        "units": {"length": "mm"},
        "methods": {},
    }
    for key, tpu in results.items():
        if tpu is None:
            continue
        doc["methods"][key] = {
            "method": tpu.method,
            "vertices": np.asarray(tpu.vertices).tolist(),
            "vertex_cov": np.asarray(tpu.vertex_cov).tolist(),
            "band": {
                "p": tpu.bands.p,
                "crit_simultaneous": tpu.bands.crit_simultaneous,
                "max_half_width_simultaneous": float(
                    np.max(tpu.bands.crit_simultaneous * tpu.offset_sd)
                ),
            },
            "deviation_sd": {
                f.id: np.sqrt(np.clip(np.diag(tpu.deviation_cov[f.id]), 0, None)).tolist()
                for f in profile.features
                if f.id in tpu.deviation_cov
            },
        }
    return json.dumps(doc, indent=2) + "\n"


def posterior_csv(bayes) -> str:
    """Posterior mean, sd and 95 % interval of every parameter of a Bayesian fit."""
    return to_csv(bayes.rows())
