"""The expected loss over many corrections at once (`_actions._loss`) equals the sum
over the posterior draws written out per draw: the quadratic term from the weights'
moments, the out-of-tolerance probability from the sorted draws (no scatter) or a
normal cdf per draw; and the count of draws below a limit is the one floating point
gives, at the limit too."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from scipy import special

from piecs_bayes.decide import DecisionSettings
from piecs_bayes.decide._actions import _bayes_correction, _count, _loss, _posterior

TOL = (-0.010, 0.012)
K = 1.0 / 0.011**2


def _loss_per_draw(c, post, st, adjust):
    """The loss as the definition writes it: every (correction, draw) pair."""
    lo, hi = TOL
    sa2 = st.adjustment_sd**2 if adjust else 0.0
    tau = np.sqrt(sa2 + st.process_sd**2)
    out = []
    for ci in c:
        d = post.samples + ci
        ed2 = np.sum(post.weights * d**2) + sa2 + st.process_sd**2
        p = (
            (d < lo) | (d > hi)
            if tau == 0
            else special.ndtr((lo - d) / tau) + special.ndtr((d - hi) / tau)
        )
        out.append(st.parts_per_decision * (K * ed2 + np.sum(post.weights * p)))
    return np.asarray(out) + st.adjustment_cost * adjust


@pytest.mark.parametrize("process_sd", [0.0, 0.002])
@pytest.mark.parametrize("prior_sd", [None, 0.01])
@pytest.mark.parametrize("n", [1, 7, 600])
def test_the_loss_of_many_corrections_is_the_sum_over_draws(process_sd, prior_sd, n):
    rng = np.random.default_rng(n)
    draws = np.round(rng.normal(0.004, 0.005, n), 4)  # repeated values, as MCMC keeps
    st = dataclasses.replace(DecisionSettings(), process_sd=process_sd, prior_sd=prior_sd)
    post = _posterior(float(draws.mean()), float(draws.std()), draws, prior_sd)
    c = np.concatenate([np.linspace(-0.03, 0.03, 241), TOL[0] - draws, TOL[1] - draws])
    for adjust in (True, False):
        want = _loss_per_draw(c, post, st, adjust)
        got = _loss(c, post, TOL, st, K, adjust)
        assert np.allclose(got, want, rtol=1e-12, atol=1e-12 * np.max(want))


def test_the_count_below_a_limit_is_what_floating_point_gives():
    rng = np.random.default_rng(0)
    for _ in range(500):
        x = np.sort(np.round(rng.normal(0.0, 1e-2, rng.integers(1, 40)), rng.integers(2, 17)))
        bound = float(rng.choice(x))
        # corrections that put a draw exactly on the limit, and a rounding either side
        c = bound - x
        c = np.concatenate([c, np.nextafter(c, 1.0), np.nextafter(c, -1.0), rng.normal(0, 1e-2, 3)])
        for strict in (True, False):
            want = [np.sum(x + ci < bound) if strict else np.sum(x + ci <= bound) for ci in c]
            assert _count(x, c, bound, strict).tolist() == want


def test_the_bayes_correction_minimises_the_loss_on_a_fine_grid():
    rng = np.random.default_rng(3)
    draws = rng.normal(0.006, 0.003, 2000)
    st = DecisionSettings()
    post = _posterior(float(draws.mean()), float(draws.std()), draws, None)
    c_b = _bayes_correction(post, TOL, st, K)
    grid = np.linspace(-0.03, 0.03, 60001)  # 1 nm apart
    best = float(np.min(_loss_per_draw(grid[::50], post, st, True)))
    assert _loss(c_b, post, TOL, st, K, True)[0] <= best + 1e-12
