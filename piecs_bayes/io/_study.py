"""Study files (TOML): the part's nominal profile, the probe, the machine, the
uncertainty sources, the probe files and the part program of one job.

All lengths are converted to millimetres and X to radius here, at the
boundary; every error names the file, the key path (``profile.feature[2].end``)
and, where there is one, the feature id and the offending value. See
``docs/formats.md`` for the format with an example.
"""

from __future__ import annotations

import glob
import math
import re
import tomllib
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ..errors import InputError
from ..geometry import MachineTransform, Profile, ProfileError, make_feature, profile_side
from ._schema import check_keys, check_source
from ._text import check_encoding, decode, read_bytes

__all__ = [
    "Study",
    "ProbeSpec",
    "FitSettings",
    "CompensationSettings",
    "load_study",
    "KNOWN_SOURCES",
]

_MM_PER = {"mm": 1.0, "in": 25.4}

#: Uncertainty sources a study may declare, with the unit of their values.
KNOWN_SOURCES = {
    "repeatability": "mm (probe repeatability, standard deviation)",
    "ball_radius": "mm (stylus ball radius calibration error)",
    "pretravel": "mm (directional pretravel, along the approach)",
    "scale_x": "1 (X axis scale error, e.g. 10e-6 = 10 ppm)",
    "scale_z": "1 (Z axis scale error)",
    "x_centre": "mm (centre-line offset error in X)",
    "z_offset": "mm (work offset error in Z)",
    "rotation": "rad (small rotation of the probe frame)",
    "thermal": "1/K (thermal expansion error, times the temperature difference)",
}
_LENGTH_SOURCES = {"repeatability", "ball_radius", "pretravel", "x_centre", "z_offset"}
_DIST_LENGTH_KEYS = {"mean", "sd", "low", "high", "scale", "half_width", "loc"}


@dataclass(frozen=True)
class ProbeSpec:
    """Touch-trigger probe: ball radius (mm) with its standard uncertainty,
    repeatability sigma (mm), how the probe files write X, pretravel (mm), and the
    degrees of freedom the declared repeatability is worth as a prior for the
    pooled residual sigma (``repeatability_dof``; 0: no prior; see docs/uncertainty.md)."""

    ball_radius: float
    ball_radius_u: float = 0.0
    repeatability: float = 0.001
    x_mode: str = "diameter"
    pretravel: float = 0.0
    repeatability_dof: float = 8.0


@dataclass(frozen=True)
class FitSettings:
    """How features are fitted. ``loss`` applies to ``method="robust"``; ``scale``
    is the robust standard deviation (mm; default: the probe repeatability);
    ``known_sigma`` scales covariances by the probe repeatability instead of the
    residual variance."""

    method: str = "robust"
    loss: str = "huber"
    scale: float | None = None
    known_sigma: bool = False
    min_points_line: int = 3
    min_points_arc: int = 4
    fix: tuple[str, ...] = ()
    free_transform: tuple[str, ...] = ()
    likelihood: str = "gaussian"
    nu: float = 4.0
    bayes_steps: int = 6000
    bayes_walkers: int | None = None
    bayes_ensembles: int = 4


@dataclass(frozen=True)
class CompensationSettings:
    """PIECS mirroring: ``gain`` in [0, 1] (1 = full mirroring) and the largest
    correction (mm) of any vertex that the tool accepts."""

    gain: float = 1.0
    max_correction: float = 0.2


@dataclass(frozen=True)
class ProgramSettings:
    """How the part program is adjusted: the tool-nose radius (mm) or a LinuxCNC
    tool table for the gouge check, an explicit ``{feature id: (line, ...)}``
    mapping of finish-cut blocks (overrides the mapping by geometry) and the
    distance (mm) within which a block counts as lying on a feature."""

    nose_radius: float | None = None
    tool_table: Path | None = None
    mapping: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    tolerance: float = 0.01


