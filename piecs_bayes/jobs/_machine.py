"""What to hand the machine from one fitted part: the error specification (PIECS
option 1: correction tables along the machine axes) and the tool-offset update
(option c), each alone or both for the machine files (`machine_data`). Data only;
`piecs_bayes.export` writes the files (native error spec, LinuxCNC tables, G10
blocks) and reads them back.
"""

from __future__ import annotations

import math
import re
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass

import numpy as np

from .. import __version__
from ..compensate import (
    CompensationTable,
    ErrorSpec,
    ToolOffsetUpdate,
    WearOffset,
    tool_offset_update,
)
from ..errors import AnalysisError, InputError
from ..fit import coverage_factor
from ..geometry import Arc, Line, part_to_machine
from ..uncertainty import (
    Characteristic,
    deviation_and_jacobian,
    feature_characteristic,
    nominal_points,
    u_systematic,
)
from ._options import offset_settings, source_sds

#: a line whose outward normal is within this of an axis is a diameter / a face
_AXIAL = 1.0 - 1e-9

#: the routes to the machine whose files carry machine data (see `jobs.apply_route`)
MACHINE_ROUTES = ("errspec", "tool_offset")


@dataclass(frozen=True, eq=False)
class MachineData:
    """The machine data of one fitted part, finished for
    `export.write_compensation_outputs` / `export.write_machine_files` to write:
    `errspec` (the [`error_spec`][]), `offsets` (the [`tool_offsets`][] update, or
    `None` when not asked for or not possible: `notes` say why), `notes` (the
    update's notes), `routes` (the routes of `MACHINE_ROUTES` they were made for)."""

    errspec: ErrorSpec
    offsets: ToolOffsetUpdate | None
    notes: tuple[str, ...] = ()
    routes: tuple[str, ...] = MACHINE_ROUTES


def machine_data(
    study, fit, *, gain=None, routes: Collection[str] = MACHINE_ROUTES
) -> MachineData | None:
    """The error spec and (when `routes` names `"tool_offset"`) the tool-offset update
    of one fitted part, for the files of the machine routes in `routes`.

    **Arguments:** `gain` for the error spec (see [`error_spec`][]); `routes` the
    routes whose files will be written (any of `APPLY_ROUTES`; those without machine
    data, `"program"` and `"none"`, are left out).

    **Returns:** a [`MachineData`][], or `None` when `routes` names neither
    `"errspec"` nor `"tool_offset"`. An update that cannot be made
    (`AnalysisError`: nothing measured to update from) leaves `offsets` `None`
    with the reason in `notes`.
    """
    routes = tuple(r for r in MACHINE_ROUTES if r in routes)
    if not routes:
        return None
    spec = error_spec(study, fit, gain=gain)
    upd, notes = None, ()
    if "tool_offset" in routes:
        try:
            upd, notes = tool_offsets(study, fit)
        except AnalysisError as e:
            notes = (str(e),)
    return MachineData(errspec=spec, offsets=upd, notes=tuple(notes), routes=routes)


def _table_name(prefix: str, fid: str) -> str:
    return f"{prefix}_{re.sub(r'[^A-Za-z0-9_.-]', '_', fid)}"


def _axial(f) -> str | None:
    """ "x" for a diameter (outward normal along X), "z" for a face, else None."""
    if not isinstance(f, Line):
        return None
    n = np.asarray(f.normal)
    if abs(n[0]) >= _AXIAL:
        return "x"
    if abs(n[1]) >= _AXIAL:
        return "z"
    return None


def _gain_of(gain, fid) -> float:
    g = gain.get(fid, 0.0) if isinstance(gain, Mapping) else gain
    g = float(g)
    if not (math.isfinite(g) and 0.0 <= g <= 1.0):
        raise InputError(f"gain must be in [0, 1], got {g!r}", feature=fid, value=g)
    return g


