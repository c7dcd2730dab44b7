"""`init`: a study from the finish program (jobs.init_study, gcode.finish_contour,
geometry.iso2768_tolerance, io.study_toml)."""

from __future__ import annotations

import math
import tomllib
from pathlib import Path

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import (
    compensation_runs,
    finish_contour,
    map_blocks_to_profile,
    parse_gcode,
    read_gcode,
    read_tool_table,
)
from piecs_bayes.geometry import drawn_limits, iso2768_tolerance
from piecs_bayes.io import load_study, toml_number
from piecs_bayes.jobs import ToolNose, init_study, study_from_program

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo"
GCODE = ROOT / "tests" / "data" / "gcode"
CORPUS = sorted(GCODE.glob("*.ngc")) + sorted((GCODE / "adjust").glob("*.ngc"))
TOL = 1e-9

#: corpus programs that cannot be a study as they stand, and why
REFUSED = {
    "05_face_mm_t5_g41.ngc": "encloses no area with the spindle axis (a lone face)",
    "12_two_runs_tool_change.ngc": "2 compensated runs (run 1: lines 6-11 (G42); run 2: lines 17-22 (G41))",
    "15_arc_entry_t3.ngc": "2 compensated runs",
    "16_rapid_in_comp_t3.ngc": "a rapid (G0) inside the compensated contour",
    "18_tapers_both_sides.ngc": "2 compensated runs",
    "27_all_orientations_both_sides.ngc": "18 compensated runs (run 1: lines 6-12 (G42.1);",
}

# -------------------------------------------------------------------------- helpers


def _close(a, b, tol=TOL) -> bool:
    return math.dist(a, b) <= tol


def _assert_features_are_the_moves(study, contour, program):
    """Every feature is its move: same type, end points and exact centre (mm, radius)."""
    feats = study.profile.features
    assert len(feats) == len(contour.segments)
    for f, s in zip(feats, contour.segments, strict=True):
        move = next(m for m in program.moves if m.line == s.line)
        assert f.kind == ("arc" if move.is_arc else "line")
        assert _close(f.p0, move.start) and _close(f.p1, move.end), (f.id, s.line)
        if move.is_arc:
            assert _close(f.center, move.exact_center()) and f.ccw == move.ccw


def _assert_round_trip(program_path, out, **options):
    r = init_study(program_path, out, **options)
    program = read_gcode(program_path)
    study = load_study(out)
    _assert_features_are_the_moves(study, r.contour, program)
    if r.contour.runs > 1:  # map_blocks_to_profile maps every run's blocks: one run only
        return r, study
    mapped = map_blocks_to_profile(program, study.profile, tol_mm=1e-6)
    for seg, f in zip(r.contour.segments, study.profile.features, strict=True):
        assert mapped.lines[seg.line] == f.id, (program_path.name, seg.line)
    assert set(mapped.connecting) >= {r.contour.lead_in, r.contour.exit}
    assert study.program == program_path.resolve() or study.program.resolve() == (
        program_path.resolve()
    )
    return r, study


def _program(tmp_path, text, name="p.ngc") -> Path:
    p = tmp_path / name
    p.write_text(text)
    return p


# -------------------------------------------------------------------------- the demo


def test_demo_gives_every_feature_of_the_demo_study(tmp_path):
    r = init_study(DEMO / "finish.ngc", tmp_path / "study.toml")
    ours, demo = load_study(tmp_path / "study.toml"), load_study(DEMO / "study.toml")
    assert len(ours.profile) == len(demo.profile) == 7
    for a, b in zip(ours.profile.features, demo.profile.features, strict=True):
        assert a.kind == b.kind and a.tolerance_on == b.tolerance_on, (a.id, b.id)
        assert _close(a.p0, b.p0) and _close(a.p1, b.p1), (a.id, b.id)
        if b.kind == "arc":
            assert _close(a.center, b.center) and a.ccw == b.ccw
        assert a.side == b.side
    written = tomllib.loads(r.text)["profile"]
    declared = tomllib.loads((DEMO / "study.toml").read_text())["profile"]
    assert (written["kind"], written["x_mode"]) == (declared["kind"], declared["x_mode"])
    assert ours.profile.ids == (
        "face_z0", "dia_24", "taper_1", "dia_30", "arc_1", "face_z60", "dia_44",
    )  # fmt: skip
    assert r.contour.lead_in == 7 and r.contour.exit == 15  # N50, N130 G1 X48
    assert [s.block for s in r.contour.segments] == [f"N{n}" for n in range(60, 130, 10)]
    assert "# line 9 (N70): G1 X24.000 Z-30.000\n[[profile.feature]]" in r.text
    assert ours.program.resolve() == (DEMO / "finish.ngc").resolve()
    assert ours.probe_files == () and ours.units == "mm"
    assert ours.name == "DEMO SHAFT FINISH CUT"


