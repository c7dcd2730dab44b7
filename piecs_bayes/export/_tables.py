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
    """Per-feature fitted deviations with standard uncertainties, as JSON."""
    doc = {
        "schema": "piecs_bayes.fit",
        "version": SCHEMA_VERSION,
        "study": None if study is None else str(study.path),
        "part": fit.part,
        "method": fit.method,
        "units": {"length": "mm", "angle": "rad", "x": "radius"},
        "features": [f.as_dict() for f in fit],
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
