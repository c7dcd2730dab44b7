"""One route to the machine (`--apply`, `[compensation] apply`), the alternatives
marked, decisions.json's "apply", the default output folder (a slug of the study
name) and "done" as the last console line."""

from __future__ import annotations

import json
import re
import shutil
from pathlib import Path

import pytest

from piecs_bayes.cli import main
from piecs_bayes.cli._common import out_dir, slug
from piecs_bayes.errors import InputError
from piecs_bayes.export.machine import ALTERNATIVE, parse_linuxcnc_comp, read_errspec
from piecs_bayes.io import load_study

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo" / "study.toml"
BATCH = ROOT / "data" / "batch" / "study.toml"

PROGRAM = {"finish_adjusted.ngc", "finish.diff"}
ERRSPEC = {"compensation.errspec.json", "linuxcnc_x.comp", "linuxcnc_z.comp", "linuxcnc_comp.ini"}
OFFSETS = {"tool_offsets.json", "tool_offsets_fanuc.ngc"}
MACHINE = re.compile(r"^(finish_adjusted|finish\.diff|compensation\.|linuxcnc_|tool_offsets)")


def _machine(folder: Path) -> set[str]:
    return {p.name for p in folder.iterdir() if MACHINE.match(p.name)}


def _compensate(tmp_path, capsys, *extra) -> tuple[Path, list[str]]:
    out = tmp_path / "out"
    assert main(["compensate", str(DEMO), "--out", str(out), *extra]) == 0
    return out, capsys.readouterr().out.rstrip("\n").splitlines()


# --------------------------------------------------------------------------- routes


@pytest.mark.parametrize(
    "extra, expected",
    [
        ((), PROGRAM),  # the default: the study names a part program
        (("--apply", "program"), PROGRAM),
        (("--apply", "errspec"), ERRSPEC),
        (("--apply", "tool_offset"), OFFSETS),
        (("--apply", "none"), set()),
    ],
    ids=["default", "program", "errspec", "tool_offset", "none"],
)
def test_the_route_chooses_the_files(tmp_path, capsys, extra, expected):
    out, lines = _compensate(tmp_path, capsys, *extra)
    names = _machine(out)
    assert expected <= names
    others = (PROGRAM | ERRSPEC | OFFSETS) - expected
    assert not names & others, names & others
    if expected & ERRSPEC:  # every table of the native spec, nothing else
        assert {p for p in names if p.endswith(".csv")} == {
            f"compensation.{t.name}.csv"
            for t in read_errspec(out / "compensation.errspec.json").tables
        }
    assert ALTERNATIVE not in "\n".join(lines)
    route = extra[1] if extra else "program"
    assert f"What to load on the machine: route {route!r}" in "\n".join(lines)
    assert "do not combine" in "\n".join(lines)
    assert re.fullmatch(r"\[ *\d+\.\d s\] done", lines[-1]), lines[-1]


def test_alternatives_are_written_only_on_request_and_marked(tmp_path, capsys):
    out, lines = _compensate(tmp_path, capsys, "--apply", "errspec", "--alternatives")
    names = _machine(out)
    assert PROGRAM | ERRSPEC | OFFSETS <= names
    listed = {Path(line.split()[0]).name: line for line in lines if line.startswith(f"  {out}")}
    for name in names:
        alternative = name in PROGRAM | OFFSETS
        assert (ALTERNATIVE in listed[name]) == alternative, listed[name]
        text = (out / name).read_text()
        if alternative:  # in the file's own header
            head = text.splitlines()[:3]
            assert any(ALTERNATIVE in h and "'errspec'" in h for h in head), (name, head)
        else:
            assert ALTERNATIVE not in text, name
    # the marks keep every file readable by its reader
    assert json.loads((out / "tool_offsets.json").read_text())["note"].startswith(ALTERNATIVE)
    prog = (out / "finish_adjusted.ngc").read_text().splitlines()
    assert prog[0] == "%" and prog[1].startswith("O1001") and prog[2].startswith(f"({ALTERNATIVE}")
    assert "(" not in prog[2][1:-1] and ")" not in prog[2][1:-1]
    text = "\n".join(lines)
    assert "files marked 'alternative: do not combine' (program, tool_offset)" in text
    assert lines[-1].endswith("] done")


def test_comp_tables_state_range_end_values_and_every_move(tmp_path, capsys):
    out, _ = _compensate(tmp_path, capsys, "--apply", "errspec")
    for axis in ("x", "z"):
        text = (out / f"linuxcnc_{axis}.comp").read_text()
        comp = parse_linuxcnc_comp(text)
        assert comp.valid, comp.problems  # the notes follow the last entry
        notes = text[text.index("#") :]
        lo, hi = (f"{v:.6f}" for v in comp.nominal[[0, -1]])
        assert f"Range: nominal {lo} to {hi} mm" in notes
        assert "holds the end" in notes and f"the trim at {lo} below it" in notes
        assert "every move of this joint" in notes and "probing" in notes
    ini = (out / "linuxcnc_comp.ini").read_text()
    assert "every move of its joint" in ini and "probing" in ini and "holds the end" in ini
    assert re.search(r"# linuxcnc_x\.comp: table x_radius, range [\d.]+ to [\d.]+ mm", ini)


def test_a_trailing_block_of_notes_is_not_a_problem_but_a_header_is():
    assert parse_linuxcnc_comp("0 0 0\n1 1 1\n# note\n\n# more\n").valid
    comp = parse_linuxcnc_comp("0 0 0\n# note\n1 1 1\n")
    assert not comp.valid and len(comp) == 1