def test_demo_tolerances_are_the_iso_values_as_drawn(tmp_path):
    init_study(DEMO / "finish.ngc", tmp_path / "s.toml")
    study = load_study(tmp_path / "s.toml")
    drawn = {f.id: drawn_limits(f) for f in study.profile}
    assert drawn["dia_24"] == pytest.approx((-0.2, 0.2))  # Ø24: >6-30, on the diameter
    assert study.profile["dia_24"].tolerance == pytest.approx((-0.1, 0.1))  # on the radius
    assert drawn["face_z0"] == pytest.approx((-0.1, 0.1))  # 0.5-3 (at least 0.5 mm)
    assert drawn["face_z60"] == pytest.approx((-0.3, 0.3))  # Z-60: >30-120
    assert drawn["dia_44"] == pytest.approx((-0.3, 0.3))
    assert drawn["taper_1"] == pytest.approx((-0.2, 0.2))  # 15.3 mm long
    assert drawn["arc_1"] == pytest.approx((-0.2, 0.2))  # R3: Table 2, 0.5-3
    text = (tmp_path / "s.toml").read_text()
    assert "# ISO 2768-m general tolerance for Ø24 mm: replace with the drawing's" in text
    init_study(DEMO / "finish.ngc", tmp_path / "f.toml", tolerance_class="ISO2768-f")
    fine = load_study(tmp_path / "f.toml")
    assert drawn_limits(fine.profile["dia_44"]) == pytest.approx((-0.15, 0.15))


# -------------------------------------------------------------------------- the corpus


@pytest.mark.parametrize("path", CORPUS, ids=[p.name for p in CORPUS])
def test_corpus_round_trip_or_refusal(tmp_path, path):
    if path.name in REFUSED:
        with pytest.raises(InputError) as exc:
            init_study(path, tmp_path / "s.toml")
        assert REFUSED[path.name] in str(exc.value) and path.name in str(exc.value)
        assert not (tmp_path / "s.toml").exists()
        return
    _assert_round_trip(path, tmp_path / "s.toml")


@pytest.mark.parametrize("name", ["12_two_runs_tool_change.ngc", "15_arc_entry_t3.ngc",
                                  "18_tapers_both_sides.ngc", "27_all_orientations_both_sides.ngc"])  # fmt: skip
def test_each_run_of_a_program_with_several(tmp_path, name):
    path = GCODE / name
    runs = compensation_runs(read_gcode(path))
    for k in range(1, len(runs) + 1):
        r, study = _assert_round_trip(path, tmp_path / f"run{k}.toml", run=k)
        assert r.contour.run == k and r.contour.lead_in == runs[k - 1][0].line
        assert f"(run {k} of {len(runs)})" in r.text
    with pytest.raises(InputError, match=f"the program has {len(runs)} compensated run"):
        study_from_program(path, run=len(runs) + 1)


def test_inch_program_gives_an_inch_study_with_the_same_geometry(tmp_path):
    r, study = _assert_round_trip(GCODE / "adjust" / "stepped_shaft_inch.ngc", tmp_path / "i.toml")
    assert study.units == "in" and 'units = "in"' in r.text
    assert "start = [0.94488, 0.0]" in r.text and "center = [1.41732, -2.24409]" in r.text
    assert "dia_0p94488" in study.profile.ids
    # tolerances in inches: Ø24 mm (0.94488 in) in class m is ±0.2 mm
    assert drawn_limits(study.profile["dia_0p94488"]) == pytest.approx((-0.2, 0.2))
    mm = load_study(init_study(GCODE / "adjust" / "stepped_shaft.ngc", tmp_path / "m.toml").path)
    for f in study.profile:  # the same contour to the inch program's 5 decimals
        other = mm.profile[f.id.replace("0p94488", "24").replace("1p1811", "30")
                           .replace("2p3622", "60").replace("1p73228", "44")]  # fmt: skip
        if f.id != "dia_0p94488":  # the mm program splits this diameter in two
            assert _close(f.p0, other.p0, 2e-3) and _close(f.p1, other.p1, 2e-3), f.id