@dataclass(frozen=True, eq=False)
class Study:
    """One compensation job, validated, in mm and radius X."""

    path: Path
    name: str
    units: str
    profile: Profile
    probe: ProbeSpec
    transform: MachineTransform
    sources: MappingProxyType
    probe_files: tuple[Path, ...]
    program: Path | None
    fit: FitSettings
    compensation: CompensationSettings
    sections: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    decision: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    capability: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    offsets: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    errspec: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    program_settings: ProgramSettings = field(default_factory=ProgramSettings)
    encoding: str = "utf-8"
    plausibility: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))

    def __repr__(self) -> str:
        return (
            f"Study({self.name!r}, {len(self.profile)} features "
            f"[{', '.join(self.profile.ids)}], {len(self.probe_files)} probe file(s), "
            f"program={self.program.name if self.program else None})"
        )


class _Reader:
    """Typed access to the TOML tree that names the key path in every error."""

    def __init__(self, file: str):
        self.file = file

    def error(self, key: str, message: str, *, feature=None, value=None) -> InputError:
        return InputError(f"{key}: {message}", file=self.file, feature=feature, value=value)

    def table(self, tree: dict, key: str, path: str, *, required=False) -> dict:
        if key not in tree:
            if required:
                raise self.error(f"{path}{key}", "missing required table")
            return {}
        val = tree[key]
        if not isinstance(val, dict):
            raise self.error(f"{path}{key}", f"expected a table, got {val!r}", value=val)
        return val

    def number(self, tree, key, path, default=None, *, positive=False, nonneg=False, feature=None):
        if key not in tree:
            if default is None:
                raise self.error(f"{path}{key}", "missing required number", feature=feature)
            return default
        val = tree[key]
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise self.error(
                f"{path}{key}", f"expected a number, got {val!r}", feature=feature, value=val
            )
        val = float(val)
        if not math.isfinite(val):
            raise self.error(
                f"{path}{key}", f"expected a finite number, got {val!r}", feature=feature, value=val
            )
        if positive and val <= 0:
            raise self.error(
                f"{path}{key}", f"must be > 0, got {val!r}", feature=feature, value=val
            )
        if nonneg and val < 0:
            raise self.error(
                f"{path}{key}", f"must be >= 0, got {val!r}", feature=feature, value=val
            )
        return val

    def integer(self, tree, key, path, default: int, *, minimum: int = 1) -> int:
        val = tree.get(key, default)
        if isinstance(val, bool) or not isinstance(val, int):
            raise self.error(f"{path}{key}", f"expected an integer, got {val!r}", value=val)
        if val < minimum:
            raise self.error(f"{path}{key}", f"must be >= {minimum}, got {val!r}", value=val)
        return val

    def boolean(self, tree, key, path, default: bool) -> bool:
        val = tree.get(key, default)
        if not isinstance(val, bool):
            raise self.error(
                f"{path}{key}", f"expected true or false (no quotes), got {val!r}", value=val
            )
        return val

    def choice(self, tree, key, path, options, default):
        val = tree.get(key, default)
        if val not in options:
            raise self.error(
                f"{path}{key}",
                f"unknown value {val!r}; expected one of {', '.join(map(repr, options))}",
                value=val,
            )
        return val

    def point(self, tree, key, path, feature):
        if key not in tree:
            raise self.error(f"{path}{key}", "missing required point [x, z]", feature=feature)
        val = tree[key]
        if isinstance(val, dict):
            val = [val.get("x"), val.get("z")]
        if (
            not isinstance(val, list)
            or len(val) != 2
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in val)
        ):
            raise self.error(
                f"{path}{key}",
                f"expected a point [x, z] of two numbers, got {val!r}",
                feature=feature,
                value=val,
            )
        if not all(math.isfinite(v) for v in val):
            raise self.error(
                f"{path}{key}", f"point must be finite, got {val!r}", feature=feature, value=val
            )
        return [float(val[0]), float(val[1])]


