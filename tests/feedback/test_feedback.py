"""Feedback policies: the replay arithmetic by hand, the bayes policy as the one-part
decision, the vectorised decision, and the calibration of the one-step-ahead predictive."""

import math
from dataclasses import replace

import numpy as np
import pytest

from piecs_bayes.decide import DecisionSettings, decide
from piecs_bayes.decide._corrections import corrections
from piecs_bayes.errors import InputError
from piecs_bayes.feedback._policies import (
    BAYES_DECISION,
    POLICIES,
    TUNING_GRIDS,
    next_part,
    predictive_coverage,
    replay,
    replay_runs,
    tune,
)
from piecs_bayes.feedback._tracking import TrackModel, track

UM = 1e-3
TOL = (-10 * UM, 10 * UM)
DEV = np.array([4.0, 6.0, -2.0, 30.0, 5.0]) * UM  # part 3 is odd (a chip)

# corrections c_k (µm) worked by hand from the rules in compensate/_feedback.py
HAND = {
    # c_{k+1} = c_k - r_k = -d_k
    ("none", ()): [0, 0, 0, 0, 0],
    ("full", ()): [0, -4, -6, 2, -30],
    # g = 0.5, null band 2 µm, upper limit 20 µm: r = 4, 4, -6 adjust; r = 29 flagged
    ("fixed_gain", (("gain", 0.5), ("null_band", 0.2), ("upper_limit", 2.0))): [
        0,
        -2,
        -4,
        -1,
        -1,
    ],
    # mean of the last two uncompensated estimates: -4, -(4+6)/2, -(6-2)/2, -(-2+30)/2
    ("mean_value", (("k", 2),)): [0, -4, -5, -2, -14],
    # a = 4, 5, 1.5, 15.75
    ("ewma", (("lam", 0.5),)): [0, -4, -5, -1.5, -15.75],
    # a = 4, 5, 1.5, 15.75; D = 0, 1, -3, 12.75; c = -(a + D)
    ("dewma", (("lam1", 0.5), ("lam2", 0.5))): [0, -4, -6, 1.5, -28.5],
}
REALISED = {  # r_k = d_k + c_k (µm), out of tolerance |r| > 10, adjustments, flags
    "none": ([4, 6, -2, 30, 5], 1, 0, 0),
    "full": ([4, 2, -8, 32, -25], 2, 4, 0),
    "fixed_gain": ([4, 4, -6, 29, 4], 1, 3, 1),
    "mean_value": ([4, 2, -7, 28, -9], 1, 4, 0),
    "ewma": ([4, 2, -7, 28.5, -10.75], 2, 4, 0),
    "dewma": ([4, 2, -8, 31.5, -23.5], 2, 4, 0),
}


@pytest.mark.parametrize("key", list(HAND))
def test_replay_arithmetic_by_hand(key):
    name, st = key
    res = replay(DEV, UM, policy=name, settings=dict(st), tolerance=TOL)
    np.testing.assert_allclose(res.corrections / UM, HAND[key], atol=1e-9)
    real, oot, adj, flags = REALISED[name]
    np.testing.assert_allclose(res.realised / UM, real, atol=1e-9)
    assert res.rmsd_mm == pytest.approx(math.sqrt(np.mean(np.square(real))) * UM)
    assert res.max_abs_mm == pytest.approx(max(abs(r) for r in real) * UM)
    assert (res.out_of_tolerance, res.adjustments, res.flags) == (oot, adj, flags)
    assert res.as_row()["name"] == name
    # the batched replay gives the same corrections
    c, fl, pit = replay_runs(np.vstack([DEV, DEV]), UM, policy=name, settings=dict(st),
                             tolerance=TOL)  # fmt: skip
    np.testing.assert_allclose(c / UM, [HAND[key]] * 2, atol=1e-9)
    assert list(fl) == [flags] * 2 and pit is None


def test_fixed_gain_reports_its_bands_in_mm():
    st = {"gain": 0.5, "null_band": 0.2, "upper_limit": 2.0}
    res = replay(DEV, UM, policy="fixed_gain", settings=st, tolerance=TOL)
    assert res.settings["null_band_mm"] == pytest.approx(2 * UM)
    assert res.settings["upper_limit_mm"] == pytest.approx(20 * UM)


def test_memory_restarts_at_a_tool_change():
    # ewma, lambda 0.5, new tool at part 3: a_3 = e_3 = 30, so c_4 = -30
    res = replay(DEV, UM, policy="ewma", settings={"lam": 0.5}, tolerance=TOL, tool_changes=(3,))
    np.testing.assert_allclose(res.corrections / UM, [0, -4, -5, -1.5, -30], atol=1e-9)
    res = replay(DEV, UM, policy="mean_value", settings={"k": 2}, tolerance=TOL,
                 tool_changes=(3,))  # fmt: skip
    np.testing.assert_allclose(res.corrections / UM, [0, -4, -5, -2, -30], atol=1e-9)