def test_incremental_and_radius_mode_programs(tmp_path):
    _, g91 = _assert_round_trip(GCODE / "adjust" / "stepped_shaft_g91.ngc", tmp_path / "a.toml")
    _, absolute = _assert_round_trip(GCODE / "adjust" / "stepped_shaft.ngc", tmp_path / "b.toml")
    for f in g91.profile:
        if f.id != "dia_24":  # split in two in the absolute program
            g = absolute.profile[f.id]
            assert _close(f.p0, g.p0) and _close(f.p1, g.p1), f.id
    # G8 (radius words) and G7 (diameter words) of the same contour: the same study
    _, rad = _assert_round_trip(GCODE / "02_od_rad_mm_t2_g42_ik.ngc", tmp_path / "r.toml")
    _, dia = _assert_round_trip(GCODE / "01_od_dia_mm_t3_g42.ngc", tmp_path / "d.toml")
    assert rad.profile.ids == dia.profile.ids
    for f, g in zip(rad.profile, dia.profile, strict=True):
        assert _close(f.p0, g.p0) and _close(f.p1, g.p1) and f.tolerance == g.tolerance


def test_x_mode_radius_writes_radii(tmp_path):
    r = init_study(DEMO / "finish.ngc", tmp_path / "r.toml", x_mode="radius")
    assert 'x_mode = "radius"' in r.text and "start = [12.0, 0.0]" in r.text
    demo = load_study(DEMO / "study.toml")
    for a, b in zip(r.study.profile, demo.profile, strict=True):
        assert _close(a.p0, b.p0) and _close(a.p1, b.p1)


def test_internal_program_gives_a_bore_study(tmp_path):
    r, study = _assert_round_trip(GCODE / "04_bore_mm_t4_g41.ngc", tmp_path / "b.toml")
    assert r.contour.kind == "internal" and 'kind = "internal"' in r.text
    assert study.profile.ids == (
        "taper_1", "taper_2", "bore_20", "arc_1", "face_z20", "bore_16", "taper_3",
    )  # fmt: skip
    # a bore's diameter tolerance as drawn: more material is a smaller diameter
    assert drawn_limits(study.profile["bore_20"]) == pytest.approx((-0.2, 0.2))
    # G42 toward the face is a bore too
    r8, _ = _assert_round_trip(GCODE / "08_bore_toward_face_t8_g42.ngc", tmp_path / "8.toml")
    assert r8.contour.kind == "internal"


def test_kind_that_contradicts_g41_g42_is_refused(tmp_path):
    with pytest.raises(InputError) as exc:
        study_from_program(DEMO / "finish.ngc", kind="internal")
    msg = str(exc.value)
    assert "finish.ngc:7" in msg and "G42 (line 7) puts the tool nose right of travel" in msg
    assert "cut into the part" in msg and "--kind external" in msg
    assert study_from_program(DEMO / "finish.ngc", kind="external").contour.kind == "external"
    with pytest.raises(InputError, match="G41 \\(line 6\\).*use G42, or --kind internal"):
        study_from_program(GCODE / "04_bore_mm_t4_g41.ngc", kind="external")


# -------------------------------------------------------------------------- refusals

_HEAD = "G18 G21 G7 G90 G95\nT3 M6\nG0 X50 Z5\n"
_LEAD = "G42 G1 X20 Z1 F0.1\n"
_TAIL = "G1 X40 Z-20\nG40 G0 X50 Z5\nM30\n"

