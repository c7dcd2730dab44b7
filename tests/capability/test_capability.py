"""Capability indices against Montgomery's piston rings, interval coverage, stability."""

import math
import re
from dataclasses import FrozenInstanceError, replace

import numpy as np
import pytest

from piecs_bayes.capability import (
    CapabilityOptions,
    c4_constant,
    capability,
    d2_constant,
    predict_capability,
    sigma_within,
    stability_check,
)
from piecs_bayes.errors import AnalysisError, InputError

# Published values (R qcc / mistat test suite, quoted in the reference file's header):
# spec -> {index: (value, lower, upper)} as printed.
PISTON_RINGS = {
    (73.95, 74.05, None): {
        "cp": ("1.703", "1.491", "1.915"),
        "cpl": ("1.743", "1.555", "1.932"),
        "cpu": ("1.663", "1.483", "1.844"),
        "cpk": ("1.663", "1.448", "1.878"),
        "cpm": ("1.691", "1.480", "1.902"),
    },
    (73.95, 74.05, 74.02): {"cpm": ("0.7856", "0.6556", "0.9154")},
    (73.99, 74.01, None): {
        "cp": ("0.3407", "0.2983", "0.3830"),
        "cpl": ("0.3807", "0.3176", "0.4439"),
        "cpu": ("0.3006", "0.2424", "0.3588"),
        "cpk": ("0.3006", "0.2312", "0.3700"),
        "cpm": ("0.3382", "0.2960", "0.3804"),
    },
    (73.99, 74.10, None): {
        "cp": ("1.8736", "1.6406", "2.1063"),
        "cpk": ("0.3807", "0.3055", "0.4559"),
        "cpm": ("0.4083", "0.3377", "0.4788"),
    },
}


def _printed(value: float, text: str) -> bool:
    """True when `value` rounds to the printed `text` (same number of decimals)."""
    decimals = len(text.split(".")[1])
    return f"{value:.{decimals}f}" == text


@pytest.fixture
def piston_rings(reference_dir):
    path = reference_dir / "capability" / "pistonrings_montgomery.txt"
    rows = np.loadtxt(path, comments="#", usecols=(1, 2))
    phase1 = rows[rows[:, 1] <= 25, 0]
    assert phase1.size == 125
    return phase1.reshape(25, 5), rows


@pytest.mark.parametrize("spec", list(PISTON_RINGS), ids=lambda s: f"{s[0]}-{s[1]}-T{s[2]}")
def test_piston_rings_match_published_digits(piston_rings, spec):
    x, _ = piston_rings
    lsl, usl, target = spec
    r = capability(
        x, lsl, usl, target=target, options=CapabilityOptions(convention="qcc", bayes=False)
    )
    assert _printed(r.sigma_within, "0.009785039")
    assert _printed(r.mean, "74.00118")
    assert r.n == 125 and r.n_subgroups == 25 and r.subgroup_size == 5
    for name, (value, lower, upper) in PISTON_RINGS[spec].items():
        got = getattr(r, name)
        ci = getattr(r, f"{name}_ci")
        assert _printed(got, value), (name, got, value)
        assert _printed(ci.lower, lower), (name, "lower", ci.lower, lower)
        assert _printed(ci.upper, upper), (name, "upper", ci.upper, upper)


def test_piston_rings_overall_and_bayes(piston_rings):
    x, _ = piston_rings
    r = capability(
        x, 73.95, 74.05, options=CapabilityOptions(convention="qcc", n_draws=400_000, seed=3)
    )
    # self-computed in the reference header: overall s = 0.0100700, Pp 1.65509, Ppk 1.61616
    assert _printed(r.sigma_overall, "0.0100700")
    assert _printed(r.pp, "1.65509") and _printed(r.ppk, "1.61616")
    b = r.bayes
    # Cp's credible interval is closed form and equals Pp's chi-square interval
    assert _printed(b.cp_interval.lower, "1.4492") and _printed(b.cp_interval.upper, "1.8606")
    assert b.cp_interval.lower == pytest.approx(r.pp_ci.lower, rel=1e-12)
    # Monte Carlo (reference: 4e6 draws): median 1.609, [1.405, 1.821], P = 0.9965
    assert b.cpk == pytest.approx(1.609, abs=0.002)
    assert b.cpk_interval.lower == pytest.approx(1.405, abs=0.003)
    assert b.cpk_interval.upper == pytest.approx(1.821, abs=0.003)
    assert b.p_cpk_above == pytest.approx(0.9965, abs=0.0006)