def _features(r: _Reader, prof: dict, scale: float, xscale: float) -> list[dict]:
    feats = prof.get("feature")
    if not isinstance(feats, list) or not feats:
        raise r.error("profile.feature", "the profile needs at least one [[profile.feature]]")
    specs = []
    for i, f in enumerate(feats):
        path = f"profile.feature[{i}]."
        if not isinstance(f, dict):
            raise r.error(path[:-1], f"expected a table, got {f!r}")
        fid = f.get("id")
        if not isinstance(fid, str) or not fid.strip():
            raise r.error(f"{path}id", f"expected a non-empty string id, got {fid!r}", value=fid)
        kind = f.get("type")
        if kind not in ("line", "arc"):
            raise r.error(
                f"{path}type",
                f"unknown feature type {kind!r}; expected 'line' or 'arc'",
                feature=fid,
                value=kind,
            )

        def pt(key, path=path, f=f, fid=fid):
            x, z = r.point(f, key, path, fid)
            return (x * xscale, z * scale)

        spec: dict[str, Any] = {"id": fid, "p0": pt("start"), "p1": pt("end")}
        if kind == "arc":
            spec["center"] = pt("center")
            direction = f.get("direction")
            if direction not in ("cw", "ccw"):
                raise r.error(
                    f"{path}direction",
                    f"unknown arc direction {direction!r}; "
                    "expected 'cw' or 'ccw' (drawing frame: z right, x up)",
                    feature=fid,
                    value=direction,
                )
            spec["ccw"] = direction == "ccw"
            if math.dist(spec["p0"], spec["p1"]) <= 1e-9 * max(1.0, abs(spec["p0"][1])):
                raise r.error(
                    f"{path}end",
                    "arc start equals its end (a full circle is not a feature of a turned profile)",
                    feature=fid,
                )
            r0, r1 = math.dist(spec["p0"], spec["center"]), math.dist(spec["p1"], spec["center"])
            if r0 <= 0 or abs(r0 - r1) > 1e-6 * max(1.0, r0):
                raise r.error(
                    f"{path}center",
                    "start and end are not equidistant from the centre "
                    f"(radii {r0:.6f} and {r1:.6f} mm)",
                    feature=fid,
                )
        elif math.dist(spec["p0"], spec["p1"]) == 0:
            raise r.error(f"{path}end", "line has zero length (start == end)", feature=fid)
        tol = f.get("tolerance", [-0.01, 0.01])
        if (
            not isinstance(tol, list)
            or len(tol) != 2
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in tol)
            or not all(math.isfinite(v) for v in tol)
            or not tol[0] < tol[1]
        ):
            raise r.error(
                f"{path}tolerance",
                f"expected [lower, upper] finite deviations with lower < upper, got {tol!r}",
                feature=fid,
                value=tol,
            )
        spec["tolerance"] = (float(tol[0]) * scale, float(tol[1]) * scale)
        specs.append(spec)
    return specs


def _sources(r: _Reader, tree: dict, scale: float) -> dict:
    out = {}
    for name, spec in tree.items():
        path = f"uncertainty.{name}"
        if name not in KNOWN_SOURCES:
            raise r.error(
                path,
                f"unknown uncertainty source {name!r}; known: {', '.join(KNOWN_SOURCES)}",
                value=name,
            )
        if not isinstance(spec, dict) or "dist" not in spec:
            raise r.error(
                path,
                f"expected a table with 'dist' (normal, uniform, half_normal...), got {spec!r}",
            )
        check_source(r.file, name, spec)
        spec = dict(spec)
        for key, val in spec.items():
            if key == "dist":
                continue
            if isinstance(val, bool) or not isinstance(val, (int, float)) or not math.isfinite(val):
                raise r.error(f"{path}.{key}", f"expected a finite number, got {val!r}", value=val)
            if name in _LENGTH_SOURCES and key in _DIST_LENGTH_KEYS:
                spec[key] = float(val) * scale
        out[name] = MappingProxyType(spec)
    return out


