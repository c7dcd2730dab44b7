"""``piecs-bayes plan STUDY``: the files, the table, the controllers and ``--more``."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from helpers import run_cli as _run

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo" / "study.toml"
GOLDEN = ROOT / "tests" / "data" / "golden" / "demo"


def test_plan_writes_the_json_the_program_and_the_figure(capsys, tmp_path):
    rc, text = _run(capsys, ["plan", DEMO, "--points", "5", "--out", tmp_path / "p"])
    assert rc == 0, text
    assert {p.name for p in (tmp_path / "p").iterdir()} == {"plan.json", "gauging.ngc", "plan.png"}
    body = json.loads((tmp_path / "p" / "plan.json").read_text())
    assert body["units"] == "mm" and body["x"] == "radius" and body["controller"] == "linuxcnc"
    assert [p["index"] for p in body["points"]] == list(range(1, 37))  # 5 a line, 6 the arc
    assert {f["feature"] for f in body["features"]} == {"face_end", "dia_24", "taper", "dia_30",
                                                        "fillet", "shoulder", "dia_44"}  # fmt: skip
    prog = (tmp_path / "p" / "gauging.ngc").read_text()
    assert prog.count("G38.2 ") == 36 and "(PROBEOPEN probe_points.txt)" in prog
    assert "T9 M6 G43" in prog and "M5 " in prog and " G94" in prog and "F200.0" in prog
    assert "fillet" in text and "predicted gauging time" in text


def test_fanuc_dialect(capsys, tmp_path):
    rc, text = _run(capsys, ["plan", DEMO, "--points", "4", "--controller", "fanuc",
                             "--out", tmp_path / "f"])  # fmt: skip
    assert rc == 0, text
    prog = (tmp_path / "f" / "gauging_fanuc.nc").read_text()
    lines = prog.splitlines()
    assert lines[1] == "O9001 (PIECS GAUGING)" and "G98" in prog and "T0909" in prog
    assert prog.count("G31 ") == prog.count("DPRNT[X#5061[44]*Z#5062[44]]") == 36
    assert lines.index("POPEN") < lines.index("PCLOS")


def test_more_plans_what_the_verdicts_ask(capsys, tmp_path):
    fit_dir = tmp_path / "fit"
    fit_dir.mkdir()
    shutil.copy(GOLDEN / "residuals.csv", fit_dir)
    dec = json.loads((GOLDEN / "decisions.json").read_text())
    rc, text = _run(capsys, ["plan", DEMO, "--more", GOLDEN, "--out", tmp_path / "none"])
    assert rc == 0 and "nothing to plan" in text and not (tmp_path / "none").exists()
    for row in dec["features"]:
        if row["feature"] == "fillet":
            row["verdict"], row["more_points"] = "measure more", 3
    (fit_dir / "decisions.json").write_text(json.dumps(dec))
    rc, text = _run(capsys, ["plan", DEMO, "--more", fit_dir, "--out", tmp_path / "m"])
    assert rc == 0, text
    body = json.loads((tmp_path / "m" / "plan.json").read_text())
    assert [p["feature"] for p in body["points"]] == ["fillet"] * 3


def test_a_bad_fit_folder_is_named(capsys, tmp_path):
    rc, text = _run(capsys, ["plan", DEMO, "--more", tmp_path, "--out", tmp_path / "m"])
    assert rc == 2 and "decisions.json" in text, text
