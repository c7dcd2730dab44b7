"""The type-1 study against closed forms, against capstat-core's bias study, and its
refusals (too few readings, a reference without U, no variation).

Closed form: readings built as `m + s z` with `z` exactly standardised (mean 0, sd 1),
so the bias is `m - reference` and the sd `s` to rounding; the quantiles are the
printed table values (t_{0.975,24} = 2.064, chi2_{0.025,24} = 12.401, chi2_{0.975,24}
= 39.364) to their digits and scipy's to 1e-12.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.msa import MsaSettings, Reference, type1_batch, type1_study

REF = Reference(40.0, 0.0004, 2.0)
T = 0.020
T24, CHI_LO, CHI_HI = 2.0638985616280205, 12.401150217444435, 39.36407702660391


def _exact(n, m, s, seed=0):
    z = np.random.default_rng(seed).normal(size=n)
    z = (z - z.mean()) / z.std(ddof=1)
    return m + s * z


def test_the_printed_quantiles():
    from scipy import stats

    assert round(T24, 3) == 2.064 and stats.t.ppf(0.975, 24) == pytest.approx(T24, rel=1e-12)
    assert (round(CHI_LO, 3), round(CHI_HI, 3)) == (12.401, 39.364)
    assert stats.chi2.ppf([0.025, 0.975], 24) == pytest.approx([CHI_LO, CHI_HI], rel=1e-12)


def test_closed_forms_of_a_biased_gauge():
    t1 = type1_study(_exact(25, 40.0005, 0.0004), reference=REF, tolerance=T, resolution=1e-4)
    assert t1.n == 25
    assert t1.bias == pytest.approx(0.0005, rel=1e-9)
    assert t1.s == pytest.approx(0.0004, rel=1e-9)
    assert t1.bias_t == pytest.approx(0.0005 / (0.0004 / 5), rel=1e-9)  # 6.25
    half = T24 * 0.0004 / 5
    assert tuple(t1.bias_ci) == pytest.approx((0.0005 - half, 0.0005 + half), rel=1e-9)
    assert tuple(t1.s_ci) == pytest.approx(
        (0.0004 * math.sqrt(24 / CHI_HI), 0.0004 * math.sqrt(24 / CHI_LO)), rel=1e-9
    )
    assert t1.cg == pytest.approx(0.2 * T / (6 * 0.0004), rel=1e-9)  # 1.6667
    assert t1.cgk == pytest.approx((0.1 * T - 0.0005) / (3 * 0.0004), rel=1e-9)  # 1.25
    cg = 0.2 * T / (6 * 0.0004)
    assert tuple(t1.cg_ci) == pytest.approx(
        (cg * math.sqrt(CHI_LO / 24), cg * math.sqrt(CHI_HI / 24)), rel=1e-9
    )
    cgk, z = 1.25, 1.959963984540054
    h = z * math.sqrt(1 / (9 * 25) + cgk**2 / (2 * 24))
    assert tuple(t1.cgk_ci) == pytest.approx((cgk - h, cgk + h), rel=1e-9)
    assert t1.resolution_share == pytest.approx(0.005) and t1.resolution_ok
    assert t1.bias_significant and t1.bias_p < 1e-5
    assert t1.cg_ok and not t1.cgk_ok and not t1.capable and t1.verdict == "not capable"
    assert t1.reasons == ("Cgk 1.25 < 1.33: bias and repeatability too large",)
    lim = t1.limits
    assert (lim["lower"], lim["upper"]) == pytest.approx((40.0 - 0.002, 40.0 + 0.002))
    assert (lim["mean_lower"], lim["mean_upper"]) == pytest.approx(
        (40.0005 - 0.0012, 40.0005 + 0.0012)
    )


def test_a_capable_gauge_and_the_settings():
    x = _exact(50, 40.0001, 0.0002)
    t1 = type1_study(x, reference=REF, tolerance=T, resolution=1e-4)
    assert t1.cg == pytest.approx(0.004 / 0.0012) and t1.cgk == pytest.approx(0.0019 / 0.0006)
    assert t1.capable and t1.reasons == () and t1.verdict == "capable"
    # another company's setting: K = 15 %, L = 4 s
    st = MsaSettings(k_share=0.15, l_spread=4.0)
    t2 = type1_study(x, reference=REF, tolerance=T, resolution=1e-4, settings=st)
    assert t2.cg == pytest.approx(0.15 * T / (4 * 0.0002))
    assert t2.cgk == pytest.approx((0.075 * T - 0.0001) / (2 * 0.0002))


def test_the_resolution_check():
    x = _exact(25, 40.0, 0.0002)
    t1 = type1_study(x, reference=REF, tolerance=T, resolution=0.0011)  # 5.5 % of T
    assert not t1.resolution_ok and not t1.capable
    assert t1.reasons == ("resolution 5.5% of T > 5%",)
    assert type1_study(x, reference=REF, tolerance=T, resolution=0.001).resolution_ok  # 5 %


def test_the_batch_is_the_study():
    x = np.random.default_rng(3).normal(40.0003, 0.0003, (4, 30))
    b = type1_batch(x, REF.value, T)
    for i in range(4):
        t1 = type1_study(x[i], reference=REF, tolerance=T, resolution=1e-4)
        assert (b.cg[i], b.cgk_lo[i], b.bias_p[i]) == pytest.approx((t1.cg, t1.cgk_ci.lower,
                                                                     t1.bias_p), rel=1e-14)  # fmt: skip


@pytest.mark.parametrize("n, seed", [(25, 1), (50, 2), (100, 3)])
def test_the_bias_test_agrees_with_capstat_core(n, seed):
    """capstat-core's `bias` (AIAG MSA 4th ed., independent-sample method): the same
    mean, bias, s, t, p and 95 % interval, to 1e-12 relative."""
    import capstat_core

    x = np.random.default_rng(seed).normal(25.0004, 0.0003, n)
    ref = Reference(25.0, 0.0002, 2.0)
    ours = type1_study(x, reference=ref, tolerance=0.01, resolution=1e-5)
    theirs = capstat_core.bias(x, 25.0, alpha=0.05)
    pairs = [(ours.mean, theirs.mean), (ours.bias, theirs.bias), (ours.s, theirs.repeatability),
             (ours.bias_t, theirs.t_statistic), (ours.bias_p, theirs.p_value),
             (ours.bias_ci.lower, theirs.ci_lower), (ours.bias_ci.upper, theirs.ci_upper)]  # fmt: skip
    for a, b in pairs:
        assert a == pytest.approx(b, rel=1e-12, abs=0)
    assert ours.bias_significant == theirs.bias_significant


@pytest.mark.parametrize(
    "readings, message",
    [
        (np.full(24, 40.0) + np.arange(24) * 1e-4, "at least 25 readings of the reference, got 24"),
        (
            np.full(30, 40.0001),
            "all 30 readings are equal (40.0001): the repeatability is not measured",
        ),
        (np.r_[np.linspace(40, 40.001, 29), np.nan], "reading 30 is not a finite number"),
    ],
    ids=["few", "zero-variance", "nan"],
)
def test_bad_readings_are_refused(readings, message):
    with pytest.raises(InputError, match=message.replace("(", r"\(").replace(")", r"\)")):
        type1_study(readings, reference=REF, tolerance=T, resolution=1e-4)


@pytest.mark.parametrize(
    "args, message",
    [
        ((40.0, 0.0, 2.0), "reference expanded_uncertainty must be > 0"),
        ((40.0, None, 2.0), "reference expanded_uncertainty: expected a finite number, got None"),
        ((40.0, 0.0004, 0.0), "reference coverage_factor must be > 0"),
        ((math.nan, 0.0004, 2.0), "reference value: expected a finite number"),
    ],
)
def test_a_reference_without_its_certificate_is_refused(args, message):
    with pytest.raises(InputError, match=message):
        Reference(*args)


@pytest.mark.parametrize("name, value", [("tolerance", 0.0), ("resolution", -1e-4),
                                         ("tolerance", math.inf)])  # fmt: skip
def test_bad_tolerance_or_resolution(name, value):
    kw = {"tolerance": T, "resolution": 1e-4, name: value}
    with pytest.raises(InputError, match=f"{name} must be a finite number > 0"):
        type1_study(_exact(25, 40.0, 0.0003), reference=REF, **kw)


@pytest.mark.parametrize(
    "kw, message",
    [({"confidence": 1.0}, "'confidence': expected a number in \\(0, 1\\)"),
     ({"min_readings": 1}, "'min_readings': expected an integer >= 2"),
     ({"grr_basis": "parts"}, "'grr_basis': expected one of 'tolerance', 'study'"),
     ({"grr_conditional": 0.05}, "'grr_conditional': expected a number above grr_acceptable")],
)  # fmt: skip
def test_settings_out_of_range_are_refused(kw, message):
    with pytest.raises(InputError, match=message):
        MsaSettings(**kw)
