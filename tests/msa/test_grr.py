"""Gauge R&R by ANOVA: AIAG's worked example, capstat-core on the same data, the
average-and-range cross-check with AIAG's K constants, and the refusals.

The worked example is AIAG MSA 4th ed. (2010), chapter III section B: 10 parts x 3
appraisers (A, B, C) x 3 trials. Its printed numbers: average and range R̿ = 0.3417,
X̄_diff = 0.4446, R_p = 3.511, UCL_R = 0.880, EV = 0.20188, AV = 0.22963,
GRR = 0.30575, PV = 1.10456, TV = 1.14610, %GRR = 26.68 %, ndc = 5; ANOVA sums of
squares 3.1673 (appraiser), 88.3619 (parts), 0.3590 (interaction), 2.7589
(equipment), 94.6471 (total), the interaction's F = 0.434 (not significant: pooled);
the ANOVA components give %GRR = 27.9 % and ndc = 4.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from msa_data import AIAG  # tests/msa is on the path

from piecs_bayes.errors import InputError
from piecs_bayes.msa import (
    COMPONENTS,
    MsaSettings,
    gauge_rr,
    gauge_rr_batch,
    range_constants,
    range_method,
)

STUDY = MsaSettings(grr_basis="study")


def _aiag(**kw):
    return gauge_rr(AIAG, appraisers=("A", "B", "C"), settings=STUDY, **kw)


def test_aiag_anova_table():
    g = _aiag()
    full = g.anova_full
    printed = {"appraiser": (2, 3.1673, 1.58363), "part": (9, 88.3619, 9.81799),
               "part x appraiser": (18, 0.3590, 0.01994), "repeatability": (60, 2.7589, 0.04598),
               "total": (89, 94.6471, None)}  # fmt: skip
    for source, (df, ss, ms) in printed.items():
        row = full[source]
        assert row.df == df and round(row.ss, 4) == ss
        if ms is not None:
            assert round(row.ms, 5) == ms
    assert round(full["part x appraiser"].f, 3) == 0.434
    assert g.pooled and g.interaction_p == pytest.approx(0.9741, abs=1e-4)
    # AIAG's table divides the parts' and appraisers' MS by the equipment MS (213.52,
    # 34.44); the random-effects model (Montgomery, Burdick) by the interaction's
    assert full["part"].ms / full["repeatability"].ms == pytest.approx(213.52, abs=0.01)
    assert full["appraiser"].ms / full["repeatability"].ms == pytest.approx(34.44, abs=0.01)
    assert full["part"].f == pytest.approx(full["part"].ms / full["part x appraiser"].ms)
    assert g.anova["repeatability"].df == 78
    assert g.anova["repeatability"].ms == pytest.approx((0.358982222 + 2.758933333) / 78, rel=1e-8)


def test_aiag_anova_components():
    g = _aiag()
    c = g.components
    assert [round(c[k].sd, 3) for k in ("repeatability", "appraiser", "gauge R&R", "part")] == [
        0.200, 0.227, 0.302, 1.042]  # fmt: skip
    assert round(g.pct_grr_study, 1) == 27.9 and g.ndc == 4 and not g.ndc_ok
    assert g.verdict == "conditional" and "part x appraiser" not in c
    assert sum(c[k].pct_contribution for k in ("gauge R&R", "part")) == pytest.approx(100.0)
    assert c["reproducibility"].variance == c["appraiser"].variance
    assert g.clipped == ()


def test_aiag_average_and_range():
    """Our R̿, X̄_diff, R_p are exact; AIAG rounds them (0.3417, 0.4446, 3.511) before
    multiplying by K: the printed results agree to that rounding (5e-4)."""
    rc = _aiag().cross_check
    assert (rc.k1, rc.k2, rc.k3, rc.constants) == (0.5908, 0.5231, 0.3146, "AIAG table")
    assert (round(rc.rbar, 4), round(rc.xdiff, 4), round(rc.rp, 3)) == (0.3417, 0.4447, 3.511)
    printed = {"ev": 0.20188, "av": 0.22963, "grr": 0.30575, "pv": 1.10456, "tv": 1.14610}
    for k, v in printed.items():
        assert getattr(rc, k) == pytest.approx(v, rel=5e-4)
    assert [round(rc.pct(k), 1) for k in ("ev", "av", "grr", "pv")] == [17.6, 20.0, 26.7, 96.4]
    assert rc.ndc == 5 and round(rc.r_ucl, 3) == 0.880
    assert rc.ranges_above == ((3, 1),)  # appraiser B, part 4: 1.03 - 0.01 = 1.02 > 0.880
    # with AIAG's rounded intermediate values the printed digits come back
    ev = 0.3417 * 0.5908
    av = math.sqrt((0.4446 * 0.5231) ** 2 - ev**2 / 30)
    assert (round(ev, 5), round(av, 5), round(3.511 * 0.3146, 5)) == (0.20188, 0.22963, 1.10456)
    assert round(math.hypot(ev, av), 5) == 0.30575


def test_the_k_constants_are_aiags_table_and_the_range_distribution():
    from scipy import stats  # noqa: F401  (scipy present: the constants computed)

    from piecs_bayes.msa._range import AIAG_K1, AIAG_K2, AIAG_K3, range_moments

    for m, k in AIAG_K1.items():
        assert 1.0 / range_moments(m)[0] == pytest.approx(k, abs=5e-5)
    for m, k in {**AIAG_K2, **AIAG_K3}.items():
        assert 1.0 / math.sqrt(range_moments(m)[1]) == pytest.approx(k, abs=5e-5)
    assert range_moments(2)[0] == pytest.approx(2 / math.sqrt(math.pi), rel=1e-10)
    assert range_moments(2)[1] == pytest.approx(2.0, rel=1e-10)  # E[W^2] = 2 for n = 2
    k1, k2, k3, source = range_constants(12, 4, 3)
    assert source == "computed" and k1 == pytest.approx(0.5908, abs=5e-5)


def _designs():
    """Known-truth studies: (name, y, tolerance) covering a kept interaction, a pooled
    one, a negative appraiser estimate and a small design."""
    rng = np.random.default_rng(11)

    def sim(p, o, r, sp, so, spo, se):
        return (5.0 + rng.normal(0, sp, (p, 1, 1)) + rng.normal(0, so, (1, o, 1))
                + rng.normal(0, spo, (p, o, 1)) + rng.normal(0, se, (p, o, r)))  # fmt: skip

    flat = sim(8, 4, 3, 0.01, 0.0, 0.0, 0.002)
    flat = flat - flat.mean((0, 2), keepdims=True) + flat.mean()  # MS_appraiser = 0 < MS_E
    return [
        ("aiag", AIAG, 5.0),
        ("interaction", sim(10, 3, 3, 0.01, 0.002, 0.003, 0.001), 0.06),
        ("pooled", sim(10, 3, 2, 0.01, 0.001, 0.0, 0.001), 0.06),
        ("clipped", flat, 0.06),
        ("small", sim(5, 2, 2, 0.005, 0.001, 0.001, 0.001), 0.03),
    ]


def _relative(a, b):
    return 0.0 if a == b else abs(a - b) / max(abs(a), abs(b))


@pytest.mark.parametrize("name, y, tol", _designs(), ids=[d[0] for d in _designs()])
def test_components_percentages_and_ndc_agree_with_capstat_core(name, y, tol):
    """capstat-core's `gage_rr` (AIAG MSA 4th ed. ANOVA: the same expected mean squares,
    pooling at p > 0.25, negative components set to 0, ndc = floor(1.41 PV/GRR)):
    every variance component, %GRR of study variation and of tolerance and the
    interaction's p-value agree to 1e-9 relative; ndc, the pooling and the band alike.
    The bands' edges differ only at exactly 10 % (capstat: "good" at <= 10, AIAG
    and here "acceptable" below 10) - none of these designs is there."""
    import capstat_core

    g = gauge_rr(y, tolerance=tol, settings=STUDY)
    cs = capstat_core.gage_rr(y, tolerance=tol)
    c = g.components
    inter = c["part x appraiser"].variance if "part x appraiser" in c else 0.0
    pairs = {
        "repeatability": (c["repeatability"].variance, cs.var_repeatability),
        "appraiser": (c["appraiser"].variance, cs.var_operator),
        "interaction": (inter, cs.var_interaction),
        "part": (c["part"].variance, cs.var_part),
        "grr": (c["gauge R&R"].variance, cs.var_gage_rr),
        "pct_study": (g.pct_grr_study, cs.pct_study_var_gage_rr),
        "pct_tolerance": (g.pct_grr_tolerance, cs.pct_tolerance_gage_rr),
        "interaction_p": (g.interaction_p, cs.interaction_pvalue),
    }
    worst = max(_relative(a, b) for a, b in pairs.values())
    assert worst <= 1e-9, {k: _relative(a, b) for k, (a, b) in pairs.items()}
    assert g.ndc == cs.ndc and g.pooled == (not cs.interaction_included)
    band = {"good": "acceptable", "marginal": "conditional", "unacceptable": "not acceptable"}
    assert g.verdict == band[cs.verdict]
    if name == "clipped":
        assert "appraiser" in g.clipped and c["appraiser"].variance == 0.0 == cs.var_operator
    if name == "interaction":
        assert not g.pooled and c["part x appraiser"].variance > 0


@pytest.mark.parametrize("name, y, tol", _designs(), ids=[d[0] for d in _designs()])
def test_the_range_method_agrees_with_capstat_core(name, y, tol):
    """capstat-core's `gage_rr_range` divides by the exact d2(r), d2*(o, 1), d2*(p, 1);
    AIAG's table (used here where it has the design) prints their inverses to 4
    decimals. R̿, X̄_diff and R_p are the same numbers: EV / K1 and PV / K3 agree to
    1e-12; with the constants computed (a design outside the table) EV, AV, PV agree
    to 1e-7 (capstat's quadrature of d2: 1e-8 absolute)."""
    import capstat_core

    p, o, r = y.shape
    rc = range_method(y, tolerance=tol)
    cs = capstat_core.gage_rr_range(y, tolerance=tol)
    rbar = math.sqrt(cs.var_repeatability) * capstat_core.d2(r)
    rp = math.sqrt(cs.var_part) * capstat_core.d2_star(p, 1)
    assert rc.ev / rc.k1 == pytest.approx(rbar, rel=1e-12)
    assert rc.pv / rc.k3 == pytest.approx(rp, rel=1e-12)
    assert rc.k1 == pytest.approx(1 / capstat_core.d2(r), abs=5e-5)
    if rc.constants == "computed":
        assert rc.ev == pytest.approx(math.sqrt(cs.var_repeatability), rel=1e-7)
        assert rc.av == pytest.approx(math.sqrt(cs.var_operator), rel=1e-7, abs=1e-12)
        assert rc.pv == pytest.approx(math.sqrt(cs.var_part), rel=1e-7)


def test_the_batch_is_the_study():
    _, y, _ = _designs()[1]
    ys = np.stack([y, AIAG, y * 2.0])
    b = gauge_rr_batch(ys, STUDY)
    for i, yi in enumerate(ys):
        g = gauge_rr(yi, settings=STUDY)
        for k, comp in g.components.items():
            assert b.estimate[k][i] == pytest.approx(comp.variance, rel=1e-12)
            assert (b.lower[k][i], b.upper[k][i]) == pytest.approx(tuple(comp.ci), rel=1e-12)


def test_repeatability_interval_is_the_exact_chi_square():
    from scipy import stats

    g = _aiag()
    ms, df = g.anova["repeatability"].ms, g.anova["repeatability"].df
    lo, hi = df * ms / stats.chi2.ppf([0.975, 0.025], df)
    assert tuple(g.components["repeatability"].ci) == pytest.approx((lo, hi), rel=1e-12)
    sd = g.components["gauge R&R"].sd_ci
    assert sd.lower <= g.components["gauge R&R"].sd <= sd.upper


def test_verdict_bands_on_the_tolerance():
    # 6 sigma_GRR = 1.814: T = 20 -> 9.1 % acceptable, T = 8 -> 22.7 %, T = 5 -> 36.3 %
    for tol, verdict in ((20.0, "acceptable"), (8.0, "conditional"), (5.0, "not acceptable")):
        g = gauge_rr(AIAG, tolerance=tol)
        assert g.verdict == verdict
        assert g.pct_grr_tolerance == pytest.approx(600 * g.components["gauge R&R"].sd / tol)
    g = gauge_rr(AIAG, tolerance=20.0)
    assert any("on %GRR of the study variation (27.9 %) the verdict would be 'conditional'" in n
               for n in g.notes)  # fmt: skip
    lo, hi = g.pct_grr_tolerance_ci
    assert lo < g.pct_grr_tolerance < hi


@pytest.mark.parametrize(
    "mutate, message",
    [
        (lambda y: y.__setitem__((6, 2, 1), np.nan),
         "part '7', setup 'C', trial 2: reading missing or not finite"),
        (lambda y: None, None),
    ],
    ids=["missing", "ok"],
)  # fmt: skip
def test_a_missing_cell_is_named(mutate, message):
    y = AIAG.copy()
    mutate(y)
    if message is None:
        gauge_rr(y, appraisers="ABC", appraiser_is="setup", settings=STUDY)
        return
    with pytest.raises(InputError, match=message):
        gauge_rr(y, appraisers="ABC", appraiser_is="setup", settings=STUDY)


@pytest.mark.parametrize(
    "y, kw, message",
    [
        (AIAG[:, :, :1], {}, "at least 2 trials, got 1"),
        (AIAG[:, :1, :], {}, "at least 2 appraisers, got 1"),
        (AIAG[:1], {}, "at least 2 parts, got 1"),
        (AIAG[:, :, 0], {}, "needs readings \\(parts, appraisers, trials\\), got shape \\(10, 3\\)"),
        (np.repeat(AIAG[:, :, :1], 3, axis=2), {}, "repeatability is not measured"),
        (AIAG, {"settings": MsaSettings()}, "grr_basis 'tolerance' needs the tolerance"),
        (AIAG, {"tolerance": -1.0}, "tolerance must be a finite number > 0"),
        (AIAG, {"parts": ["a", "b"]}, "2 parts names for 10 parts"),
    ],
)  # fmt: skip
def test_bad_designs_are_refused(y, kw, message):
    kw = {"settings": STUDY, **kw}
    with pytest.raises(InputError, match=message):
        gauge_rr(y, **kw)


def test_components_table_order():
    assert [r["component"] for r in _aiag().table()] == [
        k for k in COMPONENTS if k != "part x appraiser"]  # fmt: skip
