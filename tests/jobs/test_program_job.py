"""The adjusted finish-cut program of a study (PIECS option 2), its traceability
comment block and diff, and the tool its wear-offset update targets (issue 15)."""

import hashlib
import json
import re
import shutil
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType

import pytest

from piecs_bayes import __version__
from piecs_bayes.cli import main
from piecs_bayes.errors import InputError
from piecs_bayes.export.machine import g10_fanuc, write_compensation_outputs
from piecs_bayes.gcode import parse_gcode, read_gcode
from piecs_bayes.io import load_study
from piecs_bayes.jobs import (
    JobOptions,
    adjust_study_program,
    compensate_study,
    fit_study,
    machine_data,
    run_job,
    tool_offsets,
)

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo"
WORD = re.compile(r"([A-Z])([-+]?\d*\.?\d+)")


def _words(line: str):
    code = re.sub(r"\(.*?\)", "", line)
    return [(m.group(1), m.group(2)) for m in WORD.finditer(code)]


def test_adjusted_demo_program_changes_only_finish_cut_coordinates(tmp_path):
    out = tmp_path / "finish_adjusted.ngc"
    rc = main(
        [
            "compensate",
            str(DEMO / "study.toml"),
            "--out",
            str(tmp_path),
            "--quiet",
            "--program-out",
            str(out),
        ]
    )
    assert rc == 0
    before = (DEMO / "finish.ngc").read_text().splitlines(keepends=True)
    after = out.read_text().splitlines(keepends=True)
    # the comment block tracing the run follows "%" and the O-number line
    n = next(k for k, line in enumerate(after[2:]) if not line.startswith("("))
    assert after[:2] == before[:2] and after[2].startswith("(piecs_bayes ")
    after = after[:2] + after[2 + n :]
    assert len(before) == len(after)
    changed = [i for i, (a, b) in enumerate(zip(before, after, strict=True)) if a != b]
    finish = {i for i, line in enumerate(before) if re.match(r"N(5|6|7|8|9|10|11|12)0 ", line)}
    assert changed and set(changed) <= finish  # only the finish-cut blocks N50..N120
    for i in changed:
        wa, wb = _words(before[i]), _words(after[i])
        assert [w for w, _ in wa] == [w for w, _ in wb]  # same words, same order
        for (w, va), (_, vb) in zip(wa, wb, strict=True):
            if w not in "XZIKR":
                assert va == vb, (before[i], after[i])
            else:
                assert len(va.split(".")[-1]) == len(vb.split(".")[-1])  # number format kept
                assert abs(float(va) - float(vb)) < 0.1
        assert re.sub(WORD, "", before[i]) == re.sub(WORD, "", after[i])  # comments, spacing kept
    diff = (tmp_path / "finish_adjusted.ngc.diff").read_text()
    assert diff.startswith("--- a/") and diff.count("\n-N") == len(changed)
    source = (DEMO / "finish.ngc").as_posix().lstrip("/")
    target = (tmp_path / "finish_adjusted.ngc").as_posix().lstrip("/")
    assert diff.splitlines()[:2] == [f"--- a/{source}", f"+++ b/{target}"]  # as written
    # the 24 mm diameter is fitted ~21.6 um oversize in radius: mirrored to X23.95x
    n70 = next(line for line in after if line.startswith("N70 "))
    assert 23.950 <= float(_words(n70)[2][1]) <= 23.965


def test_program_out_never_overwrites_the_input_and_refuses_large_corrections(tmp_path, capsys):
    for name in ("study.toml", "probe_part01.csv", "finish.ngc"):
        shutil.copy(DEMO / name, tmp_path / name)
    original = (tmp_path / "finish.ngc").read_bytes()
    rc = main(
        [
            "compensate",
            str(tmp_path / "study.toml"),
            "--out",
            str(tmp_path / "o"),
            "--quiet",
            "--program-out",
            str(tmp_path / "finish.ngc"),
        ]
    )
    assert rc == 2 and "refusing to overwrite an input file" in capsys.readouterr().err
    assert (tmp_path / "finish.ngc").read_bytes() == original
    text = (
        (tmp_path / "study.toml")
        .read_text()
        .replace("max_correction = 0.1", "max_correction = 0.005")
    )
    (tmp_path / "study.toml").write_text(text)
    rc = main(
        [
            "compensate",
            str(tmp_path / "study.toml"),
            "--out",
            str(tmp_path / "o2"),
            "--quiet",
            "--program-out",
            str(tmp_path / "new.ngc"),
        ]
    )
    assert (
        rc == 1
        and "more than the configured maximum correction 0.005 mm" in capsys.readouterr().err
    )
    assert not (tmp_path / "new.ngc").exists()


