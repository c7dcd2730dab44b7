"""The lathe programs LinuxCNC ships, read by us and by LinuxCNC's ``rs274``: the same moves.

linuxcnc-uspace installs them under /usr/share/linuxcnc/ncfiles (``lathe*.ngc``,
``macros/lathe/*.ngc``, ``ngcgui_lib/lathe/*.ngc``). They are read there at test time,
never copied (their licence is not ours). A macro (a subroutine file) is run by a small
wrapper written here: a start position, the subroutine's text, a call with arguments,
``M2``. Every move (end point, arc centre, straight or arc) must equal ``rs274 -g``'s
canonical STRAIGHT_TRAVERSE / STRAIGHT_FEED / ARC_FEED to 1e-4 in the program's units
(rs274 prints 4 decimals). The programs the reader does not run yet are listed in
``NOT_READ`` with the reason, and the test checks that the reader refuses each by name.
"""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.gcode import compensated_path, parse_gcode, rs274_path, run_rs274

NC = Path("/usr/share/linuxcnc/ncfiles")
GLOBS = ("lathe*.ngc", "macros/lathe/*.ngc", "ngcgui_lib/lathe/*.ngc")
# rs274 asks the tool table for every tool an M6 loads: tools 1-10, zero diameter (so that
# G41/G42 leave the path as programmed) and zero length
TOOLS = "".join(f"T{t} P{t} D0 Z0 Q{t % 9 + 1}\n" for t in range(1, 11))
_STD = "ngcgui_lib/lathe/lathe_std.ngc"  # ngcgui's lathe preamble (g20, g64 p#<tol>, ...)