def _files(r: _Reader, tree: dict, base: Path) -> tuple[tuple[Path, ...], Path | None]:
    probe_files = tree.get("probe_files", [])
    if isinstance(probe_files, str):
        probe_files = [probe_files]
    if not isinstance(probe_files, list) or not all(isinstance(p, str) for p in probe_files):
        raise r.error("study.probe_files", f"expected a list of file names, got {probe_files!r}")
    paths = []
    for p in probe_files:
        if any(ch in p for ch in "*?["):
            # Path.glob takes relative patterns only: an absolute one goes to glob.glob
            matches = (
                sorted(Path(m) for m in glob.glob(p))
                if Path(p).is_absolute()
                else sorted(base.glob(p))
            )
        else:
            matches = [base / p]
        if not matches:
            raise r.error(
                "study.probe_files", f"no file matches {p!r} (relative to {base})", value=p
            )
        paths.extend(matches)
    program = tree.get("part_program")
    if program is not None and not isinstance(program, str):
        raise r.error("study.part_program", f"expected a file name, got {program!r}")
    return tuple(paths), (base / program if program else None)


# Keys of the job sections read by piecs_bayes.decisions (see docs/formats.md):
# (kind, bounds) with kind "length" (converted to mm), "number", "int", "bool",
# "choice" (bounds = options), "ids" (feature ids of the profile); bounds are
# (low, high, low_open, high_open), None = unbounded. Defaults live where the
# settings are used (DecisionSettings, OffsetSettings, decisions.py).
_GE0 = (0.0, None, False, False)
_GT0 = (0.0, None, True, False)
_GAIN = (0.0, 1.0, True, False)
_JOB_KEYS: dict[str, dict[str, tuple]] = {
    "decision": {
        "characteristic": ("choice", ("worst", "mid", "start", "end")),
        "run_index": ("int", (1, None, False, False)),
        "null_band": ("length", _GE0),
        "feedback_gain": ("number", _GAIN),
        "loss_k": ("per_mm2", _GT0),
        "adjustment_cost": ("number", _GE0),
        "out_of_tolerance_cost": ("number", _GE0),
        "adjustment_sd": ("length", _GE0),
        "process_sd": ("length", _GE0),
        "prior_sd": ("length", _GT0),
        "max_correction": ("length", _GT0),
        "p_significant": ("number", (0.5, 1.0, True, True)),
        "coverage_factor": ("number", _GT0),
        "guard_band_factor": ("number", _GE0),
        "parts_per_decision": ("int", (1, None, False, False)),
        "max_points_factor": ("number", (1.0, None, False, False)),
        "require_significance": ("bool", None),
    },
    "capability": {
        "characteristic": ("choice", ("mid", "start", "end")),
        "confidence": ("number", (0.0, 1.0, True, True)),
        "threshold": ("number", _GT0),
        "sigma_method": ("choice", ("auto", "mr", "overall")),
        "subtract_gauge": ("bool", None),
        "gain": ("number", (0.0, 1.0, False, False)),
        "n_draws": ("int", (1000, None, False, False)),
        "run_length": ("int", (2, None, False, False)),
        "trend_length": ("int", (3, None, False, False)),
    },
    "offsets": {
        "tool": ("int", (1, None, False, False)),
        "x_mode": ("choice", ("diameter", "radius")),
        "null_band": ("length", _GE0),
        "feedback_gain": ("number", _GAIN),
        "upper_limit": ("length", _GT0),
        "k_significance": ("number", _GE0),
        "decimals": ("int", (1, 6, False, False)),
        "nose_radius": ("choice", ("auto", "always", "off")),
        "current_x": ("length", None),
        "current_z": ("length", None),
        "current_r": ("length", _GE0),
        "x_features": ("ids", None),
        "z_features": ("ids", None),
    },
    "errspec": {
        "comp_type": ("int", (0, 1, False, False)),
        "decimals": ("int", (1, 12, False, False)),
        "points_per_feature": ("int", (2, 256, False, False)),
        "machine_units": ("choice", ("mm", "inch")),
    },
}


def _bounds_text(b) -> str:
    lo, hi, lo_open, hi_open = b
    if hi is None:
        return f"{'>' if lo_open else '>='} {lo:g}"
    if lo is None:
        return f"{'<' if hi_open else '<='} {hi:g}"
    return f"in {'(' if lo_open else '['}{lo:g}, {hi:g}{')' if hi_open else ']'}"


