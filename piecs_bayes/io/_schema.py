"""The study file's schema: every section and key it may hold, in one place.

`check_keys` walks a parsed study (TOML tree) before any value is read and
refuses an unknown section or key with its path and the nearest valid name
(``compensation.max_corection: unknown key; did you mean 'max_correction'?``),
so that a typo never silently falls back to a default. The values themselves
are read and checked (type, finiteness, range) by `_study.load_study` and the
job sections' table `_job_sections.JOB_KEYS`; this module only knows the names.
"""

from __future__ import annotations

import difflib

from ..errors import InputError

#: section -> its keys; "profile.feature" is each [[profile.feature]] table.
#: `uncertainty` holds one table per source (names in `_sections.KNOWN_SOURCES`) whose
#: keys the prior reader checks; the job sections' keys come from `_job_sections.JOB_KEYS`.
SECTIONS: dict[str, tuple[str, ...]] = {
    "study": (
        "name", "units", "probe_files", "part_program", "encoding", "probe_format", "probe_plan",
    ),
    "profile": ("kind", "x_mode", "tangent_tolerance_deg", "feature"),
    "profile.feature": (
        "id", "type", "start", "end", "center", "direction", "tolerance", "tolerance_on",
    ),
    "probe": (
        "ball_radius", "ball_radius_u", "repeatability", "repeatability_dof", "x_mode",
        "pretravel", "tool", "feed", "calibration", "calibration_max_age_days",
    ),
    "machine": ("x_centre", "z_offset", "scale_x", "scale_z", "rotation"),
    "uncertainty": (),  # source names: checked with the sources
    "fit": (
        "method", "loss", "scale", "known_sigma", "min_points_line", "min_points_arc", "fix",
        "free_transform", "likelihood", "nu", "bayes_steps", "bayes_walkers", "bayes_ensembles",
    ),
    "compensation": ("gain", "max_correction", "apply"),
    "program": (
        "nose_radius", "tool_table", "mapping", "tolerance", "stock", "dialect", "path_tip",
    ),
    "plausibility": ("max_distance", "max_outside", "duplicates"),
}  # fmt: skip


#: `[uncertainty]` source tables: distribution -> its keys (the study file's names; what
#: they mean is `piecs_bayes.fit.mcmc._priors`, which reads them)
DIST_KEYS: dict[str, tuple[str, ...]] = {
    "normal": ("mean", "sd"),
    "gaussian": ("mean", "sd"),
    "uniform": ("low", "high", "mean", "half_width"),
    "rectangular": ("low", "high", "mean", "half_width"),
    "half_normal": ("sd",),
    "halfnormal": ("sd",),
    "lognormal": ("mu", "sigma"),
    "log_normal": ("mu", "sigma"),
    "student_t": ("nu", "loc", "mean", "scale"),
    "t": ("nu", "loc", "mean", "scale"),
    "studentt": ("nu", "loc", "mean", "scale"),
    "scaled_inv_chi2": ("nu", "scale"),
}


def check_source(file: str, name: str, spec: dict) -> None:
    """An `[uncertainty]` table: a known `dist` and only its keys (nearest name suggested)."""
    dist = spec.get("dist")
    if not isinstance(dist, str) or dist.lower() not in DIST_KEYS:
        raise InputError(
            f"uncertainty.{name}.dist: unknown distribution {dist!r}"
            f"{nearest(str(dist), DIST_KEYS)} (expected one of {', '.join(DIST_KEYS)})",
            file=file,
            value=dist,
        )
    keys = DIST_KEYS[dist.lower()]
    for key in spec:
        if key != "dist" and key not in keys:
            raise _unknown(file, f"uncertainty.{name}.", key, keys, spec[key])


def nearest(name: str, options) -> str:
    """`"; did you mean 'x'?"` for the closest option, or `""`."""
    best = difflib.get_close_matches(str(name), list(options), n=1, cutoff=0.6)
    return f"; did you mean {best[0]!r}?" if best else ""


def _unknown(file, path, key, options, value=None) -> InputError:
    opts = ", ".join(options)
    return InputError(
        f"{path}{key}: unknown {'section' if not path else 'key'} {key!r}"
        f"{nearest(key, options)} (expected one of {opts})",
        file=file,
        value=value,
    )


def check_keys(tree: dict, file: str, job_keys: dict[str, dict]) -> None:
    """Refuse unknown sections and keys anywhere in the study tree (see module doc)."""
    sections = {**SECTIONS, **{k: tuple(v) for k, v in job_keys.items()}}
    sections.pop("profile.feature")
    for name, sec in tree.items():
        if name not in sections:
            raise _unknown(file, "", name, sections)
        if not isinstance(sec, dict):
            raise InputError(f"{name}: expected a table [{name}], got {sec!r}", file=file)
        if name == "uncertainty":
            continue
        keys = sections[name]
        for key in sec:
            if key not in keys:
                raise _unknown(file, f"{name}.", key, keys, sec[key])
    feats = tree.get("profile", {}).get("feature", [])
    if isinstance(feats, list):
        keys = SECTIONS["profile.feature"]
        for i, f in enumerate(feats):
            if isinstance(f, dict):
                for key in f:
                    if key not in keys:
                        raise _unknown(file, f"profile.feature[{i}].", key, keys, f[key])