#: program -> how it runs: None (as it stands), or (preamble, arguments of its sub's call)
RUN: dict[str, tuple[str, list[float]] | None] = {
    "lathe_pawn.ngc": None,
    "lathe_g70_71_demo.ngc": None,  # G71.1, G71.2 and G70 (two passes) under G42.1
    "lathe_g7x_face_boring.ngc": None,  # G72 and G70 in a subroutine, a repeat in the contour
    "lathe_g7x_quadrants.ngc": None,  # G70/G71/G72 in the four quadrants
    "lathe-g76.ngc": None,  # G76 threads (read as moves, never a contour)
    # x, surface speed, tool, pitch, z, internal, external
    "macros/lathe/threading.ngc": ("G18 G21 G7\nG0 X30 Z2\n", [20, 100, 1, 1.5, -20, 0, 1]),
    "lathecomp.ngc": None,
    # finish diameter, surface speed, depth of cut, feed/rev, length, radius, angle, tool
    "macros/lathe/boring.ngc": ("G18 G21 G7\nG0 X10 Z2\n", [20, 100, 1, 0.1, -20, 2, 0, 1]),
    # ... and the maximum rpm
    "macros/lathe/turning.ngc": (
        "G18 G21 G7\nG0 X30 Z2\n",
        [20, 100, 1, 0.1, -20, 2, 0, 1, 1500],
    ),
    # x, speed, doc, z, tool, size, front outside, front inside, back outside, max rpm
    "macros/lathe/chamfer.ngc": ("G18 G21 G7\nG0 X30 Z2\n", [20, 100, 0.5, 0, 1, 2, 1, 0, 0, 1500]),
    # x, speed, doc, -, z, tool, -, radius, front outside, front inside, back outside
    "macros/lathe/radius.ngc": ("G18 G21 G7\nG0 X30 Z2\n", [20, 100, 0.5, 0, 0, 1, 0, 2, 1, 0, 0]),
    # face diameter, speed, doc, feed/rev, z length, angle, tool, max rpm
    "macros/lathe/facing.ngc": ("G18 G21 G7\nG0 X40 Z2\n", [30, 100, 0.5, 0.1, -2, 0, 1, 1500]),
    # the ngcgui subroutines with their documented defaults, after ngcgui's preamble (inch)
    "ngcgui_lib/lathe/id.ngc": (
        "<std>G0 X0.4 Z0.2\n",
        [0.5, 0.625, 0.010, 0, 0.100, -0.600, 80, 2, 1500, 8, 8],
    ),
    "ngcgui_lib/lathe/od.ngc": (
        "<std>G0 X0.3 Z0.2\n",
        [0.260, 0.180, 0.010, 0, 100, 2, 1500, -0.5, 0.100, 6, 6, 8],
    ),
    "ngcgui_lib/lathe/taper-od.ngc": ("<std>G0 X1.2 Z0.2\n", [3000, 100, 2, 0, -2, 1, 10, 6, 8]),
    _STD: None,  # a preamble: no move (M2 added, which rs274 wants at the end)
    # diameter, depth, surface speed, feed/rev, tool, peck, retract: G83 on the axis in G17
    "macros/lathe/drill.ngc": ("G18 G21 G7\nG0 X0 Z2\n", [10, -20, 100, 0.1, 1, 3, 1]),
    # x, y, z: a mill macro (G17, a Y move)
    "macros/lathe/go_to_position.ngc": ("G18 G20 G7\nG0 X1 Z0.1\n", [1, 2, 3]),
    # max radius, fast feed, slow feed, -, probe diameter: G38.2/G38.3 along X, Y and Z
    "macros/lathe/probe-hole.ngc": ("G18 G20 G7\nG0 X1 Z0.1\n", [0.5, 10, 1, 0, 0.1]),
}
#: more runs of the macros: the other branches (inch input, the chamfer's and radius's
#: front-inside and back-outside forms)
MORE: dict[str, tuple[str, str, list[float]]] = {
    "boring-inch": ("macros/lathe/boring.ngc", "G18 G20 G7\nG0 X0.4 Z0.1\n",
                    [0.8, 300, 0.04, 0.004, -0.8, 0.08, 0, 1]),
    "turning-inch": ("macros/lathe/turning.ngc", "G18 G20 G7\nG0 X1.2 Z0.1\n",
                     [0.8, 300, 0.04, 0.004, -0.8, 0.08, 0, 1, 1500]),
    "chamfer-front-inside": ("macros/lathe/chamfer.ngc", "G18 G21 G7\nG0 X10 Z2\n",
                             [20, 100, 0.5, 0, 1, 2, 0, 1, 0, 1500]),
    "chamfer-back-outside": ("macros/lathe/chamfer.ngc", "G18 G21 G7\nG0 X30 Z-2\n",
                             [20, 100, 0.5, -5, 1, 2, 0, 0, 1, 1500]),
    "radius-front-inside": ("macros/lathe/radius.ngc", "G18 G21 G7\nG0 X10 Z2\n",
                            [20, 100, 0.5, 0, 0, 1, 0, 2, 0, 1, 0]),
    "radius-back-outside": ("macros/lathe/radius.ngc", "G18 G21 G7\nG0 X30 Z-2\n",
                            [20, 100, 0.5, 0, -5, 1, 0, 2, 0, 0, 1]),
    "facing-no-pass": ("macros/lathe/facing.ngc", "G18 G21 G7\nG0 X40 Z-1.9\n",
                       [30, 100, 0.5, 0.1, -2, 0, 1, 1500]),
    "threading-internal": ("macros/lathe/threading.ngc", "G18 G21 G7\nG0 X10 Z2\n",
                           [20, 100, 1, 1.5, -20, 1, 0]),
    "threading-inch": ("macros/lathe/threading.ngc", "G18 G20 G7\nG0 X1.2 Z0.1\n",
                       [0.75, 300, 1, 0.05, -0.8, 0, 1]),
    "drill-inch": ("macros/lathe/drill.ngc", "G18 G20 G7\nG0 X0 Z0.1\n",
                   [0.4, -0.8, 300, 0.004, 1, 0.1, 0.05]),
    "drill-below-r": ("macros/lathe/drill.ngc", "G18 G21 G7\nG0 X0 Z-1\n",
                      [10, -7, 100, 0.1, 1, 2, 1]),
    "go-to-position-metric": ("macros/lathe/go_to_position.ngc", "G18 G21 G8\nG0 X1 Z2\n",
                              [-5, 7.5, 12]),
}  # fmt: skip
#: programs not read yet, with the reason and what the refusal says
NOT_READ: dict[str, tuple[str, str]] = {
    "ngcgui_lib/lathe/g76base.ngc": (
        "G76 threading, after o<loadtool> (a subroutine in another file)",
        "subroutines in other files are not read",
    ),
    "ngcgui_lib/lathe/g76diam.ngc": (
        "G76 threading (through o<g76base>, a subroutine in another file)",
        "subroutines in other files are not read",
    ),
}
#: the documented defaults of the ngcgui G76 subroutines (their early checks exit on others)
NOT_READ_ARGS = {
    "ngcgui_lib/lathe/g76base.ngc": [10, 200, 0.5, -0.5, 0.125, -1.0, -0.03, 0.05, 0.015,
                                     1.0, 29.5, 0, 0.05, 2, 3, 8, 0],
    "ngcgui_lib/lathe/g76diam.ngc": [10, 200, -0.03, -0.5, -8, -1.0, 0.94, 0.84, 0.015,
                                     1.0, 29.5, 0, 0.05, 2, 3, 8, 0],
}  # fmt: skip

pytestmark = [
    pytest.mark.rs274,
    pytest.mark.skipif(not NC.is_dir(), reason=f"{NC} is absent (install linuxcnc-uspace)"),
]


def _installed() -> list[str]:
    if not NC.is_dir():
        return []
    return sorted({p.relative_to(NC).as_posix() for g in GLOBS for p in NC.glob(g)})