def _in_bounds(v, b) -> bool:
    lo, hi, lo_open, hi_open = b
    if lo is not None and (v <= lo if lo_open else v < lo):
        return False
    return not (hi is not None and (v >= hi if hi_open else v > hi))


def _job_section(r: _Reader, tree: dict, name: str, scale: float, profile: Profile) -> dict:
    """Validate one of the job sections (`[decision]`, `[capability]`, `[offsets]`,
    `[errspec]`): known keys only, each of the right type and range; lengths in mm."""
    sec = r.table(tree, name, "")
    spec = _JOB_KEYS[name]
    out: dict[str, Any] = {}
    for key, val in sec.items():
        path = f"{name}.{key}"
        if key not in spec:
            raise r.error(
                path, f"unknown key {key!r}; expected one of {', '.join(spec)}", value=val
            )
        kind, bounds = spec[key]
        if kind == "choice":
            if val not in bounds:
                raise r.error(
                    path,
                    f"unknown value {val!r}; expected one of {', '.join(map(repr, bounds))}",
                    value=val,
                )
            out[key] = val
            continue
        if kind == "bool":
            if not isinstance(val, bool):
                raise r.error(path, f"expected true or false, got {val!r}", value=val)
            out[key] = val
            continue
        if kind == "ids":
            if not isinstance(val, list) or not all(isinstance(v, str) for v in val):
                raise r.error(path, f"expected a list of feature ids, got {val!r}", value=val)
            for v in val:
                if v not in profile.ids:
                    raise r.error(
                        path,
                        f"unknown feature id {v!r}; the profile has {', '.join(profile.ids)}",
                        feature=v,
                        value=v,
                    )
            out[key] = tuple(val)
            continue
        if kind == "int":
            if isinstance(val, bool) or not isinstance(val, int):
                raise r.error(path, f"expected an integer, got {val!r}", value=val)
        elif isinstance(val, bool) or not isinstance(val, (int, float)):
            raise r.error(path, f"expected a number, got {val!r}", value=val)
        elif not math.isfinite(val):
            raise r.error(path, f"expected a finite number, got {val!r}", value=val)
        if bounds is not None and not _in_bounds(val, bounds):
            raise r.error(path, f"expected a number {_bounds_text(bounds)}, got {val!r}", value=val)
        if kind == "length":
            val = float(val) * scale
        elif kind == "per_mm2":
            val = float(val) / scale**2
        elif kind == "number":
            val = float(val)
        out[key] = val
    return out


def _parse(path: Path) -> dict:
    """The TOML tree of a study file: UTF-8 (a BOM accepted); a file in another
    encoding is read in the one its own ``encoding = "..."`` line names."""
    name = str(path)
    data = read_bytes(path, what="study file")
    try:
        text = decode(data, file=name)
    except InputError:
        m = re.search(rb'^\s*encoding\s*=\s*"([A-Za-z0-9_.-]+)"', data, flags=re.MULTILINE)
        if m is None:
            raise
        text = decode(
            data, file=name, encoding=check_encoding(m.group(1).decode("ascii"), file=name)
        )
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", file=name) from None


