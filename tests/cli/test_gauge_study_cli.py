"""``piecs-bayes gauge-study type1|grr FILE --out DIR`` on the shipped example: the
printed tables and verdicts, the JSON, the figure; bad input exits 2 with one line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
EXAMPLE = ROOT / "data" / "gauge" / "gauge.toml"


def _run(argv) -> int:
    from piecs_bayes.cli import main

    return main(argv)


def test_type1_prints_the_table_and_writes_json_and_run_chart(tmp_path, capsys):
    out = tmp_path / "g"
    rc = _run(["gauge-study", "type1", str(EXAMPLE), "--out", str(out)])
    text = capsys.readouterr().out
    assert rc == 0, text
    for expected in ("Type-1 study: 50 readings of the reference 40.0012 mm", "Cgk",
                     "verdict: CAPABLE", "Q_MS = 2 U_MS / T", "u_EVR"):  # fmt: skip
        assert expected in text, text
    assert {p.name for p in out.iterdir()} == {"gauge_type1.json", "gauge_type1_run_chart.png"}
    doc = json.loads((out / "gauge_type1.json").read_text(encoding="utf-8"))
    assert doc["schema"] == "piecs_bayes.gauge_study" and doc["kind"] == "type1"
    stats = {r["quantity"]: r for r in doc["type1"]["statistics"]}
    assert stats["cg"]["value"] > 1.33 and stats["cgk"]["lower"] < stats["cgk"]["value"]
    assert doc["type1"]["verdict"] == "capable" and len(doc["type1"]["readings_mm"]) == 50
    assert doc["budget"]["q_ms"] < 0.15 and doc["budget"]["u_mp_mm"] is None
    assert doc["grr"] is None and doc["settings"]["k_share"] == 0.2
    png = (out / "gauge_type1_run_chart.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 10_000


def test_grr_prints_anova_components_and_budget(tmp_path, capsys):
    out = tmp_path / "g"
    rc = _run(["gauge-study", "grr", str(EXAMPLE), "--out", str(out), "--no-figures"])
    text = capsys.readouterr().out
    assert rc == 0, text
    for expected in ("Gauge R&R (ANOVA, crossed): 10 parts x 3 setups x 3 trials",
                     "ANOVA, with interaction", "part x setup", "%GRR of T =", "ndc =",
                     "cross-check, average and range (K1 0.5908, K2 0.5231, K3 0.3146",
                     "Q_MP = 2 U_MP / T", "u_AV"):  # fmt: skip
        assert expected in text, text
    assert [p.name for p in out.iterdir()] == ["gauge_grr.json"]
    doc = json.loads((out / "gauge_grr.json").read_text(encoding="utf-8"))
    g = doc["grr"]
    assert g["appraiser_is"] == "setup" and g["appraisers"] == ["A", "B", "C"]
    assert [r["source"] for r in g["anova_with_interaction"]] == [
        "part", "appraiser", "part x appraiser", "repeatability", "total"]  # fmt: skip
    comps = {c["component"]: c for c in g["components_mm"]}
    assert comps["gauge R&R"]["pct_tolerance"] == pytest.approx(g["pct_grr_tolerance"])
    assert g["ndc"] >= 5 and g["range_method_mm"]["constants"] == "AIAG table"
    assert doc["budget"]["q_mp"] is not None and doc["type1"] is not None


def test_grr_writes_its_figure(tmp_path, capsys):
    out = tmp_path / "g"
    assert _run(["gauge-study", "grr", str(EXAMPLE), "--out", str(out), "-q"]) == 0
    assert capsys.readouterr().out == ""
    assert (out / "gauge_grr.png").read_bytes()[:4] == b"\x89PNG"


def _copy_example(tmp_path, **replace) -> Path:
    for name in ("type1_ring.csv", "grr.csv"):
        (tmp_path / name).write_bytes((EXAMPLE.parent / name).read_bytes())
    text = EXAMPLE.read_text(encoding="utf-8")
    for old, new in replace.items():
        text = text.replace(old, new)
    path = tmp_path / "gauge.toml"
    path.write_text(text, encoding="utf-8")
    return path


@pytest.mark.parametrize(
    "kind, edit, message",
    [
        ("type1", {"expanded_uncertainty = 0.0006 # U from its calibration certificate\n": ""},
         "gauge.toml: [type1] expanded_uncertainty is missing"),
        ("grr", {'readings = "grr.csv"': 'readings = "missing.csv"'},
         "missing.csv: [grr] readings file not found"),
    ],
    ids=["no-U", "no-file"],
)  # fmt: skip
def test_bad_input_exits_2_with_one_line(tmp_path, capsys, kind, edit, message):
    path = _copy_example(tmp_path, **edit)
    rc = _run(["gauge-study", kind, str(path), "--out", str(tmp_path / "o")])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and message in err[0] and err[0].startswith("piecs-bayes: error: "), err
    assert not (tmp_path / "o").exists()


def test_too_few_readings_exit_2(tmp_path, capsys):
    path = _copy_example(tmp_path)
    lines = (tmp_path / "type1_ring.csv").read_text(encoding="utf-8").splitlines()
    (tmp_path / "type1_ring.csv").write_text("\n".join(lines[:20]) + "\n", encoding="utf-8")
    assert _run(["gauge-study", "type1", str(path), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err
    assert (
        "type1_ring.csv: a type-1 study needs at least 25 readings of the reference, got 18" in err
    )


def test_help_imports_nothing_heavy():
    code = ("import sys, contextlib, io\nimport piecs_bayes.cli\n"
            "for argv in (['gauge-study', '--help'], ['gauge-study', 'grr', '--help']):\n"
            "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
            "        piecs_bayes.cli.main(argv)\n"
            "print(','.join(m for m in ('jax', 'numpy', 'scipy', 'matplotlib') if m in sys.modules))\n")  # fmt: skip
    env = {**os.environ, "JAX_PLATFORMS": "cpu"}
    out = subprocess.run([sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True,
                         text=True)  # fmt: skip
    assert out.returncode == 0 and out.stdout.strip() == "", out.stderr
