"""Readers of the study file's core sections: `[study]` files, `[profile]` and its
features, `[probe]`, `[machine]`, `[uncertainty]`, `[fit]` and `[compensation]`.

Each takes a [`Reader`][] (which names the file and key path in its errors) and
the length scale to millimetres; X is converted to radius here.
"""

from __future__ import annotations

import glob
import math
import re
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType
from typing import Any

from ..errors import InputError
from ..geometry import (
    TOLERANCE_ON,
    MachineTransform,
    Profile,
    ProfileError,
    feature_form,
    make_feature,
    profile_side,
    tolerance_choices,
)
from ._reader import Reader
from ._schema import check_source
from ._settings import APPLY_ROUTES, CompensationSettings, FitSettings, ProbeSpec, split_fix

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
_TRANSFORM_NAMES = ("x_centre", "z_offset", "scale_x", "scale_z", "rotation")

#: the largest length a study may hold (mm): 100 m, beyond the travel of any lathe (the
#: largest roll lathes turn some 20-30 m); a larger number is a typo or a unit slip, and
#: one near 1e300 would overflow every fit
MAX_LENGTH_MM = 1e5
#: `[machine]` number -> (largest magnitude, its unit, what it is): offsets of a lathe
#: within `MAX_LENGTH_MM`; axis scale errors are parts per million (a machine beyond
#: 1 % is broken, not mis-scaled); the probe frame's rotation a small squareness error
#: (0.01 rad = 0.57 deg, 1 mm over 100 mm)
_TRANSFORM_LIMITS = {
    "x_centre": (MAX_LENGTH_MM, "mm", "a centre-line offset beyond any machine's travel"),
    "z_offset": (MAX_LENGTH_MM, "mm", "a work offset beyond any machine's travel"),
    "scale_x": (0.01, "", "an X axis scale error above 1 % (a machine's is some ppm)"),
    "scale_z": (0.01, "", "a Z axis scale error above 1 % (a machine's is some ppm)"),
    "rotation": (
        0.01,
        "rad",
        "a probe-frame rotation above 0.57 deg (a squareness error is some urad)",
    ),
}


def _check_arc(r: Reader, spec: dict, path: str, fid: str) -> None:
    """An arc's start and end differ and lie at one distance from its centre."""
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
            f"start and end are not equidistant from the centre (radii {r0:.6f} and {r1:.6f} mm)",
            feature=fid,
        )


def _tolerance(r: Reader, f: dict, path: str, fid: str, scale: float) -> tuple[float, float]:
    """A feature's `tolerance = [lower, upper]` as drawn (default ±0.01), in mm."""
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
    return (float(tol[0]) * scale, float(tol[1]) * scale)


#: a feature's form in words, and what its tolerance is on when drawn
_FORM_TEXT = {
    "cylinder": ("a diameter (cylinder)", "on the diameter Ø, as drawn"),
    "face": ("a face or shoulder", "on its axial position Z, as drawn"),
    "taper": ("a taper", "along the surface normal, a profile tolerance"),
    "arc": ("an arc", "along the surface normal, a profile tolerance"),
}


def _tolerance_on(r: Reader, f: dict, spec: dict, path: str, fid: str) -> str:
    """A feature's `tolerance_on`: required, and one that fits the feature's form."""
    form = feature_form(spec["p0"], spec["p1"], spec.get("center"))
    choices = tolerance_choices(form)
    words, meaning = _FORM_TEXT[form]
    on = f.get("tolerance_on")
    if on is None:
        tol = f.get("tolerance", "(default [-0.01, 0.01])")
        other = "".join(f'; "{c}" for a tolerance on the {c}' for c in choices[1:])
        raise r.error(
            f"{path}tolerance_on",
            f"missing: {fid!r} is {words}; say what its tolerance {tol} limits: add the line "
            f'tolerance_on = "{choices[0]}" to its [[profile.feature]] table (the tolerance '
            f"is then {meaning}{other})",
            feature=fid,
        )
    if on not in TOLERANCE_ON:
        raise r.error(
            f"{path}tolerance_on",
            f"unknown value {on!r}; expected one of {', '.join(map(repr, TOLERANCE_ON))}",
            feature=fid,
            value=on,
        )
    if on not in choices:
        raise r.error(
            f"{path}tolerance_on",
            f"{on!r} does not fit {fid!r}, {words}: write "
            + " or ".join(f'tolerance_on = "{c}"' for c in choices)
            + f" (the tolerance is then {meaning})",
            feature=fid,
            value=on,
        )
    return on


