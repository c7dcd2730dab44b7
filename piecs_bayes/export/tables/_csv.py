"""Results tables: pure ``result -> text`` writers (JSON and CSV).

Numbers are written with 10 significant digits (0.1 nm on a 100 mm part);
lengths are mm in the part frame, X as radius, angles in rad. The CSVs say so in
their headers: the unit in a column's name (`x_radius_mm`, `u_offset_mm`), or a
`unit` column where one column holds values of several units (fit.csv,
posterior.csv, uncertainty_budget.csv). Their rows come from the results' `rows()`
methods, which `to_dataframe()` hands to pandas: the two agree.
"""

from __future__ import annotations

import csv
import io
import json

import numpy as np

SCHEMA_VERSION = 1


def to_csv(rows: list[dict], columns: list[str] | None = None) -> str:
    """Rows of dicts as CSV text (header first, ``\\n`` line ends); floats with 10
    significant digits and a decimal point (46.0, not 46: a float column reads back
    as floats), `None` as an empty cell."""
    columns = columns or (list(rows[0]) if rows else [])
    buf = io.StringIO()
    w = csv.DictWriter(buf, fieldnames=columns, lineterminator="\n")
    w.writeheader()
    for r in rows:
        w.writerow({k: (_float_text(v) if isinstance(v, float) else v) for k, v in r.items()})
    return buf.getvalue()


def _float_text(v: float) -> str:
    text = f"{v:.10g}"
    return text + ".0" if text.lstrip("-").isdigit() else text


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
    """One row per fitted parameter (`ProfileFit.rows`): value and standard
    uncertainty in the row's `unit` (mm, or rad for a line's rotation)."""
    return to_csv(fit.rows())


def residuals_csv(fit) -> str:
    """One row per probe point (`ProfileFit.residual_rows`): ball centre, residual,
    robust weight, outlier flag, nominal point and error vector (mm, radius X)."""
    return to_csv(fit.residual_rows())


def path_csv(path, *, bounds=None) -> str:
    """Adjusted tool-path vertices (`AdjustedPath.rows`: part frame, mm, X as a
    radius) with their moves from nominal.

    ``bounds``, when given, is a mapping of extra per-vertex columns (e.g.
    standard uncertainties; name them with their unit) added beside the coordinates.
    """
    rows = path.rows()
    for key, col in (bounds or {}).items():
        for j, row in enumerate(rows):
            row[key] = float(np.asarray(col)[j])
    return to_csv(rows)


def bounds_csv(tpu) -> str:
    """Per-vertex standard uncertainties of an adjusted path (`ToolpathUncertainty.rows`)."""
    return to_csv(tpu.rows())


def band_csv(tpu, profile) -> str:
    """The adjusted path's normal offset from nominal along the contour with its
    standard uncertainty and pointwise / simultaneous 95 % bands
    (`ToolpathUncertainty.band_rows`)."""
    return to_csv(tpu.band_rows(profile))


def budget_csv(tpu, profile) -> str:
    """Uncertainty budget (linearised), long: per feature parameter and vertex
    coordinate, one row per source and a `total` row with the variance share and the
    standard uncertainty in the row's `unit` (`ToolpathUncertainty.budget_rows`)."""
    return to_csv(tpu.budget_rows(profile))


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
    """Posterior mean, sd and 95 % interval of every parameter of a Bayesian fit, in
    the row's `unit` (`BayesProfileFit.rows`)."""
    return to_csv(bayes.rows())
