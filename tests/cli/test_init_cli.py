"""``piecs-bayes init PROGRAM --out STUDY``: output, exit codes, --force, options."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

from helpers import run_cli as _run

from piecs_bayes.io import load_study

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo"
GCODE = ROOT / "tests" / "data" / "gcode"


def test_init_writes_a_study_that_loads(capsys, tmp_path):
    out = tmp_path / "work" / "study.toml"
    rc, text = _run(capsys, ["init", DEMO / "finish.ngc", "--out", out])
    assert rc == 0, text
    assert "external: 7 features (lead-in line 7 and exit line 15 are not features)" in text
    assert "dia_24         line line 9    G1 X24.000 Z-30.000" in text
    study = load_study(out)
    assert study.program.resolve() == (DEMO / "finish.ngc").resolve()
    rel = os.path.relpath(DEMO / "finish.ngc", out.parent)
    assert f'part_program = "{Path(rel).as_posix()}"' in out.read_text()


def test_force_and_no_overwrite(capsys, tmp_path):
    out = tmp_path / "study.toml"
    out.write_text("# the engineer's own study\n")
    before = out.read_bytes()
    rc, text = _run(capsys, ["init", DEMO / "finish.ngc", "--out", out])
    assert rc == 2 and f"{out}: exists; pass --force to write over it" in text, text
    assert len(text.strip().splitlines()) == 1 and out.read_bytes() == before
    rc, text = _run(capsys, ["init", DEMO / "finish.ngc", "--out", out, "--force", "-q"])
    assert rc == 0 and text == "", text
    assert load_study(out).profile.ids[1] == "dia_24"
    # the program itself, even with --force
    prog = tmp_path / "finish.ngc"
    prog.write_bytes((DEMO / "finish.ngc").read_bytes())
    rc, text = _run(capsys, ["init", prog, "--out", prog, "--force"])
    assert rc == 2 and "refusing to overwrite an input file" in text
    assert prog.read_bytes() == (DEMO / "finish.ngc").read_bytes()


def test_options(capsys, tmp_path):
    out = tmp_path / "s.toml"
    argv = ["init", GCODE / "12_two_runs_tool_change.ngc", "--out", out]
    rc, text = _run(capsys, argv)
    assert rc == 2 and "2 compensated runs" in text and "--run N" in text, text
    assert "12_two_runs_tool_change.ngc: " in text
    rc, text = _run(capsys, [*argv, "--run", "2", "--x-mode", "radius",
                             "--tolerance-class", "ISO2768-c"])  # fmt: skip
    assert rc == 0, text
    body = out.read_text()
    assert 'x_mode = "radius"' in body and "ISO 2768-c general tolerance" in body
    assert "G41 at line 17" in body
    rc, text = _run(capsys, [*argv, "--run", "0"])
    assert rc == 2 and "expected an integer >= 1" in text
    rc, text = _run(capsys, ["init", DEMO / "finish.ngc", "--out", tmp_path / "x.toml",
                             "--tolerance-class", "ISO2768-q"])  # fmt: skip
    assert rc == 2 and "expected one of ISO2768-f, ISO2768-m, ISO2768-c, ISO2768-v" in text
    rc, text = _run(capsys, ["init", DEMO / "finish.ngc", "--out", tmp_path / "k.toml",
                             "--kind", "internal"])  # fmt: skip
    assert rc == 2 and "finish.ngc:7" in text and "cut into the part" in text, text
    assert not (tmp_path / "k.toml").exists()
    rc, text = _run(capsys, ["init", GCODE / "01_od_dia_mm_t3_g42.ngc", "--out", tmp_path / "t.toml",
                             "--tool-table", GCODE / "tools.tbl", "--tool-units", "in",
                             "--ball-radius", "0.3"])  # fmt: skip
    assert rc == 0, text
    study = load_study(tmp_path / "t.toml")
    assert study.probe.ball_radius == 0.3 and study.program_settings.nose_radius > 0


def test_init_in_a_child_process_uses_this_checkout(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "JAX_PLATFORMS": "cpu", "MPLBACKEND": "Agg"}
    code = (
        "import piecs_bayes, sys; print(piecs_bayes.__file__); "
        "from piecs_bayes.cli import main; sys.exit(main(sys.argv[1:]))"
    )
    proc = subprocess.run(
        [sys.executable, "-c", code, "init", str(DEMO / "finish.ngc"), "--out", "s.toml"],
        cwd=tmp_path, env=env, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    assert proc.stdout.splitlines()[0].startswith(str(ROOT / "piecs_bayes"))
    assert (tmp_path / "s.toml").is_file()
    assert 'part_program = "' in (tmp_path / "s.toml").read_text()
