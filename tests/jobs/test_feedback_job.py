"""Feedback over the shipped run (issue 17, the job layer): `jobs.feedback_study` on
data/batch (policies replayed, the tool change before part21 found, feedback.json's
keys), on the same run with the tool change declared (as the controller logs an insert
change), the `[feedback]` table's checks and the finished-part CSV's errors."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from helpers import BATCH, batch_study_with

from piecs_bayes.errors import InputError
from piecs_bayes.io import load_study

ANCHORS = ("full", "fixed_gain", "mean_value", "ewma", "dewma")


@pytest.fixture(scope="module")
def batch():
    from piecs_bayes.jobs import feedback_study

    study = load_study(BATCH / "study.toml")
    return study, feedback_study(study, progress=False)


@pytest.fixture(scope="module")
def declared(tmp_path_factory):
    """data/batch with the insert change before part21 declared in `[feedback]` (the
    simulator's truth.json: `tool_change_part`), as a shop's controller logs it."""
    from piecs_bayes.jobs import feedback_study

    truth = json.loads((BATCH / "truth.json").read_text(encoding="utf-8"))
    assert truth["tool_change_part"] == "part21"
    folder = tmp_path_factory.mktemp("batch_declared")
    path = batch_study_with(folder, 'tool_changes = ["part21"]')
    return feedback_study(load_study(path), progress=False)


def _no_worse(res):
    bayes = res.overall("bayes")
    for name in ANCHORS:
        other = res.overall(name)
        assert bayes["rmsd_mm"] <= other["rmsd_mm"] * (1 + 1e-9), (name, bayes, other)
        assert bayes["out_of_tolerance"] <= other["out_of_tolerance"], name
    assert res.overall("none")["rmsd_mm"] > 2 * bayes["rmsd_mm"]


def test_bayes_is_no_worse_than_every_anchor_with_the_tool_change_declared(declared):
    """The anchors restart their memory at the change; the model also knows that the new
    edge starts unworn (the wear of the old one goes with it, `wear_reset`)."""
    assert declared.tool_changes == ("part21",)
    _no_worse(declared)


@pytest.mark.xfail(
    strict=True,
    reason="undeclared, the bayes policy loses 4.5 % RMS to the anchors tuned in "
    "hindsight on the same 36 parts (2.462 um against mean_value's 2.355; issue 28's "
    "grid lost 3.3 %): at part21 every policy takes the -12 um step, the anchors' lag "
    "behind the upward wear happens to shrink it; at part22 one part cannot tell a step "
    "from an odd part. The grid favours a nearly fixed level on every feature "
    "(Track.ewma_weight 0.03-0.07 at the end); where the extra 1.2 % comes from is not "
    "analysed yet. With issue 28's grid, on 1,000 simulated runs of "
    "this study's process the ratio's median was 1.003 and 3 % of runs reached 1.033 "
    "(benchmarks/bench_batch_process.py, docs/feedback.md; declared: the test above)",
)
def test_bayes_is_no_worse_than_every_anchor(batch):
    _, res = batch
    _no_worse(res)


def test_bayes_beats_no_feedback_and_the_mirror(batch):
    _, res = batch
    bayes = res.overall("bayes")["rmsd_mm"]
    assert res.overall("none")["rmsd_mm"] > 2 * bayes
    assert bayes < 1.1 * min(res.overall(n)["rmsd_mm"] for n in ANCHORS)


def test_the_tool_change_at_part21_is_found(batch):
    _, res = batch
    assert res.tool_changes == ()  # data/batch declares none: the model must find it
    assert "part21" in res.steps
    found = res.steps["part21"]
    assert len(found) >= 5, found  # every feature that the tool change moves
    i = res.parts.index("part21")
    for fid in found:
        f = res[fid]
        assert f.track.p_step[i] > 0.5
        assert not any(s["part"] != "part21" and not s["declared"] for s in f.steps)


def test_coverage_and_next_part(batch):
    _, res = batch
    cov = res.coverage()
    assert 0.85 <= cov["overall"] <= 1.0 and cov["n"] == 7 * 35
    for r in res.next_part_rows():
        assert np.isfinite(r["correction_mm"]) and r["u_mm"] > 0
        f = res[r["feature"]]
        assert r["correction_drawn_mm"] == pytest.approx(f.scale * r["correction_mm"])
        # the correction moves the predicted level towards the target
        assert abs(r["level_mm"] + r["correction_mm"]) <= abs(r["level_mm"]) + 1e-12


def test_feedback_json_has_the_issue_keys(batch, tmp_path):
    from piecs_bayes.export.tables import feedback_csvs, feedback_json

    _, res = batch
    doc = json.loads(feedback_json(res))
    assert {"policies", "predictive_coverage", "next_part", "steps"} <= set(doc)
    assert [p["name"] for p in doc["policies"]] == list(res.policies)
    for p in doc["policies"]:
        assert {"name", "settings", "rmsd_mm", "max_abs_mm", "out_of_tolerance",
                "adjustments"} <= set(p)  # fmt: skip
        assert len(p["features"]) == 7
    assert {"feature", "correction_mm", "u_mm"} <= set(doc["next_part"][0])
    assert any(s["part"] == "part21" for s in doc["steps"])
    parts = feedback_csvs(res)["feedback_parts.csv"].splitlines()
    head = parts[0].split(",")
    for col in ("part", "feature", "unit", "value", "u", "pred_mean", "pred_sd", "p_outlier",
                "p_step", "realised_bayes", "realised_ewma"):  # fmt: skip
        assert col in head, col
    assert len(parts) == 1 + 7 * 36
    df = res.to_dataframe("parts")
    assert list(df.columns) == head and len(df) == 7 * 36


@pytest.mark.parametrize(
    ("table", "words"),
    [
        ('tool_change = ["part03"]', ["feedback.tool_change", "did you mean 'tool_changes'"]),
        ('policies = ["ewma", "pid"]', ["feedback.policies", "'pid'"]),
        ("policies = 3", ["feedback.policies", "3"]),
        ('finish_files = ["nothing/*.csv"]', ["feedback.finish_files", "nothing/*.csv"]),
        ('characteristic = "worst"', ["feedback.characteristic", "'worst'"]),
        ('tool_changes = ["part03", "part03"]', ["feedback.tool_changes", "part03"]),
        # the loop's keys (issue 28: sampled inspection, metrology delay)
        ("inspect_every = 0", ["feedback.inspect_every", "must be >= 1", "0"]),
        ('inspect_every = "5"', ["feedback.inspect_every", "expected an integer"]),
        ("inspect_every = 2.5", ["feedback.inspect_every", "expected an integer"]),
        ("delay = -1", ["feedback.delay", "must be >= 0"]),
        ("delay = true", ["feedback.delay", "expected an integer"]),
        ("delays = 1", ["feedback.delays", "unknown key"]),
    ],
)
def test_bad_feedback_keys_are_refused_naming_file_key_value(tmp_path, table, words):
    path = batch_study_with(tmp_path, table, "part0[1-4].csv")
    with pytest.raises(InputError) as exc:
        load_study(path)
    msg = str(exc.value)
    assert str(path) in msg
    for w in words:
        assert w in msg, (w, msg)


def test_an_unknown_tool_change_part_is_refused(tmp_path):
    from piecs_bayes.jobs import feedback_study

    study = load_study(batch_study_with(tmp_path, 'tool_changes = ["part99"]', "part0[1-4].csv"))
    assert study.sections["feedback"]["tool_changes"] == ("part99",)
    with pytest.raises(InputError, match=r"feedback.tool_changes: unknown part 'part99'") as e:
        feedback_study(study, progress=False)
    assert e.value.file == str(study.path) and e.value.value == "part99"


def _finish(tmp_path: Path, body: str, name="finish_part03.csv") -> Path:
    p = tmp_path / name
    p.write_text(body, encoding="utf-8")
    return p


@pytest.mark.parametrize(
    ("body", "line", "column", "value"),
    [
        (
            "part,feature,deviation,u\npart03,dia_24,0.001,0.0005\npart03,dia_30,abc,0.0005\n",
            3,
            "deviation",
            "abc",
        ),
        ("part,feature,deviation,u\npart03,dia_99,0.001,0.0005\n", 2, "feature", "dia_99"),
        ("# CMM\npart,feature,deviation,u\npart03,dia_24,0.001,0\n", 3, "u", "0"),
        ("part,feature,deviation,u\npart03,dia_24,nan,0.001\n", 2, "deviation", "nan"),
        ("part,feature,deviation,u,on\npart03,dia_24,0.001,0.001,radial\n", 2, "on", "radial"),
        ("part,feature,deviation,uu\npart03,dia_24,0.001,0.001\n", 1, "uu", "uu"),
        ("part,feature,deviation\npart03,dia_24,0.001\n", 1, "u", None),
        ("part,feature,deviation,u\npart03,dia_24,,0.001\n", 2, "deviation", ""),
    ],
)
def test_finish_csv_errors_are_located(tmp_path, body, line, column, value):
    from piecs_bayes.io import read_finish_csv

    study = load_study(BATCH / "study.toml")
    path = _finish(tmp_path, body)
    with pytest.raises(InputError) as exc:
        read_finish_csv(path, profile=study.profile)
    e = exc.value
    assert (e.file, e.line, e.column) == (str(path), line, column), str(e)
    if value is not None:
        assert e.value == value
    assert f"{path}:{line}" in str(e)


def test_finish_csv_reads_drawn_and_normal_and_refuses_twice(tmp_path):
    from piecs_bayes.io import read_finish_csv, read_finish_files

    study = load_study(BATCH / "study.toml")
    a = _finish(tmp_path, "feature,deviation,u,on\ndia_24,0.004,0.001,drawn\n"
                "taper,0.002,0.001,normal\n")  # fmt: skip
    d = read_finish_csv(a, profile=study.profile)
    assert d.parts == ("finish_part03",)  # no part column: the file's stem
    np.testing.assert_allclose(d.deviation, [0.002, 0.002])  # Ø 4 µm = δ 2 µm
    np.testing.assert_allclose(d.u, [0.0005, 0.001])
    b = _finish(tmp_path, "part,feature,deviation,u\nfinish_part03,taper,0.001,0.001\n", "b.csv")
    with pytest.raises(InputError, match="measured twice") as exc:
        read_finish_files([a, b], profile=study.profile)
    assert exc.value.file == str(b) and exc.value.line == 2 and f"{a}:3" in str(exc.value)


def test_finished_parts_not_in_the_run_are_refused(batch, tmp_path):
    from piecs_bayes.jobs import feedback_study

    study, _ = batch
    p = _finish(tmp_path, "part,feature,deviation,u\npart77,dia_24,0.001,0.001\n")
    with pytest.raises(InputError, match="not a part of the run") as exc:
        feedback_study(study, finish=[p], progress=False)
    assert (exc.value.file, exc.value.line, exc.value.value) == (str(p), 2, "part77")


def test_the_shipped_finished_parts_give_the_transfer(batch):
    from piecs_bayes.io import read_finish_files
    from piecs_bayes.jobs import FeedbackSettings, feedback_from_values

    study, res = batch
    files = sorted((BATCH / "finish").glob("finish_*.csv"))
    truth = json.loads((BATCH / "finish" / "truth.json").read_text(encoding="utf-8"))
    fin = read_finish_files(files, profile=study.profile)
    out = feedback_from_values(
        {k: f.values for k, f in res.features.items()},
        {k: f.u for k, f in res.features.items()},
        profile=study.profile, parts={k: f.parts for k, f in res.features.items()},
        finish=fin, settings=FeedbackSettings(policies=("none", "ewma", "bayes")),
    )  # fmt: skip
    assert out.replayed_on == "finish"
    for f in out.features.values():
        beta, u_beta = f.transfer
        assert abs(beta - truth["transfer"][f.feature]) < 4 * u_beta + 0.02, (f.feature, beta)
        assert f.finish["n"] == len(files)
        # "none" replays the finish as cut: beta times the semifinish values
        np.testing.assert_allclose(f.policies["none"].realised, beta * f.values)
    rows = out.finish_rows()
    assert len(rows) == 7 and all(0.5 <= r["coverage_from_semifinish"] <= 1 for r in rows)


def test_the_study_reader_knows_the_same_policies():
    from piecs_bayes.feedback import POLICIES
    from piecs_bayes.io import FEEDBACK_POLICIES

    assert FEEDBACK_POLICIES == POLICIES


def test_simulated_finished_parts_read_back_as_their_truth(tmp_path):
    from piecs_bayes.io import read_finish_files
    from piecs_bayes.simulate import write_finish

    study = load_study(BATCH / "study.toml")
    truth = write_finish(tmp_path, BATCH / "truth.json", study=study, every=12, seed=3)
    files = sorted(tmp_path.glob("finish_*.csv"))
    assert [f.name for f in files] == ["finish_part12.csv", "finish_part24.csv",
                                       "finish_part36.csv"]  # fmt: skip
    fin = read_finish_files(files, profile=study.profile)
    for rec in truth["parts"]:
        got = fin.for_feature("dia_24")[rec["part"]]
        assert got[0] == pytest.approx(rec["features"]["dia_24"]["measured_mm"], abs=1e-6)
        assert got[1] == pytest.approx(truth["u_cmm_mm"])


def test_feedback_settings_defaults_and_refusal():
    """`FeedbackSettings` holds what `feedback_from_values` took as keywords, with the
    same defaults; an unknown policy is refused with the message it had."""
    from piecs_bayes.feedback import POLICIES
    from piecs_bayes.jobs import FeedbackSettings

    s = FeedbackSettings()
    assert (s.tool_changes, s.policies, s.characteristic, s.inspect_every, s.delay) == (
        (), POLICIES, "mid", 1, 0
    )  # fmt: skip
    assert FeedbackSettings(policies=["none", "ewma"]).policies == ("none", "ewma")
    with pytest.raises(InputError, match="unknown policy 'pid'; expected some of none, full"):
        FeedbackSettings(policies=("none", "pid"))
