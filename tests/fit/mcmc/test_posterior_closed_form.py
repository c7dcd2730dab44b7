"""Every sampler and every move set against closed-form posteriors.

The samplers are the single-part emcee run (`sample_posterior`) and the
lockstep ensembles (`sample_posteriors`, JAX and NumPy backends); the move
sets are the package's whole vocabulary (`"stretch"`, `"de"`). Targets with
known answers:

- a normal linear model with unknown variance under the Jeffreys prior
  $p(\\beta, \\sigma^2) \\propto 1/\\sigma^2$, on real data (NIST StRD Chwirut2,
  54 observations, a quadratic in the metal distance: strongly correlated
  coefficients): $\\beta \\mid y \\sim t_\\nu(\\hat\\beta, s^2 (X^TX)^{-1})$ and
  $\\sigma^2 \\mid y \\sim \\nu s^2/\\chi^2_\\nu$, $\\nu = n - p$;
- the normal location-scale model (Newcomb's 66 measurements, BDA3 sect. 3.2), the
  same closed form with $p = 1$;
- a 5-D correlated Gaussian with scales from 1e-3 to 10.

Criteria (issue 12): means within 3 Monte Carlo standard errors (the
sampler's own ESS), standard deviations within 2 % and correlations within
0.02 of the closed form. The log-scale parameter $\\log\\sigma$ has the closed
form $\\tfrac12\\log(\\nu s^2) - \\tfrac12\\log X$, $X \\sim \\chi^2_\\nu$: mean
$\\tfrac12[\\log(\\nu s^2/2) - \\psi(\\nu/2)]$, sd $\\tfrac12\\sqrt{\\psi_1(\\nu/2)}$.
emcee 3.1.6's DE snooker move fails exactly these checks (about -6 % in the
sds), which is why no move set uses it.
"""

from __future__ import annotations

import functools
import math
import warnings

import jax.numpy as jnp
import numpy as np
import pytest
from scipy import special

from piecs_bayes.fit.mcmc import (
    SamplerOptions,
    gaussian_loglik,
    sample_posterior,
    sample_posteriors,
)
from piecs_bayes.fit.mcmc._moves import MOVES, emcee_moves, snooker_move_is_sound

SAMPLERS = ("emcee", "lockstep-jax", "lockstep-numpy")
TARGETS = ("linear", "newcomb", "gauss5")
#: steps per ensemble (4 ensembles of 64 walkers): bulk ESS >= 13,000 for every
#: parameter, so that 2 % on an sd is > 3 of its Monte Carlo standard errors
STEPS = {"stretch": 4000, "de": 2500}


def _strd_data(path):
    lines = path.read_text().splitlines()
    start = next(i for i, line in enumerate(lines) if line.startswith("Data:  y"))
    return np.array([list(map(float, line.split())) for line in lines[start + 1 :] if line.split()])


def _jeffreys_closed_form(x, y):
    """Closed-form posterior moments of (beta, log sigma) under 1/sigma^2."""
    n, p = x.shape
    nu = n - p
    xtx_inv = np.linalg.inv(x.T @ x)
    beta = xtx_inv @ x.T @ y
    s2 = float(np.sum((y - x @ beta) ** 2) / nu)
    cov_beta = nu / (nu - 2.0) * s2 * xtx_inv
    mean_ls = 0.5 * (math.log(nu * s2 / 2.0) - special.digamma(nu / 2.0))
    sd_ls = 0.5 * math.sqrt(special.polygamma(1, nu / 2.0))
    mean = np.append(beta, mean_ls)
    cov = np.zeros((p + 1, p + 1))
    cov[:p, :p] = cov_beta
    cov[p, p] = sd_ls**2  # beta and log sigma are uncorrelated (odd symmetry in beta)
    return mean, cov


def _linear_logpost(theta, data):
    x, y = data
    return gaussian_loglik(y - x @ theta[:-1], jnp.exp(theta[-1]))


def _gauss5_logpost(theta, data):
    mean, prec = data
    d = theta - mean
    return -0.5 * d @ prec @ d


