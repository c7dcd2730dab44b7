"""Programs without nose compensation (CAM output: the tool's path): the part contour taken
back from the path (`path_contour`, `init --nose-radius R --tip T`) and the adjusted path
(`adjust_path_program`).

Known answers: the path of data/demo/finish.ngc compensated by our own `nose_compensate`
(nose radius 0.4 mm, tips 0, 1, 2 and 6; written with 6 decimals, as CAM systems write)
gives the demo's contour back, the first feature's start and the last one's end excepted
(where the nose comes onto the part and leaves it is the path's lead-in's and exit's
choice). For a profile moved by known amounts, the adjusted path is the compensated path
of the demo program moved by the same amounts.
"""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from piecs_bayes.cli import main
from piecs_bayes.errors import InputError
from piecs_bayes.gcode import (
    ToolPath,
    adjust_path_program,
    adjust_program,
    finish_contour,
    nose_compensate,
    parse_gcode,
    path_contour,
    read_gcode,
)
from piecs_bayes.geometry import Profile, make_feature
from piecs_bayes.io import load_study

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "finish.ngc"
R = 0.4


def _compensated(tip: int) -> str:
    """finish.ngc with G42.1 D0.8 L<tip> (tip 0: G42 with the nose radius), resolved."""
    text = DEMO.read_text()
    if tip:
        text = text.replace("G42 G1", f"G42.1 D{2 * R:g} L{tip} G1")
    return nose_compensate(parse_gcode(text, name="finish.ngc"), nose_radius=R).text


def _profile(contour) -> Profile:
    feats = [make_feature({"id": f"f{k}", **s.spec}, contour.side)
             for k, s in enumerate(contour.segments)]  # fmt: skip
    return Profile(tuple(feats))


@pytest.mark.parametrize("tip", [0, 1, 2, 6])
def test_the_demo_contour_from_its_path(tip):
    path = parse_gcode(_compensated(tip), name="cam.ngc")
    got = path_contour(path, nose_radius=R, tip=tip, kind="external" if tip == 0 else None)
    want = finish_contour(read_gcode(DEMO))
    assert got.kind == "external" and len(got.segments) == len(want.segments) == 7
    last = len(want.segments) - 1
    for k, (a, b) in enumerate(zip(got.segments, want.segments, strict=True)):
        assert a.kind == b.kind
        if k:
            assert math.dist(a.start, b.start) < 2e-6, (k, a, b)
        if k < last:
            assert math.dist(a.end, b.end) < 2e-6, (k, a, b)
        if a.kind == "arc":
            assert math.dist(a.center, b.center) < 2e-6 and a.ccw == b.ccw
    assert got.comp.diameter_mm == 2 * R and got.comp.orientation == tip


def _moved(profile: Profile) -> Profile:
    def move(p):
        return (p[0] * 1.0004 + 0.003, -45.0 + (p[1] + 45.0) * 1.0004)

    feats = []
    for f in profile:
        spec = {"id": f.id, "p0": move(f.p0), "p1": move(f.p1)}
        if f.kind == "arc":
            spec.update(center=move(f.center), ccw=f.ccw)
        feats.append(make_feature(spec, f.side))
    return Profile(tuple(feats))


def test_the_adjusted_path_is_the_compensated_path_of_the_adjusted_contour():
    tip = 2
    path = parse_gcode(_compensated(tip), name="cam.ngc")
    nominal = _profile(path_contour(path, nose_radius=R, tip=tip))
    adj = adjust_path_program(path, nominal, _moved(nominal),
                              tool_path=ToolPath(R, tip), max_correction_mm=0.1)  # fmt: skip
    moved = parse_gcode(adj.text, name="adjusted")
    # the same correction made to the compensated program, then compensated
    comp = parse_gcode(DEMO.read_text().replace("G42 G1", f"G42.1 D{2 * R:g} L{tip} G1"))
    cnom = _profile(finish_contour(comp))
    cadj = adjust_program(comp, cnom, _moved(cnom), max_correction_mm=0.1)
    want = nose_compensate(parse_gcode(cadj.text, name="c"), nose_radius=R)
    ours = [m for m in moved.moves if m.kind != "rapid"]
    ref = [m for m in want.path if m.kind != "rapid"]
    assert len(ours) == len(ref)
    for a, b in list(zip(ours, ref, strict=True))[1:-2]:  # the lead-in and exit: their own
        assert math.dist(a.end, b.end) < 2e-3, (a, b)
    assert adj.changes and all(c.shift_mm < 0.05 for c in adj.changes)


def test_refusals_say_what_to_give(tmp_path):
    cam = tmp_path / "cam.ngc"
    cam.write_text(_compensated(0))
    with pytest.raises(InputError, match="--nose-radius R --tip T"):
        finish_contour(read_gcode(cam))
    with pytest.raises(InputError, match="--kind external or internal"):
        path_contour(read_gcode(cam), nose_radius=R, tip=0)
    with pytest.raises(InputError, match="has nose compensation"):
        path_contour(read_gcode(DEMO), nose_radius=R, tip=2)


def test_init_from_a_tool_path(tmp_path, capsys):
    cam = tmp_path / "cam.ngc"
    cam.write_text(_compensated(2))
    out = tmp_path / "study.toml"
    argv = ["init", str(cam), "--out", str(out), "--nose-radius", "0.4", "--tip", "2", "-q"]
    assert main(argv) == 0, capsys.readouterr().err
    study = load_study(out)
    assert study.program_settings.path_tip == 2
    assert study.program_settings.nose_radius == pytest.approx(R)
    assert len(study.profile.features) == 7
    assert main(["init", str(cam), "--out", str(tmp_path / "b.toml"), "--tip", "2"]) == 2
    assert "nose radius and its tip" in capsys.readouterr().err