def error_spec(study, fit, *, gain=None, points_per_feature: int | None = None) -> ErrorSpec:
    """The error specification (PIECS option 1) of one fitted part.

    Corrections are $-g\\,e$ with $e$ the error along the corrected machine axis (mm),
    machine positions, X as radius:

    - `x_<feature>` for every line that is not a face (diameters, tapers): the X
      correction (radius) as a function of Z along the feature, `points_per_feature`
      rows; on a taper the X move that restores the surface is $\\delta/n_x$;
    - `z_<feature>` for every face: the Z correction as a function of X;
    - `x_radius`: the X correction at each diameter's nominal radius as a function of
      X (diameter errors across diameters: an error that depends on the axis' own
      position, what a LinuxCNC joint table can hold);
    - `z_position`: the Z correction at each face's Z (idem for Z).

    Arcs get no table: their error is not along one axis; the adjusted program
    carries them. Standard uncertainties: $g\\sqrt{u_\\text{fit}^2 + u_\\text{sys}^2}
    /|n_\\text{axis}|$.

    **Arguments:** `gain` a number or a mapping by feature id (default the study's
    `compensation.gain`; e.g. `DecisionTable.gains`); `points_per_feature` (default the
    study's `[errspec]`, else 11).
    """
    gain = study.compensation.gain if gain is None else gain
    k = int(points_per_feature or study.errspec.get("points_per_feature", 11))
    ts = np.linspace(0.0, 1.0, k)
    sds = source_sds(study)
    tables = []
    axis_rows: dict[str, list] = {"x": [], "z": []}
    for f in fit:
        if not isinstance(f.feature, Line):
            continue
        g = _gain_of(gain, f.feature.id)
        tables.append(_feature_table(f, g, ts, sds, study.transform))
        kind = _axial(f.feature)
        if kind is not None:  # the error at the mid-point, at the axis position
            axis_rows[kind].append(_axis_row(f, g, kind, sds, study.transform))
    tables += [_axis_table(axis, rows) for axis, rows in axis_rows.items() if rows]
    return ErrorSpec(
        tables=tuple(tables),
        description=f"{study.name}: PIECS error specification from the fit of part "
        f"{fit.part or '-'} ({fit.method})",
        source={
            "study": str(study.path),
            "part": fit.part,
            "method": fit.method,
            "gain": dict(gain) if isinstance(gain, Mapping) else float(gain),
            "piecs_bayes": __version__,
        },
    )


def _feature_table(f, g: float, ts, sds, transform) -> CompensationTable:
    """The correction along one line (X as a function of Z, or Z of X for a face)."""
    feat = f.feature
    axis = "z" if _axial(feat) == "z" else "x"
    pos_axis = "x" if axis == "z" else "z"
    na = np.asarray(feat.normal)[0 if axis == "x" else 1]
    val, jac = deviation_and_jacobian(feat, f.values, ts)
    cov = np.zeros((2, 2)) if f.covariance is None else np.asarray(f.covariance)
    u_fit = np.sqrt(np.maximum(np.einsum("ij,jk,ik->i", jac, cov, jac), 0.0))
    u = np.hypot(u_fit, u_systematic(feat, ts, sds))
    err = val / na  # error along the corrected axis
    q = nominal_points(feat, tuple(float(t) for t in ts))[0]
    qm = np.asarray(part_to_machine(np.asarray(q), transform))  # NumPy in: NumPy path
    what = "radius" if axis == "x" else "position"
    return CompensationTable(
        name=_table_name(axis, feat.id),
        axis=axis,
        position_axis=pos_axis,
        position=qm[:, 0] if pos_axis == "x" else qm[:, 1],
        correction=-g * err,
        u_correction=g * u / abs(na),
        feature=(feat.id,) * len(ts),
        description=f"{axis.upper()} correction ({what}) along {feat.id!r} as a function "
        f"of machine {pos_axis.upper()}, gain {g:g}",
    )


def _axis_row(f, g: float, kind: str, sds, transform) -> tuple:
    """(position, correction, u, feature) of a diameter or face at its mid-point."""
    feat = f.feature
    na = np.asarray(feat.normal)[0 if kind == "x" else 1]
    cov = np.zeros((2, 2)) if f.covariance is None else np.asarray(f.covariance)
    mv, mj = deviation_and_jacobian(feat, f.values, [0.5])
    mv, mj = float(mv[0]), mj[0]
    u_mid = math.hypot(
        math.sqrt(max(float(mj @ cov @ mj), 0.0)),
        float(u_systematic(feat, [0.5], sds)[0]),
    )
    qmid = np.asarray(part_to_machine(feat.midpoint[None], transform))[0]
    pos_mid = float(qmid[0] if kind == "x" else qmid[1])
    return pos_mid, -g * mv / na, g * u_mid, feat.id