ZERO = TrackModel(level_sd=0.0, drift_sd=0.0, scatter_sd=0.0, step_prob=0.0, outlier_prob=0.0,
                  drift0_sd=0.0)  # fmt: skip


@pytest.mark.parametrize(
    "ds", [BAYES_DECISION, DecisionSettings(), DecisionSettings(adjustment_cost=0.3),
           DecisionSettings(prior_sd=0.004, adjustment_sd=0.001)],
)  # fmt: skip
@pytest.mark.parametrize("d0,u0", [(6.0, 0.5), (2.5, 1.0), (-9.0, 2.0), (0.8, 3.0)])
def test_bayes_on_one_part_is_the_one_part_decision(ds, d0, u0):
    one = decide(tolerance=TOL, mean=d0 * UM, sd=u0 * UM, settings=ds)
    nxt = next_part([d0 * UM], [u0 * UM], tolerance=TOL, model=ZERO, decision_settings=ds)
    assert nxt["correction"] == pytest.approx(one.correction, abs=1e-7 * UM)
    assert nxt["mean"] == pytest.approx(d0 * UM) and nxt["sd"] == pytest.approx(u0 * UM)
    assert nxt["decision"].verdict == one.verdict
    # the replay's correction of the second part is the same decision
    res = replay([d0 * UM, 0.0], [u0 * UM, UM], policy="bayes", settings={"model": ZERO},
                 tolerance=TOL, decision_settings=ds)  # fmt: skip
    assert res.corrections[1] == pytest.approx(one.correction, abs=1e-7 * UM)


def test_vectorised_decision_equals_decide():
    rng = np.random.default_rng(0)
    settings = [BAYES_DECISION, DecisionSettings(), DecisionSettings(prior_sd=0.004, adjustment_sd=5e-4),
                DecisionSettings(adjustment_cost=0.2, out_of_tolerance_cost=3.0, parts_per_decision=5)]  # fmt: skip
    for st in settings:
        for tol in (TOL, (-4 * UM, 12 * UM)):
            m = rng.normal(0, 8, 40) * UM
            s = np.exp(rng.uniform(np.log(0.2), np.log(8.0), 40)) * UM
            p = rng.uniform(0, 4, 40) * UM
            fast = corrections(m, s, p, tol, st)
            for i in range(40):
                d = decide(tolerance=tol, mean=m[i], sd=s[i], settings=replace(st, process_sd=p[i]))
                assert fast[i] == pytest.approx(d.correction, abs=1e-7 * UM)
                assert (fast[i] == 0.0) == (d.correction == 0.0)


def _simulated_runs(rng, runs, parts):
    k = np.arange(parts)[None, :]
    level = rng.normal(0, 4, (runs, 1)) + rng.normal(0, 0.3, (runs, 1)) * k
    odd = (rng.random((runs, parts)) < 0.05) * rng.normal(0, 30, (runs, parts))
    u = rng.uniform(0.8, 1.2, (runs, parts))
    dev = level + rng.normal(0, 1.6, (runs, parts)) + odd + u * rng.standard_normal((runs, parts))
    return dev * UM, u * UM


@pytest.mark.parametrize(
    "runs", [60, pytest.param(160, marks=pytest.mark.slow)], ids=["60runs", "160runs"]
)
def test_one_step_ahead_predictive_coverage_is_95_percent(runs):
    """29 predictions a run (a calibrated predictive's PITs are independent): at 60 runs
    the binomial sd of the rate is 0.52 %, the window 93-97 % is 3.8 sds each side, and
    a 91 % coverage fails it 99.8 % of the time; at 160 runs (slow tier) 0.32 %."""
    rng = np.random.default_rng(17)
    dev, u = _simulated_runs(rng, runs, 30)
    c, _, pit = replay_runs(dev, u, policy="bayes", settings={}, tolerance=TOL)
    cover = np.mean((pit[:, 1:] >= 0.025) & (pit[:, 1:] <= 0.975))
    assert 0.93 <= cover <= 0.97
    assert np.all(np.isnan(pit[:, 0]))
    # predictive_coverage of a Track counts the same parts
    tr = track(dev[0], u[0])
    share = predictive_coverage(tr, dev[0])
    pit0 = pit[0, 1:]
    assert share == pytest.approx(np.mean((pit0 >= 0.025) & (pit0 <= 0.975)))


def test_bayes_beats_no_feedback_and_ignores_an_odd_part():
    rng = np.random.default_rng(2)
    dev, u = _simulated_runs(rng, 1, 40)
    dev = dev[0] + 0.3 * UM * np.arange(40)
    dev[20] += 40 * UM
    res = replay(dev, u[0], policy="bayes", settings={}, tolerance=TOL)
    none = replay(dev, u[0], policy="none", settings={}, tolerance=TOL)
    assert res.rmsd_mm < none.rmsd_mm
    assert abs(res.corrections[21] - res.corrections[20]) < 2 * UM