def test_piecs_convention_is_exact_and_wider(piston_rings):
    x, _ = piston_rings
    qcc = capability(x, 73.95, 74.05, options=CapabilityOptions(convention="qcc", bayes=False))
    exact = capability(x, 73.95, 74.05, options=CapabilityOptions(bayes=False))
    # exact d2(5) = 2.325929 instead of the table's 2.326
    assert d2_constant(5) == pytest.approx(2.3259289473, abs=1e-10)
    assert d2_constant(5, convention="qcc") == 2.326
    assert exact.cp == pytest.approx(qcc.cp * 2.325929 / 2.326, rel=1e-6)
    # R-bar of 25 subgroups of 5 carries ~90.6, not 124, degrees of freedom
    assert exact.df_within == pytest.approx(90.6, abs=0.1)
    assert qcc.df_within == 124
    assert exact.cp_ci.upper - exact.cp_ci.lower > qcc.cp_ci.upper - qcc.cp_ci.lower


def test_constants_against_tables():
    assert [round(d2_constant(n), 3) for n in (2, 3, 4, 10, 25)] == [
        1.128,
        1.693,
        2.059,
        3.078,
        3.931,
    ]
    assert [round(c4_constant(n), 4) for n in (2, 5, 10, 25)] == [0.7979, 0.9400, 0.9727, 0.9896]


@pytest.mark.parametrize(
    "label, shape, kw",
    [
        ("rbar", (25, 5), {}),
        ("moving range", (60,), {}),
        ("overall", (60,), {"sigma_method": "overall"}),
    ],
)
def test_interval_coverage_by_simulation(label, shape, kw):
    rng = np.random.default_rng(20240611)
    reps, mu, sig, lsl, usl = 1500, 0.003, 0.01, -0.05, 0.05
    cp_true = (usl - lsl) / (6 * sig)
    cpk_true = min(usl - mu, mu - lsl) / (3 * sig)
    hit_cp = hit_cpk = 0
    for _ in range(reps):
        r = capability(
            rng.normal(mu, sig, shape), lsl, usl, options=CapabilityOptions(bayes=False, **kw)
        )
        hit_cp += cp_true in r.cp_ci
        hit_cpk += cpk_true in r.cpk_ci
    mc = 3 * math.sqrt(0.95 * 0.05 / reps)  # 3 Monte Carlo standard errors: 0.017
    assert abs(hit_cp / reps - 0.95) < mc, (label, hit_cp / reps)
    assert abs(hit_cpk / reps - 0.95) < mc, (label, hit_cpk / reps)


def test_qcc_degrees_of_freedom_undercover_with_moving_ranges():
    rng = np.random.default_rng(7)
    hits = {"piecs": 0, "qcc": 0}
    for _ in range(800):
        x = rng.normal(0.0, 0.01, 60)
        for conv in hits:
            opts = CapabilityOptions(convention=conv, bayes=False)
            hits[conv] += 1.0 in capability(x, -0.03, 0.03, options=opts).cp_ci
    assert hits["qcc"] / 800 < 0.92 < hits["piecs"] / 800


def test_bayes_probability_and_gauge_subtraction():
    rng = np.random.default_rng(11)
    x = rng.normal(0.0, 0.004, 80)
    opts = CapabilityOptions(sigma_method="overall", n_draws=200_000, seed=1)
    r0 = capability(x, -0.02, 0.02, options=opts)
    r1 = capability(x, -0.02, 0.02, gauge_sd=0.002, options=opts)
    assert r1.sigma_overall == pytest.approx(math.sqrt(r0.sigma_overall**2 - 0.002**2))
    assert r1.cp > r0.cp and r1.bayes.p_cpk_above > r0.bayes.p_cpk_above
    # effective df after subtraction: nu * (sigma_p^2 / sigma^2)^2
    ratio = r1.sigma_overall**2 / r0.sigma_overall**2
    assert r1.df_overall == pytest.approx(79 * ratio**2)
    with pytest.raises(AnalysisError, match="gauge variance"):
        capability(x, -0.02, 0.02, gauge_sd=0.01, options=CapabilityOptions(n_draws=200_000))


def test_predicted_capability_after_centering():
    rng = np.random.default_rng(5)
    x = rng.normal(0.006, 0.002, 50)  # off-centre: Cpk well below Cp
    r = capability(
        x, -0.01, 0.01, options=CapabilityOptions(sigma_method="overall", n_draws=200_000, seed=2)
    )
    opts = CapabilityOptions(n_draws=200_000, seed=2)
    p = predict_capability(r, options=opts)
    assert p.mean_after == pytest.approx(0.0, abs=1e-15)
    assert p.cpk == pytest.approx(r.pp, rel=1e-12)  # centred: Cpk = Cp
    assert p.cpk > 2 * r.ppk and p.p_cpk_above > r.bayes.p_cpk_above
    assert p.cpk_ci.lower < p.cpk < p.cpk_ci.upper
    # an uncertain shift widens the interval and lowers the probability
    q = predict_capability(r, u_offset=0.002, options=opts)
    assert q.cpk_ci.upper - q.cpk_ci.lower > p.cpk_ci.upper - p.cpk_ci.lower
    assert q.p_cpk_above < p.p_cpk_above
    half = predict_capability(r, options=replace(opts, gain=0.5))
    assert half.mean_after == pytest.approx(r.mean / 2)