def _axis_table(axis: str, rows) -> CompensationTable:
    """Diameter errors across diameters (X) or face errors across Z."""
    pos, corr, u, ids = zip(*rows, strict=True)
    return CompensationTable(
        name="x_radius" if axis == "x" else "z_position",
        axis=axis,
        position_axis=axis,
        position=pos,
        correction=corr,
        u_correction=u,
        feature=ids,
        description=(
            "X correction (radius) at each diameter's nominal radius: diameter errors "
            "across diameters"
            if axis == "x"
            else "Z correction at each face's nominal Z: face errors across Z"
        ),
    )


def _combine(chars: Sequence[Characteristic], factor) -> tuple[float, float, float]:
    """Inverse-variance mean of `factor * mean` over characteristics, its random
    uncertainty and the (common, not averaged) systematic one."""
    e = np.array([c.mean * fa for c, fa in zip(chars, factor, strict=True)])
    uf = np.array([max(c.u_fit, 1e-12) for c in chars])
    w = 1.0 / uf**2
    mean = float(np.sum(w * e) / np.sum(w))
    u_rand = float(1.0 / math.sqrt(np.sum(w)))
    u_sys = float(np.mean([c.u_systematic for c in chars]))
    return mean, u_rand, u_sys


def tool_offsets(study, fit) -> tuple[ToolOffsetUpdate, tuple[str, ...]]:
    """Wear-offset update (PIECS option c) from one fitted part, and notes.

    - X: the inverse-variance mean radial error of the diameters (cylindrical lines,
      or `[offsets] x_features`) at their mid-points, as a diameter error in
      `x_mode = "diameter"` (default);
    - Z: the mean Z error of the faces (or `z_features`);
    - R: the effective minus the table nose radius from the arcs' radius changes
      ($-s\\,\\Delta r$, $s$ = +1 convex, -1 concave: a larger nose moves every surface
      into the material), used with `nose_radius = "auto"` (default) only when it is
      significant ($|e| > t_{0.975}(\\nu)\\,u$, $\\nu$ the degrees of freedom of the
      probe sigma its covariance is scaled by, `fit.sigma.dof`; the normal 1.96 when
      the sigma is known), always with `"always"`, never with `"off"`. When R
      changes, the X and Z errors it explains are taken off them (this assumes the
      finish cut uses G41/G42 nose-radius compensation).

    Null band, feedback gain and upper limit come from `[offsets]`.

    **The tool** is the one that cuts the finish pass (`program_tool`): with a part
    program, the T word in force on its finish-cut blocks (`T0202`: tool 2, wear
    offset 2), and `[offsets] tool`, when given, must match it; without a program,
    `[offsets] tool` (default 1). The first note says where the number came from.
    """
    cfg = study.offsets
    st = offset_settings(study)
    x_mode = cfg.get("x_mode", "diameter")
    notes: list[str] = []
    tool, offset, source = program_tool(study, notes)
    notes.insert(0, f"tool {tool}, wear offset {offset}: from {source}")
    sds = source_sds(study)
    fitted = {f.id: f for f in fit}

    def mids(key, kind):
        ids = _pick(study, fitted, key, kind, notes)
        return [feature_characteristic(fitted[i], at="mid", sources=sds) for i in ids]

    xs, zs = mids("x_features", "x"), mids("z_features", "z")
    x_err, u_x, nx = _axis_error(xs, 0, notes)
    z_err, u_z, nz = _axis_error(zs, 1, notes)
    dof = getattr(getattr(fit, "sigma", None), "dof", math.inf)
    r_err, u_r = _nose_radius_error(fitted, cfg.get("nose_radius", "auto"), notes, dof)
    xs_factor = 2.0 if x_mode == "diameter" else 1.0

    def update(x_e, z_e):
        return tool_offset_update(
            WearOffset(tool, offset, x_mode, source),
            x_error=None if x_e is None else xs_factor * x_e,
            u_x=0.0 if u_x is None else xs_factor * u_x,
            z_error=z_e,
            u_z=0.0 if u_z is None else u_z,
            nose_radius_error=r_err,
            u_r=0.0 if u_r is None else u_r,
            settings=st,
        )

    if x_err is None and z_err is None and r_err is None:
        raise AnalysisError(
            "no tool-offset update: no diameter, face or significant arc was measured"
        )
    upd = update(x_err, z_err)
    if upd.r.applied and not upd.blocked:
        d_r = upd.r.correction  # surfaces move out of the material by this much
        upd = update(
            None if x_err is None else x_err + d_r * nx,
            None if z_err is None else z_err + d_r * nz,
        )
        notes.append(
            f"X and Z errors corrected for the nose-radius change {d_r * 1e3:+.2f} um "
            "(assumes G41/G42 nose-radius compensation in the finish cut)"
        )
    return upd, tuple(notes)


