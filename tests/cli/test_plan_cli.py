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


BORE = ROOT / "tests" / "data" / "stepped_bore" / "study.toml"
#: what the plan says of the stepped bore's step face with the defaults (issue 42;
#: tests/jobs/test_plan_reach.py derives the numbers)
FACE_LEFT_OUT = (
    "feature 'face_z20': wherever the 1 mm ball can touch it, the probe's stand-off "
    "(stock + clearance = 1.5 mm out along the normal) comes nearer than that to feature "
    "'bore_32' (a corner or groove too narrow for the ball with stock and clearance); "
    "reached with [plan] clearance = 0.437 (now 1) or [plan] end_clearance = 0.005 (now 0.2)"
)


def test_a_feature_the_probe_cannot_reach_is_listed_not_measured(capsys, tmp_path):
    """The stepped bore with the defaults: planned without its step face, which the table,
    a warning (shown under --quiet too), plan.json and the program's header name."""
    rc, text = _run(capsys, ["plan", BORE, "--out", tmp_path / "p"])
    assert rc == 0, text
    assert "face_z20       - not measured (the probe cannot reach it)" in text
    assert (
        f"piecs-bayes: warning: {BORE}: not measured: {FACE_LEFT_OUT} (--strict makes this "
        "an error)"
    ) in text
    body = json.loads((tmp_path / "p" / "plan.json").read_text())
    assert [u["feature"] for u in body["unreachable"]] == ["face_z20"]
    assert {p["feature"] for p in body["points"]} == {"bore_32", "bore_26"}
    prog = (tmp_path / "p" / "gauging.ngc").read_text()
    assert "(not measured: face_z20, the probe cannot reach it, see plan.json)" in prog
    rc, text = _run(capsys, ["plan", BORE, "--quiet", "--out", tmp_path / "q"])
    assert rc == 0 and text.startswith("piecs-bayes: warning:") and text.count("\n") == 1


def test_strict_refuses_a_plan_that_leaves_a_feature_out(capsys, tmp_path):
    rc, text = _run(capsys, ["plan", BORE, "--strict", "--out", tmp_path / "p"])
    assert rc == 2
    assert text == (
        f"piecs-bayes: error: {BORE}, feature 'face_z20': the plan would leave 1 feature(s) "
        f"not measured (strict): {FACE_LEFT_OUT}\n"
    )
    assert not (tmp_path / "p").exists()


def test_the_loop_decides_the_unreached_feature_not_measured(capsys, tmp_path):
    """Plan, gauge on the simulated machine, decide: the step face has no point, the
    decisions say "not measured" for it (text, JSON, CSV) and decide the bores."""
    study = tmp_path / "study.toml"
    study.write_text(
        BORE.read_text().replace(
            "probe_files = []",
            'probe_files = ["probe_points.txt"]\nprobe_format = "linuxcnc"\n'
            'probe_plan = "plan/plan.json"',
        )
    )
    truth = tmp_path / "truth.json"
    truth.write_text(json.dumps({"deviations": {
        "bore_32": {"offset": 0.012, "rotation": 0.0},
        "face_z20": {"offset": -0.01, "rotation": 0.0},
        "bore_26": {"offset": -0.006, "rotation": 0.0},
    }}))  # fmt: skip
    assert _run(capsys, ["plan", study, "--out", tmp_path / "plan"])[0] == 0
    argv = ["simulate", "gauge", tmp_path / "plan" / "gauging.ngc", "--study", study,
            "--truth", truth, "--out", tmp_path / "probe_points.txt"]  # fmt: skip
    assert _run(capsys, argv)[0] == 0
    rc, text = _run(capsys, ["decide", study, "--out", tmp_path / "d"])
    assert rc == 0, text
    assert "not measured (no decision): face_z20" in text
    dec = json.loads((tmp_path / "d" / "decisions.json").read_text())
    assert dec["unmeasured"] == ["face_z20"]
    assert [f["feature"] for f in dec["features"]] == ["bore_32", "bore_26"]
    rows = (tmp_path / "d" / "decisions.csv").read_text().splitlines()
    assert [r.split(",")[1:3] for r in rows[1:]] == [
        ["bore_32", "compensate"], ["bore_26", "compensate"], ["face_z20", "not measured"],
    ]  # fmt: skip