def test_one_sided_specification():
    x = np.random.default_rng(3).normal(1.0, 0.1, 40)
    r = capability(x, usl=1.5, options=CapabilityOptions(bayes=False))
    assert math.isnan(r.cp) and math.isnan(r.cpm) and math.isnan(r.cpl)
    assert r.cpk == r.cpu == pytest.approx((1.5 - r.mean) / (3 * r.sigma_within))


def test_layouts_and_sigma_methods():
    rng = np.random.default_rng(9)
    x = rng.normal(10.0, 0.01, (20, 4))
    labels = np.repeat(np.arange(20), 4)
    a = sigma_within(x)
    b = sigma_within(x.ravel(), subgroups=labels)
    assert a.method == "rbar" and a.value == pytest.approx(b.value)
    s = sigma_within(x, method="sbar")
    expected = np.mean(np.std(x, axis=1, ddof=1)) / c4_constant(4)
    assert s.value == pytest.approx(expected)
    ragged = [x[0], x[1, :3], x[2]]
    assert sigma_within(ragged, method="pooled").df == 3 + 2 + 3
    with pytest.raises(InputError, match="equal size.*pooled"):
        sigma_within(ragged, method="rbar")
    assert sigma_within(x.ravel()).method == "mr"


def test_bad_input_is_named():
    with pytest.raises(InputError, match="value 2 is nan"):
        capability([1.0, 2.0, float("nan"), 3.0], 0.0, 4.0)
    with pytest.raises(InputError, match="lsl must be below usl"):
        capability([1.0, 2.0, 3.0], 4.0, 0.0)
    with pytest.raises(InputError, match="at least one specification limit"):
        capability([1.0, 2.0, 3.0])
    with pytest.raises(InputError, match="unknown convention"):
        capability([1.0, 2.0, 3.0], 0, 4, options=CapabilityOptions(convention="minitab"))


def test_stability_finds_a_step_change():
    rng = np.random.default_rng(42)
    x = rng.normal(0.0, 0.002, 40)
    x[22:] += 0.007  # a tool change: 3.5 sigma
    s = stability_check(x)
    assert not s.in_control
    assert any(i >= 22 for i in s.out_of_control)
    assert abs(s.step_index - 22) <= 1 and s.step_size == pytest.approx(0.007, abs=0.002)
    assert any("step" in r for r in s.reasons())
    # detection rate over many runs of a 3-sigma step
    found = 0
    for _ in range(300):
        y = rng.normal(0.0, 1.0, 40)
        y[20:] += 3.0
        found += any(i >= 20 for i in stability_check(y).out_of_control)
    assert found / 300 > 0.95


def test_stability_finds_a_drift():
    rng = np.random.default_rng(43)
    found = 0
    for _ in range(300):
        y = rng.normal(0.0, 1.0, 40) + np.linspace(0.0, 4.0, 40)  # tool wear
        found += not stability_check(y).in_control
    assert found / 300 > 0.95


def test_stable_process_has_few_false_alarms():
    rng = np.random.default_rng(44)
    charts, rule1, points = 0, 0, 0
    for _ in range(1000):
        s = stability_check(rng.normal(0.0, 1.0, 30))
        charts += not s.in_control
        rule1 += len(s.beyond_limits)
        points += s.n
    assert charts / 1000 < 0.16  # ~12 % of 30-point charts raise any alarm
    assert 0.001 < rule1 / points < 0.006  # ~0.27 % beyond 3 sigma


def test_stability_limits_and_rules_on_known_values():
    y = [0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 1.0, 0.0, 10.0]
    s = stability_check(y)
    assert s.mr_center == pytest.approx((8 * 1.0 + 10.0) / 9)  # eight ranges of 1, one of 10
    assert s.sigma == pytest.approx(s.mr_center / (2 / math.sqrt(math.pi)))
    assert s.mr_ucl == pytest.approx(3.2665 * s.mr_center, rel=1e-4)
    assert s.beyond_limits == (9,) and s.mr_beyond == (9,)
    run = stability_check([1.0] * 8 + [-1.0, 2.0, -3.0, 4.0, -5.0, 6.0], run_length=8)
    assert run.runs == ((0, 7),)
    trend = stability_check([5.0, 0.0, 1.0, 2.0, 3.0, 4.0, 5.0, 6.0, 0.0, 5.0])
    assert trend.trends == ((1, 7),)
    assert "OUT OF CONTROL" in repr(trend)


