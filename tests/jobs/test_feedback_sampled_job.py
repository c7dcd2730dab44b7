"""`[feedback] inspect_every` and `delay` (issue 28; their key checks are in
test_feedback_job.py): the job tracks and replays in production order (the parts
between measured ones are prediction steps), and every anchor's row says which
comparison it is."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import batch_study_with

from piecs_bayes.io import load_study


def test_the_keys_are_read():
    from piecs_bayes.io import FEEDBACK_KEYS

    assert {"inspect_every", "delay"} <= set(FEEDBACK_KEYS)


@pytest.fixture(scope="module")
def sampled(tmp_path_factory):
    from piecs_bayes.jobs import feedback_study

    # the first 19 parts of data/batch (before its tool change): the loop is the
    # replay's on any run, and half the run is half the suite's time for this job
    folder = tmp_path_factory.mktemp("sampled")
    path = batch_study_with(folder, "inspect_every = 3\ndelay = 1", "part[01]?.csv")
    return feedback_study(load_study(path), progress=False)


def test_the_job_runs_the_loop_as_the_shop_does(sampled):
    from piecs_bayes.feedback import SHOP_SETTINGS, replay

    res = sampled
    assert (res.inspect_every, res.delay) == (3, 1)
    f = next(iter(res.features.values()))
    n = len(f.parts)
    assert n == 19
    assert f.track.level.shape == (n,) and f.policies["bayes"].realised.shape == (n,)
    # the bayes row is the replay in production order (19 measured parts of 55)
    prod = np.full(3 * (n - 1) + 1, np.nan)
    prod[::3] = f.values
    u = np.full(prod.size, np.nan)
    u[::3] = f.u
    again = replay(prod, u, policy="bayes", settings={}, tolerance=f.tolerance,
                   inspect_every=3, delay=1)  # fmt: skip
    np.testing.assert_allclose(f.policies["bayes"].realised, again.realised[::3], atol=1e-12)
    for name in SHOP_SETTINGS:
        shown = f.policies[f"{name} (a)"].settings
        assert {k: shown[k] for k in SHOP_SETTINGS[name]} == SHOP_SETTINGS[name]
    nxt = res.next_part_rows()
    assert all(np.isfinite(r["correction_mm"]) and r["u_mm"] > 0 for r in nxt)


def test_rows_say_which_comparison_they_are(sampled):
    from piecs_bayes.export.tables import feedback_text

    rows = {(r["feature"], r["policy"]): r["comparison"] for r in sampled.policy_rows()}
    assert rows["all", "ewma"].startswith("b: tuned on this run")
    assert rows["all", "ewma (a)"].startswith("a: one setting for the machine")
    assert rows["all", "bayes"] == ""
    text = feedback_text(sampled)
    assert "ewma (a)" in text and "ewma (b)" in text and "every 3. part measured" in text
    head = sampled.to_dataframe("parts").columns
    assert "realised_ewma_a" in head and "realised_ewma" in head


def test_the_report_shows_both_comparisons(sampled):
    from piecs_bayes.export.report import feedback_report_html

    page = feedback_report_html(sampled, png={"feedback_tracks": b"", "feedback_policies": b""})
    for label in ("ewma (a) (µm)", "ewma (b) (µm)", "dewma (a)", "fixed_gain (b)"):
        assert label in page, label
    assert "one setting a shop" in page and "tuned on this run" in page