def _feature(r: Reader, f, i: int, scale: float, xscale: float) -> dict:
    """The spec of `[[profile.feature]]` number `i` for `geometry.make_feature`."""
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

    def pt(key):
        x, z = r.point(f, key, path, fid)
        for axis, v, mm in (("x", x, abs(x * xscale)), ("z", z, abs(z * scale))):
            if mm > MAX_LENGTH_MM:
                what = " (a diameter)" if axis == "x" and xscale != scale else ""
                raise r.error(
                    f"{path}{key}",
                    f"{axis} = {v:g}{what} is beyond any plausible part size (expected "
                    f"|{axis}| <= {MAX_LENGTH_MM / 1e3:g} m, {_in_units(MAX_LENGTH_MM, scale)})",
                    feature=fid,
                    value=v,
                )
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
        _check_arc(r, spec, path, fid)
    elif math.dist(spec["p0"], spec["p1"]) == 0:
        raise r.error(f"{path}end", "line has zero length (start == end)", feature=fid)
    spec["tolerance"] = _tolerance(r, f, path, fid, scale)
    return spec


def _features(r: Reader, prof: dict, scale: float, xscale: float) -> list[dict]:
    feats = prof.get("feature")
    if not isinstance(feats, list) or not feats:
        raise r.error("profile.feature", "the profile needs at least one [[profile.feature]]")
    return [_feature(r, f, i, scale, xscale) for i, f in enumerate(feats)]


def read_profile(r: Reader, tree: dict, scale: float) -> Profile:
    """`[profile]` and its `[[profile.feature]]` tables: the nominal profile."""
    prof = r.table(tree, "profile", "", required=True)
    x_mode = r.choice(prof, "x_mode", "profile.", ("radius", "diameter"), "radius")
    kind = r.choice(prof, "kind", "profile.", ("external", "internal"), "external")
    tangent_tol = r.number(prof, "tangent_tolerance_deg", "profile.", 0.5, positive=True)
    specs = _features(r, prof, scale, scale / 2 if x_mode == "diameter" else scale)
    try:
        side = profile_side(specs, internal=kind == "internal")
        Profile(tuple(make_feature(s, side) for s in specs), tangent_tol_deg=tangent_tol)
    except ProfileError as exc:  # a chain that is not connected, before its tolerances
        raise InputError(str(exc), file=r.file, feature=exc.feature) from None
    for i, (f, s) in enumerate(zip(prof["feature"], specs, strict=True)):
        s["tolerance_on"] = _tolerance_on(r, f, s, f"profile.feature[{i}].", s["id"])
    return Profile(tuple(make_feature(s, side) for s in specs), tangent_tol_deg=tangent_tol)


def _probe_tool(r: Reader, pr: dict) -> int | None:
    """`[probe] tool`: the probe's tool number (1-99 on a lathe turret), or None."""
    if "tool" not in pr:
        return None
    t = pr["tool"]
    if isinstance(t, bool) or not isinstance(t, int) or not 1 <= t <= 99:
        raise r.error("probe.tool", f"expected a tool number 1-99, got {t!r}", value=t)
    return t


def _probe_calibration(r: Reader, pr: dict, base: Path, ball_radius: float, tool, u: float):
    """`[probe] calibration`: the probe_cal.json (relative to the study), or None.
    Refused: a calibration whose r0 is another ball's (more than 0.05 mm from the
    declared `ball_radius`), of another tool than `[probe] tool`, or beside a
    declared `ball_radius_u` (the calibration carries the radius's uncertainty)."""
    from ._probe_cal import read_probe_calibration

    name = pr.get("calibration")
    if name is None:
        return None
    if not isinstance(name, str) or not name.strip():
        raise r.error("probe.calibration", f"expected a file name, got {name!r}", value=name)
    cal = read_probe_calibration(base / name)
    if u > 0:
        raise r.error(
            "probe.ball_radius_u",
            f"{u:g} mm beside a calibration ({name}): the calibration's covariance is the "
            "radius's uncertainty; remove ball_radius_u",
            value=u,
        )
    if abs(cal.r0 - ball_radius) > 0.05:
        raise r.error(
            "probe.calibration",
            f"{name} gives r0 = {cal.r0:.4f} mm for a declared ball_radius of {ball_radius:g} mm: "
            "the calibration of another probe or stylus",
            value=cal.r0,
        )
    m = re.fullmatch(r"\s*T?0*(\d+)\b.*", str(cal.probe or ""), flags=re.IGNORECASE)
    if tool is not None and m and int(m.group(1)) != tool:
        raise r.error(
            "probe.calibration",
            f"{name} calibrates probe {cal.probe!r}, the study's probe is tool {tool}: the "
            "calibration of another probe",
            value=cal.probe,
        )
    return cal