@pytest.fixture(scope="module")
def demo():
    study = load_study(DEMO / "study.toml")
    return study, fit_study(study)


def _sha(path) -> str:
    return hashlib.sha256(Path(path).read_bytes()).hexdigest()


GAINS = {"face_end": 0.0, "dia_24": 0.5, "taper": 1.0, "dia_30": 1.0, "fillet": 1.0}
GAINS |= {"shoulder": 1.0, "dia_44": 1.0}
CREATED = "2026-01-02T03:04:05+00:00"


def test_adjusted_program_starts_with_a_block_that_traces_its_run(demo):
    study, fit = demo
    adj = adjust_study_program(study, compensate_study(study, fit, gain=GAINS), created=CREATED)
    lines = adj.text.splitlines()
    original = study.program.read_text().splitlines()
    assert lines[:2] == original[:2] == ["%", "O1001 (DEMO SHAFT FINISH CUT)"]
    assert lines[2 : 2 + adj.header_lines] == [
        f"(piecs_bayes {__version__} adjusted finish cut: only coordinate words changed)",
        f"(date {CREATED})",
        f"(study study.toml sha256 {_sha(study.path)})",
        f"(probe probe_part01.csv sha256 {_sha(DEMO / 'probe_part01.csv')})",
        "(gains face_end 0, dia_24 0.5, taper 1, dia_30 1, fillet 1)",
        "(gains shoulder 1, dia_44 1)",
    ]
    # only comment lines are added: every other line as before, or a rewritten block
    n = adj.header_lines
    body = lines[:2] + lines[2 + n :]
    changed = {c.line for c in adj.changes}
    assert changed and len(body) == len(original)
    for k, (a, b) in enumerate(zip(original, body, strict=True), start=1):
        assert (a == b) == (k not in changed), (k, a, b)
    # and the program moves as the unadjusted one, apart from the changed coordinates
    before, after = read_gcode(study.program).moves, parse_gcode(adj.text).moves
    assert [(m.kind, m.line + n) for m in before] == [(m.kind, m.line) for m in after]
    for a, b in zip(before, after, strict=True):
        assert (a.comp is None) == (b.comp is None)
        if a.line in changed:
            assert 0 < max(abs(a.end[0] - b.end[0]), abs(a.end[1] - b.end[1])) < 0.1
        else:  # (it starts where the block before it now ends)
            assert (a.end, a.center) == (b.end, b.center)
    # the diff names the input program and the adjusted one
    head = adj.diff.splitlines()[:2]
    assert head == [f"--- a/{study.program.as_posix().lstrip('/')}", "+++ b/finish_adjusted.ngc"]
    named = adjust_study_program(
        study, compensate_study(study, fit), created=CREATED, output="reports/demo/new.ngc"
    )
    assert named.diff.splitlines()[1] == "+++ b/reports/demo/new.ngc"


def test_the_job_dates_the_program_with_its_run(tmp_path):
    res = run_job(
        DEMO / "study.toml", JobOptions(bayes=False, uncertainty=False, capability=False),
        progress=False,
    )  # fmt: skip
    assert res.created and f"(date {res.created})" in res.program.text.splitlines()
    assert f"sha256 {_sha(DEMO / 'study.toml')}" in res.program.text


def test_tool_offsets_target_the_programs_finish_tool(demo, tmp_path):
    study, fit = demo
    upd, notes = tool_offsets(study, fit)
    assert (upd.tool, upd.offset) == (2, 2)  # N20 T0202: tool 2, wear offset 2
    assert notes[0] == (
        f"tool 2, wear offset 2: from the T word T0202 on line 4 of {study.program} "
        "(in force on the finish-cut lines 8-14)"
    )
    cur = MappingProxyType({"current_x": 0.1, "current_z": -2.5, "current_r": 0.4})
    with_cur = replace(study, offsets=cur)
    write_compensation_outputs(with_cur, machine_data(with_cur, fit), tmp_path)
    doc = json.loads((tmp_path / "tool_offsets.json").read_text())
    assert (doc["tool"], doc["offset"]) == (2, 2) and "T0202 on line 4" in doc["tool_source"]
    fanuc = (tmp_path / "tool_offsets_fanuc.ngc").read_text()
    assert fanuc.startswith("(piecs-bayes Fanuc wear update T0202: tool 2, wear offset 2, X as")
    assert "\nG10 P2 X" in fanuc
    linuxcnc = (tmp_path / "tool_offsets_linuxcnc.ngc").read_text()
    assert linuxcnc.startswith("(piecs-bayes LinuxCNC wear update T2,")
    assert "\nG10 L1 P2 X" in linuxcnc and "(tool from the T word T0202 on line 4" in linuxcnc
    # T0211: tool 2 with wear offset 11; the study may name the tool when it matches
    prog = tmp_path / "t0211.ngc"
    prog.write_text(study.program.read_text().replace("T0202", "T0211"))
    named = replace(study, program=prog, offsets=MappingProxyType({"tool": 2}))
    upd, notes = tool_offsets(named, fit)
    assert (upd.tool, upd.offset) == (2, 11) and "named by [offsets] tool" in notes[0]
    assert "\nG10 P11 U" in g10_fanuc(upd)