def load_study(path) -> Study:
    """Read and validate a study file.

    **Arguments:**

    - `path`: the TOML file; probe files and the part program are resolved
      relative to its folder.

    **Returns:** a :class:`Study` (mm, radius X).

    **Raises:** :class:`InputError` naming the file, key path, feature and value.
    """
    path = Path(path)
    name = str(path)
    tree = _parse(path)
    check_keys(tree, name, _JOB_KEYS)
    r = _Reader(name)
    study = r.table(tree, "study", "", required=True)
    encoding = check_encoding(study.get("encoding", "utf-8"), file=name)
    units = r.choice(study, "units", "study.", ("mm", "in"), "mm")
    scale = _MM_PER[units]

    prof = r.table(tree, "profile", "", required=True)
    x_mode = r.choice(prof, "x_mode", "profile.", ("radius", "diameter"), "radius")
    kind = r.choice(prof, "kind", "profile.", ("external", "internal"), "external")
    tangent_tol = r.number(prof, "tangent_tolerance_deg", "profile.", 0.5, positive=True)
    specs = _features(r, prof, scale, scale / 2 if x_mode == "diameter" else scale)
    try:
        side = profile_side(specs, internal=kind == "internal")
        profile = Profile(tuple(make_feature(s, side) for s in specs), tangent_tol_deg=tangent_tol)
    except ProfileError as exc:
        raise InputError(str(exc), file=name, feature=exc.feature) from None

    pr = r.table(tree, "probe", "", required=True)
    probe = ProbeSpec(
        ball_radius=r.number(pr, "ball_radius", "probe.", positive=True) * scale,
        ball_radius_u=r.number(pr, "ball_radius_u", "probe.", 0.0, nonneg=True) * scale,
        repeatability=r.number(pr, "repeatability", "probe.", 0.001 / scale, positive=True) * scale,
        x_mode=r.choice(pr, "x_mode", "probe.", ("diameter", "radius"), "diameter"),
        pretravel=r.number(pr, "pretravel", "probe.", 0.0) * scale,
        repeatability_dof=r.number(pr, "repeatability_dof", "probe.", 8.0, nonneg=True),
    )
    for f in profile.features:
        if f.kind == "arc" and not f.convex and f.radius <= probe.ball_radius:
            raise InputError(
                f"concave arc radius {f.radius:g} mm is not larger than the probe ball radius "
                f"{probe.ball_radius:g} mm: the ball cannot touch it",
                file=name,
                feature=f.id,
                value=f.radius,
            )

    m = r.table(tree, "machine", "")
    transform = MachineTransform(
        x_centre=r.number(m, "x_centre", "machine.", 0.0) * scale,
        z_offset=r.number(m, "z_offset", "machine.", 0.0) * scale,
        scale_x=r.number(m, "scale_x", "machine.", 0.0),
        scale_z=r.number(m, "scale_z", "machine.", 0.0),
        rotation=r.number(m, "rotation", "machine.", 0.0),
    )
    sources = _sources(r, r.table(tree, "uncertainty", ""), scale)

    ft = r.table(tree, "fit", "")
    fit = FitSettings(
        method=r.choice(ft, "method", "fit.", ("lsq", "robust", "bayes"), "robust"),
        loss=r.choice(
            ft, "loss", "fit.", ("linear", "huber", "soft_l1", "cauchy", "tukey"), "huber"
        ),
        scale=(r.number(ft, "scale", "fit.", positive=True) * scale) if "scale" in ft else None,
        known_sigma=r.boolean(ft, "known_sigma", "fit.", False),
        min_points_line=r.integer(ft, "min_points_line", "fit.", 3),
        min_points_arc=r.integer(ft, "min_points_arc", "fit.", 4),
        likelihood=r.choice(ft, "likelihood", "fit.", ("gaussian", "student_t"), "gaussian"),
        nu=r.number(ft, "nu", "fit.", 4.0, positive=True),
        bayes_steps=r.integer(ft, "bayes_steps", "fit.", 6000),
        bayes_walkers=(
            r.integer(ft, "bayes_walkers", "fit.", 0) if "bayes_walkers" in ft else None
        ),
        bayes_ensembles=r.integer(ft, "bayes_ensembles", "fit.", 4),
    )
    for key in ("fix", "free_transform"):
        val = ft.get(key, [])
        if not isinstance(val, list) or not all(isinstance(v, str) for v in val):
            raise r.error(f"fit.{key}", f"expected a list of names, got {val!r}", value=val)
    for item in ft.get("fix", []):
        fid, _, pname = item.partition(".")
        if fid not in profile.ids or pname not in profile[fid].param_names:
            raise r.error(
                "fit.fix",
                f"cannot fix {item!r}: expected 'feature.parameter' with a feature of the profile "
                "and one of its parameters "
                "(line: offset, rotation; arc: center_x, center_z, radius)",
                feature=fid,
                value=item,
            )
    transform_names = ("x_centre", "z_offset", "scale_x", "scale_z", "rotation")
    for item in ft.get("free_transform", []):
        if item not in transform_names:
            raise r.error(
                "fit.free_transform",
                f"unknown transform parameter {item!r}; "
                f"expected one of {', '.join(transform_names)}",
                value=item,
            )
    fit = FitSettings(
        **{
            **fit.__dict__,
            "fix": tuple(ft.get("fix", [])),
            "free_transform": tuple(ft.get("free_transform", [])),
        }
    )
    if fit.min_points_line < 3 or fit.min_points_arc < 4:
        raise r.error(
            "fit.min_points_line",
            "at least 3 points per line and 4 per arc are needed for an uncertainty",
        )

    cp = r.table(tree, "compensation", "")
    gain = r.number(cp, "gain", "compensation.", 1.0)
    if not 0.0 <= gain <= 1.0:
        raise r.error("compensation.gain", f"gain must be in [0, 1], got {gain!r}", value=gain)
    comp = CompensationSettings(
        gain=gain,
        max_correction=r.number(cp, "max_correction", "compensation.", 0.2 / scale, positive=True)
        * scale,
    )
    probe_files, program = _files(r, study, path.parent)
    program_settings = _program_settings(
        r, r.table(tree, "program", ""), scale, profile, path.parent
    )
    job = {
        name: MappingProxyType(_job_section(r, tree, name, scale, profile)) for name in _JOB_KEYS
    }
    known = {"study", "profile", "probe", "machine", "uncertainty", "fit", "compensation"}
    known |= {"program", *job}
    extra = {k: v for k, v in tree.items() if k not in known}
    return Study(
        path=path,
        name=str(study.get("name", path.stem)),
        units=units,
        profile=profile,
        probe=probe,
        transform=transform,
        sources=MappingProxyType(sources),
        probe_files=probe_files,
        program=program,
        fit=fit,
        compensation=comp,
        sections=MappingProxyType(extra),
        program_settings=program_settings,
        encoding=encoding,
        plausibility=MappingProxyType(_plausibility(r, r.table(tree, "plausibility", ""), scale)),
        **job,
    )