def read_probe(
    r: Reader, tree: dict, scale: float, profile: Profile, base: Path = Path(".")
) -> ProbeSpec:
    """`[probe]`; a concave arc the ball cannot touch is an error. With
    `calibration`, the calibrated r0 is the ball radius (`_probe_calibration`)."""
    pr = r.table(tree, "probe", "", required=True)
    probe = ProbeSpec(
        ball_radius=r.number(pr, "ball_radius", "probe.", positive=True) * scale,
        ball_radius_u=r.number(pr, "ball_radius_u", "probe.", 0.0, nonneg=True) * scale,
        repeatability=r.number(pr, "repeatability", "probe.", 0.001 / scale, positive=True) * scale,
        x_mode=r.choice(pr, "x_mode", "probe.", ("diameter", "radius"), "diameter"),
        pretravel=r.number(pr, "pretravel", "probe.", 0.0) * scale,
        repeatability_dof=r.number(pr, "repeatability_dof", "probe.", 8.0, nonneg=True),
        tool=_probe_tool(r, pr),
        feed=r.number(pr, "feed", "probe.", positive=True) * scale if "feed" in pr else None,
        calibration_max_age_days=r.number(
            pr, "calibration_max_age_days", "probe.", 30.0, positive=True
        ),
    )
    cal = _probe_calibration(r, pr, base, probe.ball_radius, probe.tool, probe.ball_radius_u)
    if cal is not None:
        probe = replace(probe, ball_radius=cal.r0, calibration=cal)
    for f in profile.features:
        if f.kind == "arc" and not f.convex and f.radius <= probe.ball_radius:
            raise InputError(
                f"concave arc radius {f.radius:g} mm is not larger than the probe ball radius "
                f"{probe.ball_radius:g} mm: the ball cannot touch it",
                file=r.file,
                feature=f.id,
                value=f.radius,
            )
    return probe


def _in_units(mm: float, scale: float) -> str:
    """A length in mm as the study writes it: ``100000 mm`` or ``3937 in``."""
    return f"{mm:g} mm" if scale == 1.0 else f"{mm / scale:.4g} in"


def read_machine(r: Reader, tree: dict, scale: float) -> MachineTransform:
    """`[machine]`: the nominal probe-to-machine transform; each number finite and
    within `_TRANSFORM_LIMITS` (an absurd one is named here, not as implausible probe
    points)."""
    m = r.table(tree, "machine", "")
    values = {}
    for key, (limit, unit, what) in _TRANSFORM_LIMITS.items():
        val = r.number(m, key, "machine.", 0.0)
        length = unit == "mm"
        if abs(val * scale if length else val) > limit:
            if length:
                written = f"{val:g} {'mm' if scale == 1.0 else 'in'}"
                shown = f"{limit / 1e3:g} m, {_in_units(limit, scale)}"
            else:
                written = f"{val:g}{' ' + unit if unit else ''}"
                shown = f"{limit:g}{' ' + unit if unit else ''}"
            raise r.error(
                f"machine.{key}",
                f"{written} is {what} (expected |{key}| <= {shown})",
                value=val,
            )
        values[key] = val * scale if length else val
    return MachineTransform(**values)


def read_sources(r: Reader, tree: dict, scale: float) -> dict:
    """`[uncertainty]`: one distribution table per known source, lengths in mm."""
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
            elif name in _LENGTH_SOURCES and key == "mu":  # a lognormal's log of a length
                spec[key] = float(val) + math.log(scale)
        out[name] = MappingProxyType(spec)
    return out


def _fit_values(r: Reader, ft: dict, scale: float) -> dict[str, Any]:
    """The scalar `[fit]` settings, read in the order they are declared."""
    return {
        "method": r.choice(ft, "method", "fit.", ("lsq", "robust", "bayes"), "robust"),
        "loss": r.choice(
            ft, "loss", "fit.", ("linear", "huber", "soft_l1", "cauchy", "tukey"), "huber"
        ),
        "scale": (r.number(ft, "scale", "fit.", positive=True) * scale) if "scale" in ft else None,
        "known_sigma": r.boolean(ft, "known_sigma", "fit.", False),
        "min_points_line": r.integer(ft, "min_points_line", "fit.", 3),
        "min_points_arc": r.integer(ft, "min_points_arc", "fit.", 4),
        "likelihood": r.choice(ft, "likelihood", "fit.", ("gaussian", "student_t"), "gaussian"),
        "nu": r.number(ft, "nu", "fit.", 4.0, positive=True),
        "bayes_steps": r.integer(ft, "bayes_steps", "fit.", 6000),
        "bayes_walkers": (
            r.integer(ft, "bayes_walkers", "fit.", 0) if "bayes_walkers" in ft else None
        ),
        "bayes_ensembles": r.integer(ft, "bayes_ensembles", "fit.", 4),
    }