def program_tool(study, notes: list | None = None) -> tuple[int, int, str]:
    """`(tool, wear offset, where from)` of the tool that cuts the study's finish pass.

    - With a part program: the T word in force on the finish-cut blocks (those mapped
      to the profile, `gcode.finish_cut_tools`; `gcode.tool_call` reads `Tttoo`,
      `T202`, `T2` and LinuxCNC's `T2 M6`). `[offsets] tool`, when given, must be that
      tool (`InputError` naming the study, the program's T word, its line and both
      numbers); several tools on the finish blocks need `[offsets] tool` to choose.
      A program without a T word before its finish cut falls back to `[offsets] tool`.
    - Without a program: `[offsets] tool`, default 1.

    `notes` (a list) receives what the caller should know (an unmapped program, finish
    blocks cut before any T word).
    """
    notes = [] if notes is None else notes
    named = study.offsets.get("tool")
    fallback = int(named) if named is not None else 1
    own = (
        f"[offsets] tool = {fallback} in {study.path}"
        if named is not None
        else "the default [offsets] tool = 1"
    )
    if study.program is None:
        return fallback, fallback, f"{own} (the study names no part program)"
    from ..gcode import finish_cut_tools, read_gcode

    prog = str(study.program)
    ps = study.program_settings
    found = finish_cut_tools(
        read_gcode(study.program, ps.dialect),
        study.profile,
        tol_mm=ps.tolerance,
        mapping=dict(ps.mapping) or None,
    )
    if not found.mapped:
        notes.append(
            f"tool: the finish-cut blocks of {prog} do not map to the profile "
            f"({found.why}); the tool is read from its compensated (or feed) moves"
        )
    if found.untooled and found.calls:
        notes.append(f"tool: lines {_ranges(found.untooled)} of {prog} cut before any T word")
    if not found.calls:
        return fallback, fallback, f"{own} ({prog} calls no tool before its finish cut)"
    call = _choose_call(study, found.calls, named, prog)
    if call.offset < 1:
        raise InputError(
            f"the finish cut runs with its wear offset cancelled ({call.word}: offset 00); "
            "a wear-offset update would not act on it",
            file=prog,
            line=call.line,
            value=call.word,
        )
    blocks = _ranges(call.blocks)
    how = "named by [offsets] tool, " if named is not None else ""
    return (
        call.tool,
        call.offset,
        f"the T word {call.word} on line {call.line} of {prog} ({how}in force on the "
        f"finish-cut lines {blocks})",
    )


def _choose_call(study, calls, named, prog):
    """The one tool call on the finish blocks, or the one `[offsets] tool` names."""
    listed = ", ".join(
        f"{c.word} (line {c.line}: tool {c.tool}, wear offset {c.offset})" for c in calls
    )
    if named is None:
        if len(calls) > 1:
            raise InputError(
                f"several tools cut the finish-cut blocks of {prog}: {listed}; name the one "
                f"to update with [offsets] tool",
                file=str(study.path),
            )
        return calls[0]
    match = [c for c in calls if c.tool == named]
    if len(match) == 1:
        return match[0]
    if not match:
        c = calls[0]
        raise InputError(
            f"[offsets] tool = {named} in {study.path} does not match the part program: "
            f"its finish cut is made with tool {c.tool} ({c.word}, wear offset {c.offset})"
            + (f"; the finish-cut tools are {listed}" if len(calls) > 1 else ""),
            file=prog,
            line=c.line,
            value=named,
        )
    raise InputError(
        f"tool {named} cuts the finish-cut blocks of {prog} with several wear offsets: "
        f"{listed}; one update cannot serve them all",
        file=str(study.path),
    )