def test_tune_keeps_the_lowest_rms():
    rng = np.random.default_rng(3)
    dev, u = _simulated_runs(rng, 1, 30)
    best = tune(dev[0], u[0], policy="ewma", tolerance=TOL)
    all_rms = [replay(dev[0], u[0], policy="ewma", settings=st, tolerance=TOL).rmsd_mm
               for st in TUNING_GRIDS["ewma"]]  # fmt: skip
    assert best.rmsd_mm == min(all_rms)
    assert set(TUNING_GRIDS) == set(POLICIES)


def test_next_part_uses_the_applied_corrections():
    y = np.array([5.0, 5.5, 4.8, 5.2]) * UM
    plain = next_part(y, UM, tolerance=TOL)
    applied = np.array([0.0, -5.0, -5.0, -5.0]) * UM
    shifted = next_part(y + applied, UM, tolerance=TOL, applied=applied)
    assert shifted["correction"] == pytest.approx(plain["correction"], abs=1e-9)
    assert shifted["adjustment"] == pytest.approx(plain["correction"] + 5 * UM, abs=1e-9)


def test_bad_policy_or_settings_are_refused():
    with pytest.raises(InputError, match="unknown policy"):
        replay(DEV, UM, policy="pid", settings={}, tolerance=TOL)
    with pytest.raises(InputError, match="settings"):
        replay(DEV, UM, policy="ewma", settings={"lambda": 0.2}, tolerance=TOL)
    with pytest.raises(InputError, match="tolerance"):
        replay(DEV, UM, policy="none", settings={}, tolerance=(0.01, -0.01))
    with pytest.raises(InputError, match="p must be"):
        predictive_coverage(track(DEV, UM), DEV, p=1.0)


def test_next_part_is_the_replays_next_correction():
    rng = np.random.default_rng(8)
    dev, u = _simulated_runs(rng, 1, 12)
    dev, u = dev[0] + 0.4 * UM * np.arange(12), u[0]
    res = replay(dev, u, policy="bayes", settings={}, tolerance=TOL)
    c = res.corrections
    nxt = next_part(res.realised[:11], u[:11], tolerance=TOL, applied=c[:11])
    assert nxt["correction"] == pytest.approx(c[11], abs=1e-7 * UM)
    assert nxt["adjustment"] == pytest.approx(c[11] - c[10], abs=1e-7 * UM)


def test_a_large_correction_is_undone_not_locked_in():
    """The level steps down 14 µm and 14 µm more, then comes back: the policy builds a
    correction of about +29 µm in adjustments below max_correction (the tolerance
    width, 20 µm) and undoes it when the level is back. Undoing is never withheld: a
    limit on every adjustment would keep a large correction once the model's prediction
    moves back by more than the limit in one part (e.g. odd parts taken for a step)."""
    from piecs_bayes.feedback._replay import held as _held

    rng = np.random.default_rng(11)
    dev = rng.normal(0.0, 1.0, 40) * UM
    dev[20:26] -= 14 * UM
    dev[26:28] -= 28 * UM
    res = replay(dev, UM, policy="bayes", settings={}, tolerance=TOL)
    c = res.corrections
    assert c[28] > 25 * UM
    assert np.all(np.abs(c[31:]) < 1.5 * UM)
    assert not _held(30 * UM, -30 * UM, 20 * UM)  # back towards zero: applied
    assert not _held(30 * UM, -45 * UM, 20 * UM)
    assert _held(0.0, 25 * UM, 20 * UM) and _held(10 * UM, 25 * UM, 20 * UM)
    assert not _held(10 * UM, 15 * UM, 20 * UM)  # within the limit


def test_next_part_withholds_a_large_adjustment_away_from_zero():
    y = np.array([25.0, 25.5, 24.8, 25.2]) * UM  # 25 µm off, nothing corrected yet
    held = next_part(y, UM, tolerance=TOL)
    assert held["adjustment"] == 0.0 and held["correction"] == 0.0
    assert held["decision"].verdict == "do not compensate" and held["decision"].blocked
    assert "max_correction" in held["decision"].reasons[0]
    assert decide(tolerance=TOL, mean=float(np.mean(y)), sd=UM).blocked  # as decide
    # cut with a +30 µm correction that is no longer needed: undone in one adjustment
    applied = np.full(4, 30.0) * UM
    back = next_part(applied + np.array([0.5, -0.3, 0.2, 0.0]) * UM, UM, tolerance=TOL,
                     applied=applied)  # fmt: skip
    assert back["adjustment"] == pytest.approx(-30 * UM, abs=1.5 * UM)
    assert abs(back["correction"]) < 1.5 * UM
