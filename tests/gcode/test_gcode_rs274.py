"""Peer agreement with LinuxCNC's standalone interpreter ``rs274`` (``make conformance``).

For every corpus program: the canonical moves rs274 makes from our
``nose-comp`` output equal the ones it makes with compensation on the
original, to the 4 decimals it prints (1e-4 mm; 1e-4 in for inch programs),
and so does our float64 compensated path. The gouge programs make rs274 stop
on the block where we raise. The ``--corner extend`` outputs run cleanly.

rs274 reads the tool table in inches (``tests/data/gcode/tools.tbl``).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from _corpus_sides import corpus_kind

from piecs_bayes.errors import AnalysisError
from piecs_bayes.gcode import (
    compensated_path,
    nose_compensate,
    read_gcode,
    read_tool_table,
    rs274_path,
    run_rs274,
)

DATA = Path(__file__).resolve().parents[1] / "data" / "gcode"
TABLE = DATA / "tools.tbl"
CORPUS = sorted(DATA.glob("*.ngc"))
GOUGES = sorted((DATA / "gouge").glob("*.ngc"))

pytestmark = [
    pytest.mark.rs274,
    pytest.mark.skipif(
        rs274_path() is None,
        reason="LinuxCNC's rs274 is not installed (make conformance installs linuxcnc-uspace)",
    ),
]


@pytest.fixture(scope="module")
def tools():
    return read_tool_table(TABLE, units="in")


def _tolerance(program) -> float:
    """One unit of rs274's last printed digit, in mm, plus float slack."""
    inch = any(st.units == "in" for st in program.states)
    return (25.4e-4 if inch else 1e-4) + 1e-9


def _compare(ref, got, tol):
    assert len(ref) == len(got), f"{len(ref)} canonical moves vs {len(got)}"
    worst = 0.0
    for k, (a, b) in enumerate(zip(ref, got, strict=True)):
        assert a.kind == b.kind and a.rotation == b.rotation, (k, a, b)
        dev = np.max(np.abs(np.subtract(a.end, b.end)))
        if a.center is not None:
            dev = max(dev, np.max(np.abs(np.subtract(a.center, b.center))))
        assert dev <= tol, (k, a, b, dev)
        worst = max(worst, float(dev))
    return worst


@pytest.mark.parametrize("path", CORPUS, ids=lambda p: p.name)
def test_nose_comp_output_matches_rs274(path, tools):
    program = read_gcode(path)
    reference = run_rs274(path, tool_table=TABLE)
    assert reference.error is None, reference.error
    result = nose_compensate(program, tool_table=tools, kind=corpus_kind(path))
    ours = run_rs274(result.text, tool_table=TABLE)
    assert ours.error is None, ours.error
    _compare(reference.moves, ours.moves, _tolerance(program))


@pytest.mark.parametrize("path", CORPUS, ids=lambda p: p.name)
def test_compensated_path_matches_rs274(path, tools):
    """Our float64 path, rounded as rs274 prints it, is rs274's canon."""
    program = read_gcode(path)
    reference = run_rs274(path, tool_table=TABLE)
    moves = compensated_path(program, tool_table=tools)
    half = _tolerance(program) / 2 + 1e-9
    assert len(moves) == len(reference.moves)
    for m, a in zip(moves, reference.moves, strict=True):
        assert np.max(np.abs(np.subtract(m.end, a.end))) <= half, (m, a)
        assert (a.kind == "arc") == m.is_arc
        if m.is_arc:
            assert np.max(np.abs(np.subtract(m.center, a.center))) <= half
            assert a.rotation == (1 if m.kind == "ccw" else -1)


# what our message says for each gouge program (the wording is ours, not rs274's)
GOUGE_WORDS = {
    "g01": "must end farther than the nose radius",
    "g02": "concave corner",
    "g03": "not larger than the nose radius",
    "g04": "concave corner",
    "g05": "must end farther than the nose radius",
    "g06": "concave corner",
    "g07": "concave corner",
}


@pytest.mark.parametrize("path", GOUGES, ids=lambda p: p.name)
def test_gouges_raise_where_linuxcnc_raises(path, tools):
    reference = run_rs274(path, tool_table=TABLE)
    assert reference.error is not None and reference.returncode != 0
    with pytest.raises(AnalysisError) as exc:
        nose_compensate(read_gcode(path), tool_table=tools)
    # rs274 prints its message and then the offending block: the one we name
    block = read_gcode(path).source.line(exc.value.line).text.strip()
    assert reference.error.splitlines()[-1].strip() == block
    assert f":{exc.value.line}: " in str(exc.value)
    assert GOUGE_WORDS[path.name[:3]] in str(exc.value)


@pytest.mark.parametrize("path", CORPUS, ids=lambda p: p.name)
def test_extend_outputs_run_in_rs274(path, tools):
    program = read_gcode(path)
    try:
        result = nose_compensate(program, tool_table=tools, corner="extend", kind=corpus_kind(path))
    except AnalysisError as exc:
        assert "straight entry" in str(exc)  # the extend rule wants a straight entry move
        return
    ours = run_rs274(result.text, tool_table=TABLE)
    assert ours.error is None, ours.error
    half = _tolerance(program) / 2 + 1e-9
    assert len(ours.moves) == len(result.path)
    for m, a in zip(result.path, ours.moves, strict=True):
        assert np.max(np.abs(np.subtract(m.end, a.end))) <= half


def test_a_program_with_both_faults_names_the_side_first(tools):
    """G42 on the material side and a gouge further on: rs274 judges gouges only and
    stops at the corner; we name the side, the fault a machinist must fix first (on
    the other side every concave corner is convex and the gouge is another one)."""
    from piecs_bayes.errors import InputError

    path = DATA / "faults" / "side_and_gouge.ngc"
    reference = run_rs274(path, tool_table=TABLE)
    assert reference.error is not None
    with pytest.raises(InputError) as exc:
        nose_compensate(read_gcode(path), tool_table=tools)
    assert "material side" in str(exc.value) and "G42 (line 6)" in str(exc.value)