def _ranges(lines) -> str:
    """Line numbers as ranges: 7-13, 20."""
    out, lines = [], sorted(lines)
    start = prev = lines[0]
    for ln in [*lines[1:], None]:
        if ln is not None and ln == prev + 1:
            prev = ln
            continue
        out.append(f"{start}-{prev}" if prev > start else str(start))
        if ln is not None:
            start = prev = ln
    return ", ".join(out)


def _pick(study, fitted, key: str, kind: str, notes: list) -> list[str]:
    """The measured diameters (`kind` "x") or faces ("z"), or those `[offsets] key` names."""
    ids = study.offsets.get(key)
    if ids is None:
        return [fid for fid, f in fitted.items() if _axial(f.feature) == kind]
    missing = [fid for fid in ids if fid not in fitted]
    if missing:
        notes.append(f"{key}: {', '.join(missing)} not measured on this part")
    bad = [fid for fid in ids if fid in fitted and _axial(fitted[fid].feature) != kind]
    if bad:
        raise InputError(
            f"offsets.{key}: {', '.join(bad)} is not a "
            f"{'diameter' if kind == 'x' else 'face'} (a line normal to "
            f"{kind.upper()})",
            file=str(study.path),
            value=bad,
        )
    return [fid for fid in ids if fid in fitted]


def _axis_error(chars, axis: int, notes: list):
    """(error, u, mean normal component) along X (`axis` 0) or Z (1) from the
    characteristics, `(None, None, 1.0)` without any; notes when diameters disagree."""
    if not chars:
        return None, None, 1.0
    ns = [c.normal[axis] for c in chars]
    err, ur, us = _combine(chars, ns)
    if axis == 0:
        _check_agreement(chars, ns, err, notes)
    return err, math.hypot(ur, us), float(np.mean(ns))


def _check_agreement(xs, nxs, x_err: float, notes: list) -> None:
    radial = np.array([c.mean * n for c, n in zip(xs, nxs, strict=True)])
    u_each = np.array([max(c.u_fit, 1e-12) for c in xs])
    dof = len(xs) - 1
    chi2 = float(np.sum(((radial - x_err) / u_each) ** 2))
    if dof > 0 and chi2 > dof + 3.0 * math.sqrt(2.0 * dof):
        each = ", ".join(f"{c.feature} {v * 1e3:+.1f}" for c, v in zip(xs, radial, strict=True))
        notes.append(
            f"the diameters disagree beyond their uncertainties (radial errors {each} um; "
            f"chi2 {chi2:.0f} on {dof} dof): a tool offset corrects only their mean, the "
            "error spec or the adjusted program corrects each"
        )


def _dof_text(dof: float) -> str:
    return "inf" if math.isinf(dof) else f"{dof:.3g}"


def _nose_radius_error(fitted, mode: str, notes: list, dof: float = math.inf):
    """Effective minus table nose radius from the arcs' radius changes, or (None, None)
    when not significant: $|e| \\le t_{0.975}(\\nu)\\,u$ with $\\nu$ = `dof`, the
    degrees of freedom of the probe sigma the arcs' covariances are scaled by."""
    arcs = [
        f
        for f in fitted.values()
        if isinstance(f.feature, Arc) and "radius" not in f.fixed and f.covariance is not None
    ]
    if mode == "off" or not arcs:
        return None, None
    e = np.array([-f.feature.sense * f.values[2] for f in arcs])
    u = np.array([max(math.sqrt(f.covariance[2, 2]), 1e-12) for f in arcs])
    w = 1.0 / u**2
    est, u_est = float(np.sum(w * e) / np.sum(w)), float(1.0 / math.sqrt(np.sum(w)))
    ids = ", ".join(f.id for f in arcs)
    k = coverage_factor(dof, 0.95)  # Student-t 97.5 % quantile (the normal's at inf)
    if mode == "always" or abs(est) > k * u_est:
        notes.append(
            f"nose radius from {ids}: effective minus table radius {est * 1e3:+.2f} "
            f"± {u_est * 1e3:.2f} um"
        )
        return est, u_est
    notes.append(
        f"nose radius not updated: the radius change of {ids} gives "
        f"{est * 1e3:+.2f} ± {u_est * 1e3:.2f} um, not significant (|e| <= {k:.3g} u, "
        f"t 97.5 % at {_dof_text(dof)} dof)"
    )
    return None, None
