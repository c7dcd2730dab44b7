"""``piecs-bayes feedback STUDY --out DIR`` on the shipped run (issue 17): the files,
their keys, the exit codes of bad input."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

BATCH = Path(__file__).resolve().parents[2] / "data" / "batch"


def _run(argv) -> int:
    from piecs_bayes.cli import main

    return main(argv)


def test_feedback_writes_the_files(tmp_path, capsys):
    out = tmp_path / "fb"
    rc = _run(["feedback", str(BATCH / "study.toml"), "--out", str(out),
               "--finish", str(BATCH / "finish" / "finish_part*.csv")])  # fmt: skip
    text = capsys.readouterr().out
    assert rc == 0, text
    names = {p.name for p in out.iterdir()}
    assert {"feedback.json", "feedback_parts.csv", "feedback_policies.csv",
            "feedback_next_part.csv", "feedback_finish.csv", "feedback_tracks.png",
            "feedback_policies.png", "feedback_report.html"} <= names  # fmt: skip
    assert not [n for n in names if n.endswith(".tmp")]
    doc = json.loads((out / "feedback.json").read_text(encoding="utf-8"))
    assert {"policies", "predictive_coverage", "next_part", "steps"} <= set(doc)
    assert doc["replayed_on"] == "finish" and len(doc["finish"]["features"]) == 7
    assert "part21" in doc["steps_by_part"]
    html = (out / "feedback_report.html").read_text(encoding="utf-8")
    assert "data:image/png;base64," in html and "bayes" in html
    assert "fitted 36/36 parts" in text and "next part (bayes)" in text


def test_bad_input_exits_2_with_one_line(tmp_path, capsys):
    bad = tmp_path / "finish_part03.csv"
    bad.write_text("part,feature,deviation,u\npart03,dia_24,oops,0.001\n", encoding="utf-8")
    rc = _run(["feedback", str(BATCH / "study.toml"), "--out", str(tmp_path / "o"),
               "--finish", str(bad), "--quiet"])  # fmt: skip
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 2
    assert len(err) == 1 and f"{bad}:2" in err[0] and "'deviation'" in err[0], err
    assert not (tmp_path / "o").exists()


def test_a_pattern_matching_nothing_is_refused(tmp_path, capsys):
    rc = _run(["feedback", str(BATCH / "study.toml"), "--out", str(tmp_path / "o"),
               "--finish", str(tmp_path / "none*.csv"), "-q"])  # fmt: skip
    assert rc == 2 and "matches no file" in capsys.readouterr().err


@pytest.mark.parametrize("flag", ["--no-figures"])
def test_options_parse(flag):
    from piecs_bayes.cli._main import build_parser

    p = build_parser()
    args = p.parse_args(["feedback", "s.toml", flag, "--no-report"])
    assert args.no_figures and args.no_report and args.finish is None