def _plausibility(r: _Reader, tree: dict, scale: float) -> dict:
    """`[plausibility]`: limits of the checks made before fitting (docs/formats.md)."""
    out: dict[str, Any] = {}
    for key in ("max_distance", "max_outside"):
        if key in tree:
            out[key] = r.number(tree, key, "plausibility.", positive=True) * scale
    out["duplicates"] = r.choice(tree, "duplicates", "plausibility.", ("drop", "error"), "drop")
    return out


def _program_settings(r: _Reader, tree: dict, scale: float, profile, base: Path) -> ProgramSettings:
    nose = (
        r.number(tree, "nose_radius", "program.", positive=True) * scale
        if "nose_radius" in tree
        else None
    )
    table = tree.get("tool_table")
    if table is not None:
        if not isinstance(table, str):
            raise r.error("program.tool_table", f"expected a file name, got {table!r}", value=table)
        table = base / table
        if not table.is_file():
            raise r.error("program.tool_table", f"tool table not found: {table}", value=str(table))
    mapping = tree.get("mapping", {})
    if not isinstance(mapping, dict):
        raise r.error(
            "program.mapping", f"expected a table {{feature = [line, ...]}}, got {mapping!r}"
        )
    clean = {}
    for fid, lines in mapping.items():
        if fid not in profile.ids:
            raise r.error(
                f"program.mapping.{fid}",
                f"unknown feature id {fid!r}; the profile has {', '.join(profile.ids)}",
                feature=fid,
            )
        if isinstance(lines, int) and not isinstance(lines, bool):
            lines = [lines]
        if (
            not isinstance(lines, list)
            or not lines
            or not all(isinstance(x, int) and not isinstance(x, bool) and x > 0 for x in lines)
        ):
            raise r.error(
                f"program.mapping.{fid}",
                f"expected program line numbers (positive integers), got {lines!r}",
                feature=fid,
                value=lines,
            )
        clean[fid] = tuple(lines)
    return ProgramSettings(
        nose_radius=nose,
        tool_table=table,
        mapping=MappingProxyType(clean),
        tolerance=r.number(tree, "tolerance", "program.", 0.01 / scale, positive=True) * scale,
    )
