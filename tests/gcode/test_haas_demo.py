"""The demo shaft as a Haas program with a G71/G70 P/Q contour (issue 38): the same study
as data/demo/finish.ngc (geometry to 1e-9), the same adjusted contour, and an adjusted
program that differs from the original only in the contour blocks' coordinate words."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from piecs_bayes.gcode import adjust_program, finish_contour, parse_gcode, read_gcode
from piecs_bayes.geometry import Profile, make_feature
from piecs_bayes.io import load_study
from piecs_bayes.jobs import study_from_program

ROOT = Path(__file__).resolve().parents[2]
HAAS = ROOT / "tests" / "data" / "gcode" / "dialects" / "haas_demo_shaft.nc"
DEMO = ROOT / "data" / "demo" / "finish.ngc"
COORDS = set("XZIKRUW")


def _study(program: Path, tmp: Path):
    res = study_from_program(program, study_path=tmp / f"{program.stem}.toml")
    (tmp / f"{program.stem}.toml").write_text(res.text)
    return load_study(tmp / f"{program.stem}.toml")


def test_same_study_as_the_linuxcnc_demo(tmp_path):
    haas, demo = _study(HAAS, tmp_path), _study(DEMO, tmp_path)
    assert haas.profile.ids == demo.profile.ids
    for a, b in zip(haas.profile, demo.profile, strict=True):
        assert a.kind == b.kind and a.side == b.side and a.tolerance == b.tolerance
        assert math.dist(a.p0, b.p0) <= 1e-9 and math.dist(a.p1, b.p1) <= 1e-9
        if a.kind == "arc":
            assert math.dist(a.center, b.center) <= 1e-9 and a.ccw == b.ccw


def _profile(program) -> Profile:
    c = finish_contour(program)
    feats = [make_feature({"id": f"f{k}", **s.spec}, c.side) for k, s in enumerate(c.segments)]
    return Profile(tuple(feats))


def _adjusted(profile: Profile) -> Profile:
    """The profile scaled by 1.0004 about (x 0, z -45) and moved 3 um outward in x: every
    end point and centre moves a few micrometres, radii grow, angles stay."""

    def move(p):
        return (p[0] * 1.0004 + 0.003, -45.0 + (p[1] + 45.0) * 1.0004)

    feats = []
    for f in profile:
        spec = {"id": f.id, "p0": move(f.p0), "p1": move(f.p1)}
        if f.kind == "arc":
            spec.update(center=move(f.center), ccw=f.ccw)
        feats.append(make_feature(spec, f.side))
    return Profile(tuple(feats))


@pytest.mark.parametrize("check", ["contour", "words"])
def test_same_adjusted_contour_and_only_contour_words_change(check):
    results = {}
    for path in (HAAS, DEMO):
        program = read_gcode(path)
        nominal = _profile(program)
        adj = adjust_program(program, nominal, _adjusted(nominal), max_correction_mm=0.1)
        again = parse_gcode(adj.text, name=path.name, options=program.options)
        results[path] = (program, adj, finish_contour(again))
    if check == "contour":
        a, b = results[HAAS][2].segments, results[DEMO][2].segments
        assert len(a) == len(b)
        for s, t in zip(a, b, strict=True):
            assert s.kind == t.kind
            assert math.dist(s.start, t.start) <= 1e-9 and math.dist(s.end, t.end) <= 1e-9
        return
    program, adj, _ = results[HAAS]
    contour = finish_contour(program)
    blocks = {contour.lead_in, contour.exit, *(s.line for s in contour.segments)}
    old = program.text.splitlines()
    new = adj.text.splitlines()[adj.header_lines :]
    assert len(old) == len(new)
    changed = [k + 1 for k, (a, b) in enumerate(zip(old, new, strict=True)) if a != b]
    assert changed and set(changed) <= blocks, changed
    source = parse_gcode(adj.text, name="adjusted", options=program.options).source
    for ln in changed:
        before, after = program.source.line(ln), source.line(ln + adj.header_lines)
        kept = [(w.letter, w.text) for w in before.words if w.letter not in COORDS]
        assert kept == [(w.letter, w.text) for w in after.words if w.letter not in COORDS]
        assert [c.text for c in before.comments] == [c.text for c in after.comments]