def _wrapper(rel: str, preamble: str, args: list[float]) -> str:
    """The macro's subroutine (its text from ``o<name> sub`` to ``endsub``) after a
    preamble, called with ``args``."""
    lines = (NC / rel).read_text().splitlines()
    start = next(i for i, ln in enumerate(lines) if re.search(r"(?i)o<[^>]+>\s*sub\b", ln))
    end = next(i for i, ln in enumerate(lines) if re.search(r"(?i)o<[^>]+>\s*endsub", ln))
    name = re.search(r"(?i)o(<[^>]+>)", lines[start]).group(1)
    preamble = preamble.replace("<std>", (NC / _STD).read_text())
    body = "\n".join(lines[start : end + 1])
    return f"{preamble}{body}\no{name} call {' '.join(f'[{a}]' for a in args)}\nM2\n"


def _text(rel: str) -> str:
    how = RUN[rel]
    if how is None:
        text = (NC / rel).read_text()
        return text + "M2\n" if rel == _STD else text
    return _wrapper(rel, *how)


def _g70_quirk(program) -> set[int]:
    """The first two moves of a G70 under G41.1/G42.1 (they carry a diameter): the rs274
    that Debian ships (2.9.0~pre1) compensates the rapid to the cycle's start point and
    the move after it as no other move (LinuxCNC fixed it in July 2024: the moves to the
    start point are made uncompensated, the contour's lead-in enters compensation, as
    the reader does). Their ends are not compared; everything after them is."""
    out: set[int] = set()
    moves = program.moves
    for k, m in enumerate(moves):
        if m.via != "G70" or (k and moves[k - 1].line == m.line):
            continue
        same = [n for n in moves[k:] if n.line == m.line]
        if any(n.comp is not None and n.comp.diameter_mm for n in same):
            out |= {k, k + 1}
    return out


def _same_moves(text: str, name: str) -> int:
    program = parse_gcode(text, name=name)
    ref = run_rs274(text, tool_table=TOOLS)
    assert ref.error is None, ref.error
    ours = program.moves
    if any(m.comp is not None and m.comp.diameter_mm for m in ours):
        ours = compensated_path(program)  # G41.1/G42.1 carry their diameter
    skip = _g70_quirk(program)
    assert len(ours) == len(ref.moves), (len(ours), len(ref.moves))
    for k, (a, b) in enumerate(zip(ours, ref.moves, strict=True)):
        unit = 25.4 if program.state(a.line).units == "in" else 1.0
        where = f"move {k + 1} (line {a.line})"
        if k in skip:
            continue
        assert (a.kind in ("cw", "ccw")) == (b.kind == "arc"), where
        probe = b.kind == "probe" and a.kind == "feed" and a.via.startswith("G38")
        assert a.kind == b.kind or b.kind == "arc" or probe, where
        assert max(abs(u - v) for u, v in zip(a.end, b.end, strict=True)) / unit <= 1e-4 + 1e-9
        ay = getattr(a, "y", None)  # a PathMove (compensated) is in the XZ plane
        assert abs((ay[1] if ay else 0.0) - b.y) / unit <= 1e-4 + 1e-9, where
        if b.kind == "arc":
            assert math.dist(a.center, b.center) / unit <= 1.5e-4, where
            assert b.rotation == (1 if a.kind == "ccw" else -1), where
    return len(ours)


def test_every_installed_lathe_program_is_listed():
    installed = _installed()
    if not installed:
        pytest.skip(f"{NC} holds no lathe programs")
    assert sorted(set(installed) - set(RUN) - set(NOT_READ)) == []


@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("rel", sorted(RUN))
def test_the_reader_moves_as_rs274(rel):
    if not (NC / rel).is_file():
        pytest.skip(f"{rel} is not installed")
    n = _same_moves(_text(rel), rel)
    assert n > 0 or rel == _STD


@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("case", sorted(MORE))
def test_the_macros_other_branches_move_as_rs274(case):
    rel, preamble, args = MORE[case]
    if not (NC / rel).is_file():
        pytest.skip(f"{rel} is not installed")
    assert _same_moves(_wrapper(rel, preamble, args), case) > 0


@pytest.mark.parametrize("rel", sorted(NOT_READ))
def test_what_is_not_read_yet_is_refused_by_name(rel):
    """Not compared with rs274 (listed here, with the reason): refused naming the code."""
    if not (NC / rel).is_file():
        pytest.skip(f"{rel} is not installed")
    why, message = NOT_READ[rel]
    text = (NC / rel).read_text()
    if re.search(r"(?i)o<[^>]+>\s*sub\b", text):  # a macro: run its subroutine
        args = NOT_READ_ARGS.get(rel, [1.0] * 10)
        text = _wrapper(rel, "G18 G20 G7\nG0 X1 Z0.1\n", args)
    with pytest.raises(InputError) as exc:
        parse_gcode(text, name=rel)
    assert message in str(exc.value), (why, str(exc.value))
    assert exc.value.line is not None