REFUSALS = [
    ("no_comp", _HEAD + "G1 X20 Z1 F0.1\nG1 Z-20\n" + "G1 X40\nM30\n", 4,
     "no nose compensation (G41/G42) in the program: the path is the tool's, not the part's"),
    ("rapid", _HEAD + _LEAD + "G1 Z-10\nG0 Z-20\n" + _TAIL, 6, "a rapid (G0) inside the compensated contour"),
    ("thread_g33", _HEAD + _LEAD + "G33 Z-10 K1.5\n" + _TAIL, 5, "G33: threading is not understood"),
    ("thread_g33_1", _HEAD + _LEAD + "G33.1 Z-10 K1.5\n" + _TAIL, 5, "G33.1: threading"),
    ("thread_g76", _HEAD + _LEAD + "G76 P1.5 Z-20 I-1 J0.1 K1\n" + "G1 Z-20\n" + _TAIL, 5, "Cannot use G76 threading cycle with cutter radius compensation on"),
    ("thread_g32", _HEAD + _LEAD + "G32 Z-10 F1.5\n" + _TAIL, 5, "G32: threading"),
    ("non_planar", _HEAD + _LEAD + "G1 Y2 Z-10\n" + _TAIL, 5, "a Y move with nose compensation on: a profile is in the XZ plane"),
    ("no_feature", _HEAD + _LEAD + "G1 X40 Z-20\nG40 G0 X50\nM30\n", 4, "has no feature between its lead-in (line 4) and its exit (line 5)"),
    ("only_zero_length", _HEAD + _LEAD + "G1 X20 Z1\n" + _TAIL, 4, "only zero-length moves"),
    # (no M30 between the runs: the control stops there, and so does the reader)
    ("two_runs", _HEAD + _LEAD + "G1 Z-10\n" + _TAIL[:-4] + _LEAD + "G1 Z-5\n" + _TAIL, None,
     "2 compensated runs (run 1: lines 4-6 (G42); run 2: lines 8-10 (G42)): choose the finish contour with --run N"),
    ("lone_face", _HEAD + "G42 G1 X50 Z0 F0.1\nG1 X10 Z0\nG1 X8 Z-1\nG40 G0 X50 Z5\nM30\n", 5, "a lone face"),
    ("full_circle", _HEAD + _LEAD + "G1 Z-5\nG2 X20 Z-5 I2 K0\n" + _TAIL, 6, "a full-circle arc"),
]  # fmt: skip


@pytest.mark.parametrize("case", REFUSALS, ids=[c[0] for c in REFUSALS])
def test_each_refusal_names_the_line_and_why(tmp_path, case):
    name, text, line, message = case
    path = _program(tmp_path, text, f"{name}.ngc")
    with pytest.raises(InputError) as exc:
        init_study(path, tmp_path / "s.toml")
    assert message in str(exc.value), str(exc.value)
    assert exc.value.file == str(path) and exc.value.line == line, str(exc.value)
    assert not (tmp_path / "s.toml").exists()


def test_zero_length_moves_are_skipped_and_ids_are_unique(tmp_path):
    text = (
        "G18 G21 G7 G90 G95\nG0 X30 Z5\nG42 G1 X20 Z2 F0.1\n"
        "G1 Z2\n"  # zero length: no feature
        "G1 X24.5 Z2\nG1 Z-10\nG1 X30\nG1 Z-20\nG1 X24.5\nG1 Z-30\nG1 X30 Z-32\n"
        "G1 X40\nG40 G0 X50\nM30\n"
    )
    r, study = _assert_round_trip(_program(tmp_path, text), tmp_path / "s.toml")
    assert study.profile.ids == (
        "face_zp2", "dia_24p5", "face_z10", "dia_30", "face_z20", "dia_24p5_2", "taper_1",
    )  # fmt: skip
    assert [s.line for s in r.contour.segments] == [5, 6, 7, 8, 9, 10, 11]


def test_force_and_no_overwrite(tmp_path):
    out = tmp_path / "study.toml"
    out.write_bytes(b"# mine\r\n\xff")
    before = out.read_bytes()
    with pytest.raises(InputError, match="exists; pass --force to write over it"):
        init_study(DEMO / "finish.ngc", out)
    assert out.read_bytes() == before
    init_study(DEMO / "finish.ngc", out, force=True)
    assert load_study(out).profile.ids[0] == "face_z0"
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    # never over the program, even with force
    prog = tmp_path / "finish.ngc"
    prog.write_bytes((DEMO / "finish.ngc").read_bytes())
    with pytest.raises(InputError, match="refusing to overwrite an input file"):
        init_study(prog, prog, force=True)
    assert prog.read_bytes() == (DEMO / "finish.ngc").read_bytes()
    # a refused program leaves the existing study as it was
    bad = _program(tmp_path, "G18 G21 G7\nG0 X10 Z1\nG1 X20 Z0 F1\nM30\n", "bad.ngc")
    kept = out.read_bytes()
    with pytest.raises(InputError, match="no nose compensation"):
        init_study(bad, out, force=True)
    assert out.read_bytes() == kept