# --------------------------------------------------------------------------- the key


def _study_copy(tmp_path, apply_line: str, *, program: bool = True) -> Path:
    for name in ("probe_part01.csv", "finish.ngc"):
        shutil.copy(DEMO.parent / name, tmp_path / name)
    text = DEMO.read_text().replace("max_correction = 0.1", f"max_correction = 0.1\n{apply_line}")
    if not program:
        text = text.replace('part_program = "finish.ngc"\n', "")
    path = tmp_path / "study.toml"
    path.write_text(text)
    return path


def test_study_key_chooses_the_route(tmp_path, capsys):
    path = _study_copy(tmp_path, 'apply = "tool_offset"')
    assert load_study(path).compensation.apply == "tool_offset"
    out = tmp_path / "o"
    assert main(["compensate", str(path), "--out", str(out), "-q"]) == 0
    assert _machine(out) == OFFSETS
    # the command line wins over the study
    assert main(["compensate", str(path), "--out", str(out / "e"), "-q", "--apply", "none"]) == 0
    assert _machine(out / "e") == set()


def test_bad_apply_value_is_refused_with_key_and_file(tmp_path, capsys):
    path = _study_copy(tmp_path, 'apply = "both"')
    with pytest.raises(InputError, match=r"study\.toml: compensation\.apply: unknown value 'both'"):
        load_study(path)
    assert main(["compensate", str(path), "-q"]) == 2
    err = capsys.readouterr().err
    assert "compensation.apply" in err and str(path) in err and "'tool_offset'" in err
    # "program" needs a part program
    path = _study_copy(tmp_path, 'apply = "program"', program=False)
    assert main(["compensate", str(path), "-q", "--out", str(tmp_path / "x")]) == 2
    err = capsys.readouterr().err
    assert "compensation.apply: 'program', but the study names no part program" in err
    assert str(path) in err
    # a typo in the key itself is refused like every key
    path = _study_copy(tmp_path, 'aply = "program"')
    with pytest.raises(InputError, match="did you mean 'apply'"):
        load_study(path)
    # and a bad --apply is a usage error
    with pytest.raises(SystemExit) as exc:
        main(["compensate", str(DEMO), "--apply", "both"])
    assert exc.value.code == 2
    assert "invalid choice: 'both'" in capsys.readouterr().err


def test_without_a_program_the_default_is_the_error_spec(tmp_path, capsys):
    path = _study_copy(tmp_path, "", program=False)
    out = tmp_path / "o"
    assert main(["compensate", str(path), "--out", str(out)]) == 0
    assert _machine(out) == ERRSPEC | {p for p in _machine(out) if p.endswith(".csv")}
    assert "the default: the study names no part program" in capsys.readouterr().out


# --------------------------------------------------------------------------- output folder


def test_default_output_folder_is_a_slug_of_the_study_name():
    assert slug("Demo stepped shaft") == "demo-stepped-shaft"
    assert slug("Demo shaft batch (tool wear, tool change)") == (
        "demo-shaft-batch-tool-wear-tool-change"
    )
    assert slug("  Über-Welle  Ø24 / Los 7 ") == "uber-welle-24-los-7"
    assert slug("***") == ""

    class Args:
        out = None

    demo, batch = out_dir(Args, load_study(DEMO)), out_dir(Args, load_study(BATCH))
    assert demo == Path("reports/demo-stepped-shaft")
    assert batch == Path("reports/demo-shaft-batch-tool-wear-tool-change")
    Args.out = Path("reports/demo")  # `make demo`'s explicit folder wins
    assert out_dir(Args, load_study(DEMO)) == Path("reports/demo")


# --------------------------------------------------------------------------- demo


def test_demo_writes_one_route_records_it_and_ends_with_done(tmp_path, capsys):
    out = tmp_path / "demo"
    argv = ["demo", str(DEMO), "--out", str(out), "--no-bayes", "--apply", "errspec"]
    assert main(argv) == 0
    lines = capsys.readouterr().out.rstrip("\n").splitlines()
    assert re.fullmatch(r"\[ *\d+\.\d s\] done", lines[-1]), lines[-5:]
    assert sum("done" in line.split("]")[-1].split() for line in lines) == 1
    names = _machine(out)
    assert ERRSPEC <= names and not names & (PROGRAM | OFFSETS)
    doc = json.loads((out / "decisions.json").read_text())
    apply = doc["apply"]
    assert apply["route"] == "errspec" and apply["why"] == "chosen with --apply"
    assert set(apply["files"]) == names and apply["alternatives"] == []
    assert (out / "report.html").is_file()
    text = "\n".join(lines)
    assert "What to load on the machine: route 'errspec'" in text
    assert "main job finished" in text and "drawing the report" in text


def test_error_spec_as_an_alternative_still_reads_back(tmp_path, capsys):
    out, _ = _compensate(tmp_path, capsys, "--apply", "program", "--alternatives")
    spec = read_errspec(out / "compensation.errspec.json")
    assert spec.description.startswith(f"{ALTERNATIVE} with the route chosen, 'program'")
    text = (out / "linuxcnc_x.comp").read_text()
    assert parse_linuxcnc_comp(text).valid and f"# {ALTERNATIVE}" in text
    assert (out / "linuxcnc_comp.ini").read_text().startswith(f"# {ALTERNATIVE}")
    assert ALTERNATIVE not in (out / "finish_adjusted.ngc").read_text()