def _check_fit_names(r: Reader, ft: dict, profile: Profile) -> None:
    """`fix` names `feature.parameter` of the profile; `free_transform` transform names."""
    for key in ("fix", "free_transform"):
        val = ft.get(key, [])
        if not isinstance(val, list) or not all(isinstance(v, str) for v in val):
            raise r.error(f"fit.{key}", f"expected a list of names, got {val!r}", value=val)
    for item in ft.get("fix", []):
        fid, pname = split_fix(item)
        if fid not in profile.ids or pname not in profile[fid].param_names:
            raise r.error(
                "fit.fix",
                f"cannot fix {item!r}: expected 'feature.parameter' with a feature of the profile "
                "and one of its parameters "
                "(line: offset, rotation; arc: center_x, center_z, radius)",
                feature=fid,
                value=item,
            )
    for item in ft.get("free_transform", []):
        if item not in _TRANSFORM_NAMES:
            raise r.error(
                "fit.free_transform",
                f"unknown transform parameter {item!r}; "
                f"expected one of {', '.join(_TRANSFORM_NAMES)}",
                value=item,
            )


def read_fit(r: Reader, tree: dict, scale: float, profile: Profile) -> FitSettings:
    """`[fit]`: how the features are fitted."""
    ft = r.table(tree, "fit", "")
    values = _fit_values(r, ft, scale)
    _check_fit_names(r, ft, profile)
    fit = FitSettings(
        **values,
        fix=tuple(ft.get("fix", [])),
        free_transform=tuple(ft.get("free_transform", [])),
    )
    if fit.min_points_line < 3 or fit.min_points_arc < 4:
        raise r.error(
            "fit.min_points_line",
            "at least 3 points per line and 4 per arc are needed for an uncertainty",
        )
    return fit


def read_compensation(r: Reader, tree: dict, scale: float) -> CompensationSettings:
    """`[compensation]`: the mirroring gain in [0, 1], the largest correction and
    the route to the machine (`apply`, one of `APPLY_ROUTES`; `None` when not given)."""
    cp = r.table(tree, "compensation", "")
    apply = r.choice(cp, "apply", "compensation.", APPLY_ROUTES, None) if "apply" in cp else None
    gain = r.number(cp, "gain", "compensation.", 1.0)
    if not 0.0 <= gain <= 1.0:
        raise r.error("compensation.gain", f"gain must be in [0, 1], got {gain!r}", value=gain)
    return CompensationSettings(
        gain=gain,
        max_correction=r.number(cp, "max_correction", "compensation.", 0.2 / scale, positive=True)
        * scale,
        apply=apply,
    )


def read_probe_format(r: Reader, tree: dict, base: Path, transform) -> tuple[str, Path | None]:
    """`[study]` `probe_format` (how the probe files are written: `PROBE_FORMATS`) and
    `probe_plan` (the plan.json a control's file is read against: needed by every
    format but ``"csv"``). A control's file is in the gauging program's work frame:
    `[machine] z_offset` must then be 0 (the work offset is already applied)."""
    from ._control_probe import PROBE_FORMATS

    fmt = r.choice(tree, "probe_format", "study.", PROBE_FORMATS, "csv")
    plan = tree.get("probe_plan")
    if plan is not None and not isinstance(plan, str):
        raise r.error("study.probe_plan", f"expected a file name, got {plan!r}", value=plan)
    if fmt == "csv":
        return fmt, (base / plan if plan else None)
    if plan is None:
        raise r.error(
            "study.probe_plan",
            f"missing: probe_format {fmt!r} is read against the plan.json of the gauging "
            "program (line k of the file is point k of the plan)",
        )
    if transform.z_offset != 0.0:
        raise r.error(
            "machine.z_offset",
            f"{transform.z_offset:g} mm with probe_format {fmt!r}: a control's probe file is "
            "in the gauging program's work frame (the work offset already applied): set 0",
            value=transform.z_offset,
        )
    return fmt, base / plan


def read_files(r: Reader, tree: dict, base: Path) -> tuple[tuple[Path, ...], Path | None]:
    """`[study]` `probe_files` (glob patterns allowed) and `part_program`, relative
    to `base`."""
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
