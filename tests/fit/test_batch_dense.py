"""Densely probed features (issue 16): 512 points per feature, a line and an arc with
gross outliers, fitted robustly by the batch kernel, not by the Levenberg-Marquardt
fallback that buckets over 32 points once took (docs/xla_batched_svd_deadlock.md); the same
numbers as the per-part loop, and the truth within the stated uncertainty.
"""

import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.fit import FitOptions, fit_profile, fit_profiles, to_part_frame

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))

N_POINTS = 512
FEATURES = ("dia_30", "fillet")  # a line and an arc
OPTS = FitOptions(method="robust", loss="huber", scale=1.345 * 0.0015)
KW = dict(ball_radius=1.0, options=OPTS)


@pytest.fixture(scope="module")
def dense():
    from _common import simulate_fleet

    from piecs_bayes.simulate import DEMO_TRANSFORM

    fleet = simulate_fleet(3, seed=11, points=dict.fromkeys(FEATURES, N_POINTS), chip_rate=0.0)
    c = np.array(to_part_frame(DEMO_TRANSFORM, fleet["points"]))
    # chips under the stylus: 8 points of every feature pushed out 0.1-0.2 mm
    rng = np.random.default_rng(4)
    chips = []
    for part in np.unique(fleet["part"]):
        for fid in FEATURES:
            rows = np.flatnonzero((fleet["part"] == part) & (fleet["feature"] == fid))
            hit = rng.choice(rows, size=8, replace=False)
            c[hit, 0] += rng.uniform(0.1, 0.2, size=hit.size)
            chips.append(hit)
    args = (fleet["profile"], fleet["part"], fleet["feature"], c)
    return fleet, c, np.concatenate(chips), fit_profiles(*args, **KW)


def test_dense_features_are_fitted_by_the_kernel(dense):
    fleet, c, _, batch = dense
    assert batch.ok.all() and batch.failures == []
    assert {g.n_pad for g in batch.groups} == {N_POINTS}
    # no Levenberg-Marquardt: "fast" (the kernel alone, no retry) gives the same
    # numbers, in a few Newton steps per stage (LM takes ~125 in all)
    fast = fit_profiles(fleet["profile"], fleet["part"], fleet["feature"], c, ball_radius=1.0,
                        options=replace(OPTS, solver="fast"))  # fmt: skip
    for fid in FEATURES:
        np.testing.assert_array_equal(fast.values(fid), batch.values(fid))
        np.testing.assert_array_equal(fast.std_errors(fid), batch.std_errors(fid))
        assert np.all(batch.steps(fid) < 100)


def test_dense_fits_equal_the_loop_and_find_the_truth(dense):
    fleet, c, chips, batch = dense
    for part in batch.parts:
        m = fleet["part"] == part
        loop = fit_profile(fleet["profile"], fleet["feature"][m], c[m], **KW)
        got = batch.profile_fit(part)
        for fid in FEATURES:
            a, b = loop[fid], got[fid]
            assert a.result.status == b.result.status
            np.testing.assert_allclose(b.values, a.values, rtol=0, atol=1e-9)
            np.testing.assert_allclose(b.std_errors, a.std_errors, rtol=1e-6)
            np.testing.assert_array_equal(b.outliers, a.outliers)
            # 1.5 um noise on 512 points: the truth within 5 standard errors
            truth = fleet["truth"][fid][int(part.removeprefix("part")) - 1]
            assert np.all(np.abs(b.values - truth) < 5 * b.std_errors), (part, fid)
    # every chip that moved a point off its surface by > 0.05 mm is flagged
    flagged = batch.outlier_mask
    for k in chips:
        res = np.abs(batch_residual(batch, fleet, k))
        assert flagged[k] or res < 0.05


def batch_residual(batch, fleet, k):
    """The fitted residual (mm) of input point `k`."""
    part, fid = str(fleet["part"][k]), str(fleet["feature"][k])
    f = batch.profile_fit(part)[fid]
    rows = np.flatnonzero((fleet["part"] == part) & (fleet["feature"] == fid))
    return float(f.residuals[int(np.flatnonzero(rows == k)[0])])