def _program(tmp_path, name, old, new, study):
    p = tmp_path / name
    p.write_text(study.program.read_text().replace(old, new))
    return p


def test_a_tool_that_does_not_match_the_program_is_refused(demo, tmp_path, capsys):
    study, fit = demo
    with pytest.raises(InputError) as err:
        tool_offsets(replace(study, offsets=MappingProxyType({"tool": 3})), fit)
    assert (err.value.file, err.value.line) == (str(study.program), 4)
    assert str(err.value) == (
        f"{study.program}:4: [offsets] tool = 3 in {study.path} does not match the part "
        "program: its finish cut is made with tool 2 (T0202, wear offset 2)"
    )
    # through the CLI: bad input, exit code 2, nothing about T1 or T3 written
    for name in ("study.toml", "probe_part01.csv", "finish.ngc"):
        shutil.copy(DEMO / name, tmp_path / name)
    text = (tmp_path / "study.toml").read_text()
    text = text.replace("[offsets]\n", "[offsets]\ntool = 3\n", 1)
    if "tool = 3" not in text:
        text += "\n[offsets]\ntool = 3\n"
    (tmp_path / "study.toml").write_text(text)
    argv = ["compensate", str(tmp_path / "study.toml"), "--out", str(tmp_path / "o"), "-q"]
    rc = main([*argv, "--apply", "tool_offset"])
    assert rc == 2 and "tool = 3" in capsys.readouterr().err
    assert not (tmp_path / "o" / "tool_offsets_fanuc.ngc").exists()


def test_several_finish_tools_need_the_study_to_name_one(demo, tmp_path):
    study, fit = demo
    prog = _program(tmp_path, "two.ngc", "N70 G1", "N65 T0303\nN70 G1", study)
    two = replace(study, program=prog)
    with pytest.raises(InputError, match="several tools cut the finish-cut blocks") as err:
        tool_offsets(two, fit)
    assert "T0202 (line 4: tool 2, wear offset 2), T0303 (line 9: tool 3" in str(err.value)
    assert err.value.file == str(study.path)
    upd, notes = tool_offsets(replace(two, offsets=MappingProxyType({"tool": 3})), fit)
    assert (upd.tool, upd.offset) == (3, 3) and "T0303 on line 9" in notes[0]
    # offsets cancelled on the finish cut (T0200): a wear update would not act
    prog = _program(tmp_path, "t0200.ngc", "T0202", "T0200", study)
    with pytest.raises(InputError, match="wear offset cancelled"):
        tool_offsets(replace(study, program=prog), fit)


def test_without_a_program_the_study_names_the_tool(demo, tmp_path):
    study, fit = demo
    upd, notes = tool_offsets(replace(study, program=None), fit)
    assert (upd.tool, upd.offset) == (1, 1)
    assert notes[0] == (
        "tool 1, wear offset 1: from the default [offsets] tool = 1 (the study names no "
        "part program)"
    )
    five = replace(study, program=None, offsets=MappingProxyType({"tool": 5}))
    upd, notes = tool_offsets(five, fit)
    assert upd.tool == 5 and f"[offsets] tool = 5 in {study.path}" in notes[0]
    assert upd.source == notes[0].split("from ", 1)[1]
    # a program that calls no tool before its finish cut: the study's tool, said
    prog = _program(tmp_path, "bare.ngc", "N20 T0202 (FINISH TOOL R0.4)", "N20", study)
    upd, notes = tool_offsets(replace(study, program=prog), fit)
    assert upd.tool == 1 and "calls no tool before its finish cut" in notes[0]
