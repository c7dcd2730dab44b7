"""Calibration at the default settings: 95 % intervals cover the truth 95 % of the time.

Simulated parts of the demo shaft probed sparsely (3 to 8 points per feature; the
R3 fillet with 5 points over 68 degrees), each part with its own probe noise
(1.5 um) and its own ball-radius, centre-line and Z-scale errors drawn from the
declared sources; fitted in one batch at the defaults (robust Huber fit,
`known_sigma = false`: the pooled probe sigma with the declared repeatability as
prior, Student-t intervals with Welch-Satterthwaite dof) and with a known sigma.
Coverage of every feature parameter, every vertex coordinate and of the whole
path by the simultaneous band must lie in a window about 95 %. Two tiers, each with
its power stated and checked (`test_the_windows_have_the_stated_power`, exact
binomial): `make test` at 300 parts, window 3 binomial sds (an interval that covers
88 % fails it 96 % of the time); the slow tier (`make test-all`) at 1,000 parts,
window 93.5-96.5 % (one that covers 92 % fails 9 times in 10). The Monte Carlo route
the same at 100 and 400 parts. `benchmarks/bench_calibration.py` runs 1,000 parts
for the Monte Carlo route too and for the demo's point counts.

Before the pooled rule, these few-point parts gave parameter coverage far below
95 % (a 5-point arc stated u from its own 2 residual dof).
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from helpers import three_sds, window_pass_rate

from piecs_bayes.errors import InputError
from piecs_bayes.geometry import MachineTransform
from piecs_bayes.jobs import CoverageOptions, coverage_check
from piecs_bayes.simulate import DEMO_ERRORS, DEMO_TRANSFORM, demo_profile, process_deviations

PROFILE = demo_profile()
TRUTH = process_deviations(PROFILE, DEMO_ERRORS)
SOURCES = {"ball_radius": 0.0005, "x_centre": 0.001, "scale_z": 5e-6}
FEW = {"face_end": 3, "dia_24": 8, "taper": 4, "dia_30": 5, "fillet": 5, "shoulder": 6, "dia_44": 7}
MARGIN = 0.12  # the 90-degree fillet probed over 0.76 * 90 = 68.4 degrees
WINDOW = (0.935, 0.965)
#: quasi-random draws per band critical value: 2^13 Sobol points (the default is 2^15)
#: leave a standard error of ~0.01 on the critical value, ~0.2 % of coverage, beside
#: the binomial 0.7 % of 1,000 parts; a quarter of the test's time
BAND_SIMS = 2**13


def _check(known_sigma, n_parts, window, *, bayes=False, seed=0):
    res = coverage_check(PROFILE, TRUTH, CoverageOptions(
        n_parts=n_parts, points=FEW, margin=MARGIN, transform=DEMO_TRANSFORM,
        source_sd=SOURCES, known_sigma=known_sigma, bayes=bayes, bayes_walkers=44,
        bayes_steps=1500, band_sims=BAND_SIMS, seed=seed,
    ))  # fmt: skip
    lo, hi = window
    for route, rates in res.rates.items():
        for kind, rate in rates.items():
            assert lo <= rate <= hi, (route, kind, res.table())
    return res


#: per tier: parts, window, how often a true 95 % passes at least, a coverage the
#: window must catch and how often at least
TIERS = {
    "lin": (300, three_sds(300), 0.995, 0.88, 0.95),
    "lin-slow": (1000, WINDOW, 0.97, 0.92, 0.85),
    "mc": (100, three_sds(100), 0.995, 0.83, 0.90),
    "mc-slow": (400, three_sds(400), 0.995, 0.90, 0.85),
}


@pytest.mark.parametrize("tier", TIERS)
def test_the_windows_have_the_stated_power(tier):
    """Each tier's window passes a true 95 % coverage and fails the stated lower
    coverage as often as stated (exact binomial)."""
    n, window, level, worse, power = TIERS[tier]
    assert window_pass_rate(window, n, 0.95) >= level
    assert 1.0 - window_pass_rate(window, n, worse) >= power


def _linearised(known_sigma, tier):
    n, window, *_ = TIERS[tier]
    res = _check(known_sigma, n, window, seed=11 + known_sigma)
    if known_sigma:
        assert res.sigma_dof == (np.inf, np.inf)
    else:  # 38 points - 15 parameters (fewer when a point is flagged) + 8 of the prior
        assert 28 <= res.sigma_dof[0] <= res.sigma_dof[1] == 31


@pytest.mark.parametrize("known_sigma", [False, True], ids=["pooled", "known"])
def test_linearised_intervals_and_band_cover_at_300_parts(known_sigma):
    _linearised(known_sigma, "lin")


@pytest.mark.slow
@pytest.mark.parametrize("known_sigma", [False, True], ids=["pooled", "known"])
def test_linearised_intervals_and_band_cover_at_1000_parts(known_sigma):
    _linearised(known_sigma, "lin-slow")


def _monte_carlo(tier):
    """All parts sampled together (lockstep ensembles), the probe sigma estimated with
    the declared repeatability as its prior."""
    n, window, *_ = TIERS[tier]
    _check(False, n, window, bayes=True, seed=3)


def test_monte_carlo_from_the_posterior_covers_at_100_parts():
    _monte_carlo("mc")


@pytest.mark.slow
def test_monte_carlo_from_the_posterior_covers_at_400_parts():
    _monte_carlo("mc-slow")


def test_coverage_options_keep_the_defaults():
    o = CoverageOptions()
    assert (o.n_parts, o.points, o.noise_sd, o.ball_radius, o.margin, o.source_sd) == (
        1000, 8, 0.0015, 1.0, 0.1, None
    )  # fmt: skip
    assert o.transform == MachineTransform()
    assert (o.known_sigma, o.declared_dof, o.method, o.loss, o.p) == (
        False, 8.0, "robust", "huber", 0.95
    )  # fmt: skip
    assert (o.bayes, o.bayes_steps, o.bayes_walkers, o.bayes_chunk, o.band_sims) == (
        False, 1500, None, 100, 2**15
    )  # fmt: skip
    assert (o.seed, o.probe, o.calibrated) == (0, None, False)


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        ({"n_parts": 0}, "coverage option 'n_parts': expected an integer >= 1, got 0"),
        ({"points": 2.5}, "coverage option 'points': expected an integer >= 1, got 2.5"),
        (
            {"noise_sd": -0.001},
            "coverage option 'noise_sd': expected a finite number > 0, got -0.001",
        ),
        ({"margin": 0.5}, "coverage option 'margin': expected a number in [0, 0.5), got 0.5"),
        ({"p": 95}, "coverage option 'p': expected a number in (0, 1), got 95"),
        ({"bayes_walkers": 1}, "coverage option 'bayes_walkers': expected an integer >= 2, got 1"),
        ({"calibrated": 1}, "coverage option 'calibrated': expected true or false, got 1"),
        ({"method": "bayes"}, "coverage option 'method': expected 'lsq' or 'robust', got 'bayes'"),
    ],
)
def test_coverage_options_refuse_a_bad_value_by_name(kw, message):
    with pytest.raises(InputError, match=re.escape(message)):
        CoverageOptions(**kw)
