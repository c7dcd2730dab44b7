"""The adjusted program edits blocks that carry a corner (Fanuc ``,C``/``,R``, LinuxCNC's
G7x ``C``/``A``): the block's words program the vertex where its line meets the next, and
the corner word its size. Known answers: the profile moved rigidly, and scaled about a
point (radii and chamfer legs scale, angles stay): the adjusted program, read again, cuts
exactly the moved profile (to its 3 written decimals)."""

from __future__ import annotations

import math
from pathlib import Path

import pytest

from piecs_bayes.errors import AnalysisError
from piecs_bayes.gcode import adjust_program, finish_contour, parse_gcode, read_gcode
from piecs_bayes.geometry import Profile, make_feature

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
FANUC = DATA / "dialects" / "fanuc_chamfer_corner_words.nc"

#: a LinuxCNC G7x contour with a chamfer (C) and a fillet (A), finished by G70 under G42.1
G7X = """G18 G7 G21 G90
o100 sub
  G1 X8 Z0
  G1 X24 C1
  G1 Z-30
  G1 X30 Z-45
  G1 Z-60 A3
  G1 X44
  G1 Z-90
  G0 X60
o100 endsub
G0 X60 Z2
G71 Q100 X60 Z2 D0.2 I1.5 R0.5
G0 X60 Z10
G42.1 D0.8 L2
G70 Q100 X10 Z2
G40
G0 X60 Z50
M2
"""


def _profile(program) -> Profile:
    c = finish_contour(program)
    side = c.side
    feats = [make_feature({"id": f"f{k}", **s.spec}, side) for k, s in enumerate(c.segments)]
    return Profile(tuple(feats))


def _moved(profile: Profile, move) -> Profile:
    feats = []
    for f in profile:
        spec = {"id": f.id, "p0": move(f.p0), "p1": move(f.p1)}
        if f.kind == "arc":
            spec.update(center=move(f.center), ccw=f.ccw)
        feats.append(make_feature(spec, f.side))
    return Profile(tuple(feats))


def _translate(p):
    return (p[0] + 0.004, p[1] - 0.003)


def _scale(p):
    return (p[0] * 1.0005, p[1] * 1.0005)


@pytest.mark.parametrize("move", [_translate, _scale], ids=["translated", "scaled"])
@pytest.mark.parametrize("which", ["fanuc", "linuxcnc"])
def test_corner_blocks_cut_the_moved_profile(which, move):
    program = read_gcode(FANUC) if which == "fanuc" else parse_gcode(G7X, name="g7x.ngc")
    nominal = _profile(program)
    assert sum(1 for f in nominal if f.kind == "arc") == 1  # the R3 fillet (,R3. or A3)
    adjusted = _moved(nominal, move)
    adj = adjust_program(program, nominal, adjusted, max_correction_mm=0.1)
    again = parse_gcode(adj.text, name="adjusted", options=program.options)
    got = _profile(again)
    assert len(got.features) == len(adjusted.features)
    for g, a in zip(got, adjusted, strict=True):
        assert g.kind == a.kind
        assert math.dist(g.p0, a.p0) < 2e-3 and math.dist(g.p1, a.p1) < 2e-3, (g, a)
        if g.kind == "arc":
            assert abs(g.radius - a.radius) < 2e-3
    words = {c.line: c.new for c in adj.changes}
    corner_line = next(ln for ln, t in words.items() if ",R" in t or " A" in t)
    assert words[corner_line] != program.source.line(corner_line).text  # the size changed too


def test_a_corner_next_to_an_arc_is_refused_by_name():
    text = G7X.replace("  G1 Z-30\n", "  G2 X26 Z-30 R40\n")
    program = parse_gcode(text, name="g7x.ngc")
    nominal = _profile(program)
    adjusted = _moved(nominal, _translate)
    with pytest.raises(
        AnalysisError, match=r"g7x.ngc:\d+: the corner of this block is not between"
    ):
        adjust_program(program, nominal, adjusted, max_correction_mm=0.1)