@pytest.mark.parametrize("k", [2.0, -2.0, -1.0])
def test_indices_do_not_change_with_the_drawn_scale(k):
    # tolerances as drawn (issue 15): a diameter is 2x the normal deviation, a bore's
    # diameter -2x, a face facing -Z -1x; scaling the values and the limits together
    # keeps Cp, Cpk, Pp, Ppk, Cpm (a negative scale swaps the limits, and Cpl with Cpu)
    rng = np.random.default_rng(15)
    y = rng.normal(0.003, 0.002, 30)
    lo, hi = -0.004, 0.010
    a = capability(y, lo, hi)
    b = capability(k * y, *sorted((k * lo, k * hi)))
    for name in ("cp", "cpk", "pp", "ppk", "cpm"):
        assert getattr(b, name) == pytest.approx(getattr(a, name), rel=1e-12), name
        ci_a, ci_b = tuple(getattr(a, f"{name}_ci")), tuple(getattr(b, f"{name}_ci"))
        assert ci_b == pytest.approx(ci_a, rel=1e-12), name
    lower, upper = ("cpu", "cpl") if k < 0 else ("cpl", "cpu")
    assert (b.cpl, b.cpu) == pytest.approx((getattr(a, lower), getattr(a, upper)), rel=1e-12)
    assert b.mean == pytest.approx(k * a.mean, rel=1e-12)
    assert b.sigma_within == pytest.approx(abs(k) * a.sigma_within, rel=1e-12)
    # Bayesian: Cp in closed form; Cpk from draws that mirror with the sign (Monte Carlo)
    assert b.bayes.cp == pytest.approx(a.bayes.cp, rel=1e-12)
    assert b.bayes.cpk == pytest.approx(a.bayes.cpk, rel=5e-3)
    opts = CapabilityOptions(n_draws=200_000)
    p = predict_capability(a, u_offset=2e-4, options=opts)
    q = predict_capability(b, u_offset=abs(k) * 2e-4, options=opts)
    assert q.cpk == pytest.approx(p.cpk, rel=1e-12)
    assert q.mean_after == pytest.approx(k * p.mean_after, abs=1e-15)


def test_capability_options_keep_the_defaults_of_both_entry_points():
    # one default each: those of the capability job (`capability_from_values`, the
    # study file's [capability] table); `capability` and `predict_capability` drew
    # 200,000 by default and are given that where it is wanted
    o = CapabilityOptions()
    assert (o.characteristic, o.confidence, o.threshold, o.sigma_method, o.convention) == (
        "mid", 0.95, 1.33, "auto", "piecs"
    )  # fmt: skip
    assert (o.subtract_gauge, o.gain, o.bayes, o.n_draws, o.seed) == (False, 1.0, True, 100_000, 0)
    assert (o.run_length, o.trend_length) == (8, 7)
    defaults = stability_check.__kwdefaults__
    assert (defaults["run_length"], defaults["trend_length"]) == (o.run_length, o.trend_length)
    with pytest.raises(FrozenInstanceError):
        o.n_draws = 10  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kw", "message"),
    [
        (
            {"confidence": 1.0},
            "capability option 'confidence': expected a number in (0, 1), got 1.0",
        ),
        (
            {"threshold": math.nan},
            "capability option 'threshold': expected a finite number, got nan",
        ),
        ({"gain": -0.5}, "capability option 'gain': expected a finite number >= 0, got -0.5"),
        ({"n_draws": 0}, "capability option 'n_draws': expected an integer >= 1, got 0"),
        ({"n_draws": 1e5}, "capability option 'n_draws': expected an integer >= 1, got 100000.0"),
        ({"seed": -1}, "capability option 'seed': expected an integer >= 0, got -1"),
        ({"run_length": 1}, "capability option 'run_length': expected an integer >= 2, got 1"),
        ({"bayes": "yes"}, "capability option 'bayes': expected true or false, got 'yes'"),
        (
            {"sigma_method": "range"},
            "capability option 'sigma_method': unknown sigma method 'range'",
        ),
        ({"convention": "minitab"}, "capability option 'convention': unknown convention 'minitab'"),
        (
            {"characteristic": "worst"},
            "unknown characteristic 'worst'; expected one of 'mid', 'start', 'end'",
        ),
    ],
)
def test_capability_options_refuse_a_bad_value_by_name(kw, message):
    with pytest.raises(InputError, match=re.escape(message)):
        CapabilityOptions(**kw)