@functools.cache
def _target(name: str, reference: str):
    """(log_prob, args, x0, names, closed-form mean, closed-form covariance)."""
    from pathlib import Path

    ref = Path(reference)
    if name == "linear":
        data = _strd_data(ref / "strd" / "Chwirut2.dat")
        y, dist = data[:, 0], data[:, 1]
        x = np.vander(dist, 3, increasing=True)
        mean, cov = _jeffreys_closed_form(x, y)
        args = (jnp.asarray(x), jnp.asarray(y))
        return _linear_logpost, args, mean, ("b0", "b1", "b2", "log_sigma"), mean, cov
    if name == "newcomb":
        y = np.loadtxt(ref / "bayes" / "newcomb_speed_of_light.txt")
        x = np.ones((y.size, 1))
        mean, cov = _jeffreys_closed_form(x, y)
        args = (jnp.asarray(x), jnp.asarray(y))
        return _linear_logpost, args, mean, ("mu", "log_sigma"), mean, cov
    sd = np.array([1e-3, 0.5, 2.0, 10.0, 1.0])
    corr = np.array(
        [
            [1.0, 0.9, -0.5, 0.3, 0.0],
            [0.9, 1.0, -0.4, 0.2, 0.1],
            [-0.5, -0.4, 1.0, -0.6, 0.2],
            [0.3, 0.2, -0.6, 1.0, 0.5],
            [0.0, 0.1, 0.2, 0.5, 1.0],
        ]
    )
    cov = corr * np.outer(sd, sd)
    mean = np.array([0.002, -1.0, 3.0, 50.0, 0.0])
    args = (jnp.asarray(mean), jnp.asarray(np.linalg.inv(cov)))
    return _gauss5_logpost, args, mean, tuple(f"x{i}" for i in range(5)), mean, cov


def _run(sampler, moves, log_prob, args, x0, names, cov0):
    nsteps = STEPS[moves]
    opts = SamplerOptions(nsteps=nsteps, burn=nsteps // 5, seed=11, progress=False, moves=moves)
    kw = dict(names=names, options=opts)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        if sampler == "emcee":
            return sample_posterior(log_prob, x0, args=args, cov0=cov0, **kw)
        batched = tuple(a[None] for a in args)
        backend = sampler.split("-")[1]
        return sample_posteriors(
            log_prob, x0[None], args=batched, cov0=cov0[None], backend=backend, **kw
        )[0]


def _tiered(sampler, moves, target):
    """emcee (four times the lockstep samplers' time) is in `make test` with the "de"
    moves on the linear target, the hardest (strongly correlated coefficients, 4
    parameters): emcee's own DE move, which only this test checks; its stretch move,
    the default, is checked against closed forms in test_bayes.py (Newcomb, the
    conjugate linear model). The rest of emcee's runs are in the slow tier; the
    lockstep samplers, the package's default, on every target and move set."""
    slow = sampler == "emcee" and (target != "linear" or moves != "de")
    marks = [pytest.mark.slow] if slow else []
    return pytest.param(sampler, moves, target, marks=marks, id=f"{moves}-{sampler}-{target}")


@pytest.mark.parametrize(
    ("sampler", "moves", "target"),
    [_tiered(s, m, t) for s in SAMPLERS for m in MOVES for t in TARGETS],
)
def test_posterior_equals_the_closed_form(sampler, moves, target, reference_dir):
    log_prob, args, x0, names, mean, cov = _target(target, str(reference_dir))
    post = _run(sampler, moves, log_prob, args, x0, names, cov)
    assert post.converged, post.problems
    sd = np.sqrt(np.diag(cov))
    mcse = post.sd / np.sqrt(post.ess)
    z = (post.mean - mean) / mcse
    assert np.all(np.abs(z) <= 3.0), dict(zip(names, z, strict=True))
    rel = post.sd / sd - 1.0
    assert np.all(np.abs(rel) <= 0.02), dict(zip(names, rel, strict=True))
    corr = cov / np.outer(sd, sd)
    got = post.cov / np.outer(post.sd, post.sd)
    assert np.max(np.abs(got - corr)) <= 0.02, got - corr


def test_no_move_set_uses_the_snooker_move():
    import emcee

    for name in MOVES:
        kinds = [type(m) for m, _ in emcee_moves(name)]
        assert emcee.moves.DESnookerMove not in kinds
        assert sum(w for _, w in emcee_moves(name)) == pytest.approx(1.0, abs=1e-12)
    assert [type(m) for m, _ in emcee_moves("de")] == [emcee.moves.DEMove, emcee.moves.StretchMove]
    with pytest.raises(Exception, match="snooker move is not offered"):
        emcee_moves("de_snooker")


def test_the_snooker_check_sees_the_bug_of_the_installed_emcee():
    import emcee

    if emcee.__version__ == "3.1.6":
        assert not snooker_move_is_sound()
