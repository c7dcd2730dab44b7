"""A new study from the finish program: `piecs-bayes init` ([`init_study`][]).

The study's `[profile]` is the finish contour of the part program
(`gcode.finish_contour`: the moves of a G41/G42 run strictly between its lead-in and its
exit, one feature each), so that the profile and the program cannot disagree.
[`study_from_program`][] adds readable, unique ids (``dia_24``, ``bore_20``,
``face_z60``, ``taper_1``, ``arc_1``; ``p`` for the decimal point), `tolerance_on` by
form, ISO 2768-1 general tolerances of the class (as drawn, marked to be replaced by the
drawing's), the `[study]`, `[probe]` and `[program]` keys the program gives and marked
placeholders for the others. [`init_study`][] writes the text atomically after loading
it back (`io.load_study`) and comparing its geometry with the program's; an existing
file is refused without `force`. It returns an [`InitResult`][].

Ids, tolerances and every key written: docs/formats.md, "Study from the part program".
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass
from pathlib import Path

from ..errors import AnalysisError, InputError
from ..gcode import FinishContour, finish_contour, path_contour, read_gcode, read_tool_table
from ..geometry import iso2768_tolerance
from ..io import FeatureText, Setting, StudyText, load_study, study_toml, write_file_atomic
from ._init_names import MM_PER, feature_ids, general_tolerance

_GEOMETRY_TOL_MM = 1e-9


@dataclass(frozen=True)
class InitResult:
    """What `init` made: the study's `content` and `text`, the `contour` it comes
    from, and, once written, its `path` and the loaded `study`."""

    content: StudyText
    text: str
    contour: FinishContour
    path: Path | None = None
    study: object = None

    def __repr__(self) -> str:
        ids = ", ".join(f.id for f in self.content.features)
        return f"InitResult({self.path or '<not written>'}: {self.content.kind}, {ids})"


def _tip_text(tip: int) -> str:
    return "the nose centre" if tip in (0, 9) else f"the imaginary tip of orientation {tip}"


def _path_settings(nose: ToolNose) -> tuple[Setting, ...]:
    if nose.tip is None:
        return ()
    why = f"the program is a tool path (no G41/G42) of {_tip_text(nose.tip)}"
    return (Setting("path_tip", nose.tip, why),)


def _nose_radius(contour, nose: ToolNose, scale) -> Setting:
    tool_table, tool_units = nose.table, nose.units
    if nose.radius is not None:
        why = "the tool path's nose radius, given to init (--nose-radius)"
        return Setting("nose_radius", nose.radius / scale, why)
    comp = contour.comp
    key = "nose_radius"
    if comp.diameter_mm is not None:
        r = abs(comp.diameter_mm) / 2
        why = f"the finish tool's, from the D word of {comp.code} at line {comp.line}"
        return Setting(key, r / scale, why)
    if tool_table is not None:
        tools = read_tool_table(tool_table, units=tool_units)
        if comp.tool is None or comp.tool not in tools:
            raise InputError(
                f"{comp.code} at line {comp.line} uses tool {comp.tool}, which the tool table "
                f"{tool_table} does not hold",
                file=contour.program,
                line=comp.line,
            )
        why = f"tool {comp.tool} of {Path(tool_table).name}: the finish tool's nose radius"
        return Setting(key, tools[comp.tool].radius_mm / scale, why)
    placeholder = 0.4 / scale if scale == 1.0 else 0.016
    return Setting(key, placeholder, "the finish tool's nose radius (gouge check)", True)


def _dialect_comment(dialect) -> str:
    if dialect.reason == "given":
        return "the part program's dialect, as given"
    return f"the part program's dialect, detected: {dialect.reason}"


def _check_kind(contour: FinishContour, kind: str | None) -> None:
    if kind is None or kind == contour.kind:
        return
    if kind not in ("external", "internal"):
        raise InputError(f"kind: got {kind!r}, expected 'external' or 'internal'", value=kind)
    comp = contour.comp
    side = "left" if contour.side == 1 else "right"
    other = "G42" if comp.side == "left" else "G41"
    raise InputError(
        f"{comp.code} (line {comp.line}) puts the tool nose {side} of travel, which makes this "
        f"contour {contour.kind}: as {kind} the nose would be on the material side and cut "
        f"into the part; use {other}, or --kind {contour.kind}",
        file=contour.program,
        line=comp.line,
        value=comp.code,
    )


def _ball_radius(features, contour, ball_radius_mm, scale) -> Setting:
    concave = [
        (s.radius, fid)
        for s, (fid, _) in zip(contour.segments, features, strict=True)
        if s.kind == "arc" and _is_concave(s, contour.side)
    ]
    smallest = min(concave, default=None)
    if ball_radius_mm is not None:
        if smallest is not None and smallest[0] <= ball_radius_mm:
            raise InputError(
                f"concave arc radius {smallest[0]:g} mm is not larger than the probe ball "
                f"radius {ball_radius_mm:g} mm: the ball cannot touch it",
                file=contour.program,
                feature=smallest[1],
                value=ball_radius_mm,
            )
        return Setting("ball_radius", ball_radius_mm / scale, "the calibrated ball radius")
    r = 1.0
    why = "placeholder: your probe's calibrated ball radius"
    if smallest is not None and smallest[0] <= r:
        r = smallest[0] / 2
        why += f" (half the concave {smallest[1]}'s radius, so that the ball fits)"
    return Setting("ball_radius", r / scale, why)


def _is_concave(seg, side: int) -> bool:
    """An arc is concave when its outward normal points to its centre: the centre on
    the outward side of travel (`side` +1 left, -1 right); G3 has it on the left."""
    return (1 if seg.ccw else -1) == side


def _relative(program: Path, study_path: Path | None) -> str:
    if study_path is None:
        return program.as_posix()
    try:
        return Path(os.path.relpath(program.resolve(), study_path.resolve().parent)).as_posix()
    except ValueError:  # another drive
        return program.resolve().as_posix()


@dataclass(frozen=True)
class ToolNose:
    """Where `init` takes the finish tool's nose from.

    - `table`, `units`: a LinuxCNC tool table (lengths in ``"mm"`` or ``"in"``) for the
      tool of G41/G42.
    - `radius`, `tip`: for a program **without** G41/G42 (a tool path, as CAM writes
      it): the nose radius (mm) and the point the path is written for, a LinuxCNC
      orientation (1-8 the imaginary tip; 0 or 9 the nose centre). The part contour is
      taken back from the path (`gcode.path_contour`).
    """

    table: object = None
    units: str = "mm"
    radius: float | None = None
    tip: int | None = None

    def __post_init__(self):
        if self.units not in ("mm", "in"):
            raise InputError(f"tool table units: got {self.units!r}, expected 'mm' or 'in'")
        if (self.radius is None) != (self.tip is None):
            raise InputError(
                "a tool path needs both its nose radius and its tip (--nose-radius R --tip T; "
                "tip 0: the nose centre's path)"
            )
        if self.radius is not None and not (
            isinstance(self.radius, int | float) and math.isfinite(self.radius) and self.radius > 0
        ):
            raise InputError(f"nose radius: got {self.radius!r}, expected a number > 0 (mm)")
        if self.tip is not None and self.tip not in range(10):
            raise InputError(f"tip: got {self.tip!r}, expected a LinuxCNC orientation 0-9")


def study_from_program(
    program,
    *,
    study_path=None,
    kind: str | None = None,
    x_mode: str = "diameter",
    tolerance_class: str = "m",
    run: int | None = None,
    nose: ToolNose | None = None,
    ball_radius_mm: float | None = None,
    dialect: str | None = None,
) -> InitResult:
    """The study of a finish program, not written (see the module doc).

    **Arguments:**

    - `program`: the part program's path.
    - `study_path`: where the study will be (its `part_program` is relative to it).
    - `kind`: ``"external"`` / ``"internal"`` to check against the program's
      compensation side (None: the program's side decides).
    - `x_mode`: how the study writes X: ``"diameter"`` or ``"radius"``.
    - `tolerance_class`: ISO 2768-1 class ``"f"``, ``"m"``, ``"c"``, ``"v"``
      (``"ISO2768-m"`` is read too).
    - `run`: which compensation run (1-based) when the program has several (of a tool
      path: which run of cutting moves).
    - `nose`: a [`ToolNose`][]: the tool table for `[program] nose_radius`, or the nose
      radius and tip of a program that is a tool path (no G41/G42).
    - `ball_radius_mm`: the probe's ball radius (else a placeholder).
    - `dialect`: the program's dialect (``"linuxcnc"``, ``"fanuc"``, ``"haas"``,
      ``"okuma"``); None: detected. The study records it (`[program] dialect`).

    **Returns:** an [`InitResult`][] without `path`.

    **Raises:** `InputError` naming the program line for a contour that cannot
    be a study (`gcode.finish_contour`), a `kind` that contradicts G41/G42.
    """
    if x_mode not in ("diameter", "radius"):
        raise InputError(f"x_mode: got {x_mode!r}, expected 'diameter' or 'radius'")
    try:
        iso2768_tolerance(1.0, tolerance_class)
    except ValueError as exc:
        raise InputError(str(exc), value=tolerance_class) from None
    program = Path(program)
    nose = nose or ToolNose()
    read = read_gcode(program, dialect)
    if nose.radius is not None:
        contour = path_contour(read, nose_radius=nose.radius, tip=nose.tip, kind=kind, run=run)
    else:
        contour = finish_contour(read, run=run)
    _check_kind(contour, kind)
    units = contour.units or "mm"
    scale = MM_PER[units]
    xs = scale / 2 if x_mode == "diameter" else scale
    ids = feature_ids(contour, units)
    feats = []
    for seg, (fid, form) in zip(contour.segments, ids, strict=True):
        on, t, why = general_tolerance(seg, form, tolerance_class, units)
        where = f"line {seg.line}" + (f" ({seg.block})" if seg.block else "")
        pt = lambda p: (p[0] / xs, p[1] / scale)  # noqa: E731
        feats.append(
            FeatureText(
                id=fid,
                type=seg.kind,
                start=pt(seg.start),
                end=pt(seg.end),
                tolerance=(-t, t),
                tolerance_on=on,
                center=None if seg.center is None else pt(seg.center),
                direction=None if seg.center is None else ("ccw" if seg.ccw else "cw"),
                comments=(f"{where}: {seg.source}",),
                tolerance_comment=why,
            )
        )
    comp = contour.comp
    side = "left" if contour.side == 1 else "right"
    off = f"G40 at line {contour.off}" if contour.off else "the program's end"
    run_text = f" (run {contour.run} of {contour.runs})" if contour.runs > 1 else ""
    if nose.radius is not None:
        what = (
            f"the part contour under the tool path of lines {contour.lead_in}-{contour.exit} "
            f"(nose radius {nose.radius:g} mm, {_tip_text(nose.tip)})"
        )
        from_text = f"the tool path's side of travel ({comp.code} would make it): the nose {side}"
    else:
        what = f"its finish contour{run_text}: {comp.code} at line {comp.line} to {off}"
        from_text = f"from {comp.code} at line {comp.line}: the nose {side} of travel"
    header = (
        f"piecs_bayes study file (docs/formats.md), written by `piecs-bayes init` from "
        f"{program.name}.",
        f"[profile] is {what};",
        f"the lead-in (line {contour.lead_in}) and the exit (line {contour.exit}) are not "
        "features.",
        f"Tolerances: ISO 2768-{iso2768_tolerance(1.0, tolerance_class).tol_class} general "
        "tolerances by nominal size: replace each with the drawing's.",
        "[probe] and [program] hold placeholders where marked: fill them in before fitting.",
    ) + (() if contour.units else ("The program changes units within the contour: mm.",))
    study_path = None if study_path is None else Path(study_path)
    content = StudyText(
        name=contour.title or program.stem,
        units=units,
        kind=contour.kind,
        x_mode=x_mode,
        features=tuple(feats),
        part_program=_relative(program, study_path),
        header=header,
        study_comments={
            "probe_files": "the gauged parts' probe files (relative to this file; globs allowed)",
            "part_program": "relative to this file",
            "kind": from_text,
            "x_mode": "X of the points below",
        },
        probe=(
            _ball_radius(ids, contour, ball_radius_mm, scale),
            Setting("x_mode", x_mode, "how the probe files write X"),
            Setting("tool", 9, "placeholder: the probe's tool number (for plan)", commented=True),
            Setting(
                "feed",
                200.0 / scale,
                "placeholder: probing feed per minute, the calibration's",
                commented=True,
            ),
        ),
        program=(
            _nose_radius(contour, nose, scale),
            *_path_settings(nose),
            Setting("dialect", read.dialect.name, _dialect_comment(read.dialect)),
        ),
    )
    return InitResult(content, study_toml(content), contour)


def _compare(study, contour: FinishContour, path: Path) -> None:
    """The loaded study's features against the program's moves (mm, radius X)."""
    feats = study.profile.features
    if len(feats) != len(contour.segments):
        raise AnalysisError(f"{path}: {len(feats)} features read back, not {len(contour.segments)}")
    for f, s in zip(feats, contour.segments, strict=True):
        pts = [(f.p0, s.start), (f.p1, s.end)]
        if s.center is not None:
            pts.append((f.center, s.center))
        dev = max(math.dist(a, b) for a, b in pts)
        if dev > _GEOMETRY_TOL_MM or (s.center is not None) != (f.kind == "arc"):
            raise AnalysisError(
                f"{path}: feature {f.id!r} read back {dev:.3g} mm off line {s.line} "
                "(please report it)"
            )


def init_study(program, out, *, force: bool = False, **options) -> InitResult:
    """Write the study of a finish program to `out` (atomically; see the module doc).

    **Arguments:** `program` and `out` (paths), `force` (write over an existing
    `out`; never over the program), and the options of [`study_from_program`][].

    **Returns:** the [`InitResult`][] with `path` and the loaded `study`.

    **Raises:** `InputError` for an existing `out` without `force`, and as
    `study_from_program` does.
    """
    out = Path(out)
    if out.exists() and not out.is_dir() and not force:
        raise InputError("exists; pass --force to write over it", file=str(out))
    result = study_from_program(program, study_path=out, **options)

    def write(tmp):
        Path(tmp).write_text(result.text, encoding="utf-8")
        _compare(load_study(tmp), result.contour, out)  # before it is renamed into place

    write_file_atomic(out, write, protect=[program])
    study = load_study(out)
    return InitResult(result.content, result.text, result.contour, out, study)
