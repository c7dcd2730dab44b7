"""Calibration of the measuring-system intervals: 95 % intervals cover the truth 95 %
of the time, over simulated studies with known truth (vectorised: `type1_batch`,
`gauge_rr_batch`).

Type-1: normal readings of a reference (n = 25 and 50; centred, biased, Cgk near 1.33);
bias (Student t), s and Cg (exact chi-square: one event, Cg = K T / (L s)), Cgk
(Bissell). Gauge R&R, 10 parts x 3 appraisers x 3 (or 2) trials: (A) no interaction,
pooled by AIAG's rule (p > 0.25); (B, C) a real interaction, kept (alpha 1); the MLS
intervals of repeatability, appraiser, interaction, reproducibility, GRR and part.
Two tiers, each window's power checked (`test_the_windows_have_the_stated_power`,
exact binomial): `make test` at 300 studies per scenario, every rate within 3 binomial
sds (a coverage of 88 % fails it 96 % of the time); the slow tier at 1,000 per
scenario, each quantity's rate over its scenarios (2,000-4,000 studies) in
93.5-96.5 % (92 % fails it at least 99 times in 100) and every single rate within 3
sds of 1,000. The MLS interval of the total variance is conservative (a sum of mean
squares): 96.6 % over 40,000 studies, checked in 95-98.5 %. Numbers: docs/msa.md.
"""

from __future__ import annotations

import numpy as np
import pytest
from helpers import three_sds, window_pass_rate

from piecs_bayes.msa import MsaSettings, gauge_rr_batch, type1_batch

WINDOW = (0.935, 0.965)
T = 0.020


#: per tier: studies, window, how often a true 95 % passes at least, a coverage the
#: window must catch and how often at least
TIERS = {"fast": (300, three_sds(300), 0.995, 0.88, 0.95),
         "slow-each": (1000, three_sds(1000), 0.995, 0.90, 0.97),
         "slow-pooled": (2000, WINDOW, 0.995, 0.92, 0.99)}  # fmt: skip


@pytest.mark.parametrize("tier", TIERS)
def test_the_windows_have_the_stated_power(tier):
    n, window, level, worse, power = TIERS[tier]
    assert window_pass_rate(window, n, 0.95) >= level
    assert 1.0 - window_pass_rate(window, n, worse) >= power


#: type-1 scenarios: (n, sigma, bias) in mm, T = 20 um: Cg 2.2 / Cgk 2.2, 2.2 / 1.9,
#: 1.33 / 1.0 and 3.3 / 2.0
TYPE1 = [(25, 0.0003, 0.0), (25, 0.0003, 0.0003), (50, 0.0005, 0.0005), (50, 0.0002, -0.0008)]


def type1_coverage(n_studies: int, seed: int) -> dict:
    """`{(scenario, quantity): rate}` over `n_studies` simulated type-1 studies each."""
    rng = np.random.default_rng(seed)
    out = {}
    for k, (n, sigma, bias) in enumerate(TYPE1):
        b = type1_batch(rng.normal(40.0 + bias, sigma, (n_studies, n)), 40.0, T)
        truth = {"bias": bias, "s": sigma, "cg": 0.2 * T / (6 * sigma),
                 "cgk": (0.1 * T - abs(bias)) / (3 * sigma)}  # fmt: skip
        for q, v in truth.items():
            lo, hi = getattr(b, f"{q}_lo"), getattr(b, f"{q}_hi")
            out[k, q] = float(np.mean((lo <= v) & (v <= hi)))
    return out


#: gauge R&R scenarios: (parts, appraisers, trials, sd part, appraiser, interaction,
#: repeatability, interaction_alpha)
GRR = {"A": (10, 3, 3, 1.0, 0.2, 0.0, 0.2, 0.25), "B": (10, 3, 3, 1.0, 0.2, 0.15, 0.2, 1.0),
       "C": (10, 3, 2, 0.8, 0.25, 0.2, 0.15, 1.0)}  # fmt: skip


def _simulate(rng, m, p, o, r, sp, so, spo, se):
    return (10.0 + rng.normal(0, sp, (m, p, 1, 1)) + rng.normal(0, so, (m, 1, o, 1))
            + rng.normal(0, spo, (m, p, o, 1)) + rng.normal(0, se, (m, p, o, r)))  # fmt: skip


def grr_coverage(n_studies: int, seed: int) -> dict:
    """`{(scenario, component): rate}`; the interaction only where it is kept."""
    rng = np.random.default_rng(seed)
    out = {}
    for name, (p, o, r, sp, so, spo, se, alpha) in GRR.items():
        y = _simulate(rng, n_studies, p, o, r, sp, so, spo, se)
        b = gauge_rr_batch(y, MsaSettings(interaction_alpha=alpha))
        truth = {"repeatability": se**2, "appraiser": so**2, "reproducibility": so**2 + spo**2,
                 "gauge R&R": se**2 + so**2 + spo**2, "part": sp**2,
                 "total": sp**2 + so**2 + spo**2 + se**2}  # fmt: skip
        if spo > 0:
            truth["part x appraiser"] = spo**2
        for k, v in truth.items():
            out[name, k] = float(np.mean((b.lower[k] <= v) & (v <= b.upper[k])))
    return out


def _check(rates: dict, window, total_window=(0.93, 0.995)) -> None:
    """Every rate in `window`, the total variance's in `total_window`."""
    lo, hi = window
    bad = {k: v for k, v in rates.items() if k[1] != "total" and not lo <= v <= hi}
    assert bad == {}, rates
    t_lo, t_hi = total_window
    assert all(t_lo <= v <= t_hi for k, v in rates.items() if k[1] == "total"), rates


def _pooled(rates: dict) -> dict:
    """Each quantity's rate over its scenarios (equal numbers of studies)."""
    out: dict = {}
    for (_, q), v in rates.items():
        out.setdefault(("all", q), []).append(v)
    return {k: float(np.mean(v)) for k, v in out.items()}


def test_type1_intervals_cover_at_300_studies():
    _check(type1_coverage(300, seed=1), TIERS["fast"][1])


def test_grr_intervals_cover_at_300_studies():
    _check(grr_coverage(300, seed=2), TIERS["fast"][1])


@pytest.mark.slow
def test_type1_intervals_cover_at_1000_studies():
    rates = type1_coverage(1000, seed=3)
    _check(rates, TIERS["slow-each"][1])
    _check(_pooled(rates), WINDOW)


@pytest.mark.slow
def test_grr_intervals_cover_at_1000_studies():
    rates = grr_coverage(1000, seed=4)
    _check(rates, TIERS["slow-each"][1])
    _check(_pooled(rates), WINDOW, (0.95, 0.985))