# ------------------------------------------------------------------ the command line and init
#: what `init` makes of each program read: its study's number of features (with `--run`
#: where the program has several compensated runs), or why it has no finish contour
NO_COMP = "no nose compensation (G41/G42)"
FEATURES_G76 = 2  # the two arcs of its rounded end
INIT: dict[str, list[tuple[int | None, int]] | str] = {
    "lathe_g70_71_demo.ngc": [(None, 18)],  # the pawn: G70's contour under G42.1
    "lathecomp.ngc": [(1, 4), (2, 5)],  # two runs: G42, then G41
    "lathe-g76.ngc": [(8, FEATURES_G76)],  # its end rounded under G41 in a loop of 8 passes
    "ngcgui_lib/lathe/taper-od.ngc": [(None, 3)],
    **dict.fromkeys(
        (
            "lathe_g7x_face_boring.ngc", "lathe_g7x_quadrants.ngc", "lathe_pawn.ngc",
            "macros/lathe/threading.ngc", "macros/lathe/drill.ngc",
            "macros/lathe/go_to_position.ngc", "macros/lathe/probe-hole.ngc",
            "macros/lathe/boring.ngc", "macros/lathe/chamfer.ngc", "macros/lathe/facing.ngc",
            "macros/lathe/radius.ngc", "macros/lathe/turning.ngc", "ngcgui_lib/lathe/id.ngc",
            "ngcgui_lib/lathe/od.ngc", _STD,
        ),
        NO_COMP,
    ),
}  # fmt: skip


def test_every_program_read_has_its_init_entry():
    assert sorted(INIT) == sorted(RUN)


def _as_file(tmp_path, rel) -> Path:
    path = tmp_path / rel.replace("/", "_")
    path.write_text(_text(rel))
    return path


@pytest.mark.parametrize("rel", sorted(RUN))
def test_init_makes_a_study_from_every_finish_contour(rel, tmp_path, capsys):
    """A study from every program with a finish contour (G41/G42 in it); the others are
    refused saying there is no nose compensation, in one line."""
    from piecs_bayes.cli import main

    if not (NC / rel).is_file():
        pytest.skip(f"{rel} is not installed")
    path = _as_file(tmp_path, rel)
    want = INIT[rel]
    if isinstance(want, str):
        assert main(["init", str(path), "--out", str(tmp_path / "s.toml"), "-q"]) == 2
        err = capsys.readouterr().err.strip()
        assert want in err and len(err.splitlines()) == 1, err
        return
    for run, features in want:
        out = tmp_path / f"s{run}.toml"
        argv = ["init", str(path), "--out", str(out), "-q", *(["--run", str(run)] if run else [])]
        assert main(argv) == 0, capsys.readouterr().err
        assert out.read_text().count("[[profile.feature]]") == features


@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("rel", sorted(RUN))
def test_gcode_check_rs274_agrees_on_every_program(rel, tmp_path, capsys, monkeypatch):
    """`gcode check --rs274` on each program as a user runs it (the tool table giving
    tools 1-10): rs274 agrees."""
    from piecs_bayes.cli import main

    if not (NC / rel).is_file():
        pytest.skip(f"{rel} is not installed")
    monkeypatch.setenv("HOME", str(tmp_path))
    path = _as_file(tmp_path, rel)
    (tmp_path / "tools.tbl").write_text(TOOLS)
    argv = ["gcode", "check", str(path), "--rs274", "--tool-table", str(tmp_path / "tools.tbl")]
    rc = main(argv)
    out = capsys.readouterr().out
    assert rc == 0 and "rs274 agrees" in out, out[-800:]


#: the programs rs274 refuses too (what each says), run as `test_what_is_not_read_yet...`
BOTH_REFUSE = {
    "ngcgui_lib/lathe/g76base.ngc": "seeking o-word: o<loadtool>",
    "ngcgui_lib/lathe/g76diam.ngc": "seeking o-word: o<g76base>",
}


@pytest.mark.skipif(rs274_path() is None, reason="LinuxCNC's rs274 is not installed")
@pytest.mark.parametrize("rel", sorted(BOTH_REFUSE))
def test_rs274_refuses_them_too(rel, tmp_path, monkeypatch):
    """The subroutines in other files: rs274 alone (no subroutine path) refuses them too."""
    if not (NC / rel).is_file():
        pytest.skip(f"{rel} is not installed")
    monkeypatch.setenv("HOME", str(tmp_path))
    text = _wrapper(rel, "G18 G20 G7\nG0 X1 Z0.1\n", NOT_READ_ARGS[rel])
    res = run_rs274(text, tool_table=TOOLS)
    assert res.error is not None and BOTH_REFUSE[rel] in res.error