def test_nose_radius_and_ball_radius(tmp_path):
    # G42.1 carries the diameter
    r = init_study(GCODE / "25_od_g42_1_dl.ngc", tmp_path / "a.toml")
    assert r.study.program_settings.nose_radius == pytest.approx(0.4)
    # G42 with the tool table (inches): tool 3's radius
    r = init_study(GCODE / "01_od_dia_mm_t3_g42.ngc", tmp_path / "b.toml",
                   nose=ToolNose(table=GCODE / "tools.tbl", units="in"))  # fmt: skip
    tools = read_tool_table(GCODE / "tools.tbl", units="in")
    assert r.study.program_settings.nose_radius == pytest.approx(tools[3].radius_mm, abs=1e-12)
    # none known: a commented placeholder
    r = init_study(DEMO / "finish.ngc", tmp_path / "c.toml")
    assert r.study.program_settings.nose_radius is None and "# nose_radius = 0.4" in r.text
    # a concave R1 fillet: the placeholder ball fits, a given larger ball is refused
    r = init_study(GCODE / "01_od_dia_mm_t3_g42.ngc", tmp_path / "d.toml")
    assert r.study.probe.ball_radius == pytest.approx(0.5)
    with pytest.raises(InputError, match="not larger than the probe ball radius"):
        init_study(GCODE / "01_od_dia_mm_t3_g42.ngc", tmp_path / "e.toml", ball_radius_mm=1.0)
    r = init_study(DEMO / "finish.ngc", tmp_path / "f.toml", ball_radius_mm=0.75)
    assert r.study.probe.ball_radius == 0.75


def test_contour_of_a_program_text():
    program = parse_gcode((DEMO / "finish.ngc").read_text(), name="finish.ngc")
    c = finish_contour(program)
    assert (c.comp.code, c.side, c.kind, c.off, c.units) == ("G42", -1, "external", 16, "mm")
    assert [s.kind for s in c.segments].count("arc") == 1
    arc = c.segments[4]
    assert arc.center == (18.0, -57.0) and not arc.ccw and arc.radius == 3.0


# -------------------------------------------------------------------------- ISO 2768, numbers


@pytest.mark.parametrize(
    "size, cls, table, value, note",
    [
        (24, "m", "linear", 0.2, None),
        (3.0, "m", "linear", 0.1, None),  # 3 is in 0.5-3
        (3.0001, "c", "linear", 0.3, None),
        (0.5, "f", "linear", 0.05, None),
        (0.2, "m", "linear", 0.1, "below 0.5 mm"),
        (2.0, "v", "linear", 0.5, "ISO 2768-v gives none for 2 mm"),
        (2500, "f", "linear", 0.5, "ISO 2768-f gives none for 2500 mm"),
        (4000, "m", "linear", 2.0, None),
        (5000, "c", "linear", 4.0, "gives none for 5000 mm"),
        (3, "m", "radius", 0.2, None),
        (4, "c", "radius", 1.0, None),
        (100, "v", "radius", 2.0, None),
        (0.3, "f", "radius", 0.2, "below 0.5 mm"),
        (60, "ISO2768-c", "linear", 0.8, None),
    ],
)
def test_iso2768_tables(size, cls, table, value, note):
    t = iso2768_tolerance(size, cls, table=table)
    assert t.value == value and t.limits == (-value, value)
    assert (t.note is None) if note is None else (note in t.note), t.note


def test_iso2768_refuses_unknown_classes():
    with pytest.raises(ValueError, match="ISO2768-f, ISO2768-m"):
        iso2768_tolerance(10, "x")
    with pytest.raises(ValueError, match="finite number >= 0"):
        iso2768_tolerance(float("nan"))


def test_numbers_are_written_to_round_trip():
    for v in (24.0, -30.0, 0.94488, 1 / 3, 0.2 / 25.4, 1e-7, -0.0, 123456.789, 2 / 7 * 1e3):
        assert abs(float(toml_number(v)) - v) <= 1e-12 * max(1.0, abs(v))
    assert toml_number(24.0) == "24.0" and toml_number(-0.0) == "0.0"
    assert toml_number(0.94488) == "0.94488"
