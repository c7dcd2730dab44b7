"""Compensation decisions: known-truth scenarios, exact rules, and realised loss."""

import math

import numpy as np
import pytest
from scipy import special

from piecs_bayes.decide import DecisionSettings, DrawnFeature, conformance, settings_from_spec
from piecs_bayes.decide import decide as _decide
from piecs_bayes.errors import InputError

TOL = (-0.010, 0.010)

_OPENING = {
    "compensate": "compensate with gain ",
    "do not compensate": "do not compensate: ",
    "measure more": "measure more: ",
}


def check_verdict_agrees_with_reasons(d):
    """The reasons end with the conclusion, which states the verdict (and nothing
    else does); the gain applied is the one stated; numbers in µm, null band shown."""
    assert d.reasons[-1].startswith(_OPENING[d.verdict]), (d.verdict, d.reasons[-1])
    for r in d.reasons[:-1]:
        assert not any(r.startswith(o) for o in _OPENING.values()), r
    text = " ".join(d.reasons)
    if d.verdict == "compensate":
        assert d.gain > 0 and d.reasons[-1].startswith(f"compensate with gain {d.gain:.2f}")
    else:
        assert d.gain == 0.0 and d.correction == 0.0 and "compensate with" not in text
    assert d.blocked == ("exceeds max_correction" in d.reasons[-1])
    assert "lowest" not in text and " mm" not in text and "+0 mm" not in text
    assert f"null band ±{d.drawn_null_band * 1e3:.1f} µm" in text


def decide(**kw):
    """`compensate.decide`, each result checked for agreement of verdict and reasons."""
    d = _decide(**kw)
    check_verdict_agrees_with_reasons(d)
    return d


def test_deviation_far_above_noise_is_compensated():
    d = decide(tolerance=TOL, mean=0.006, sd=0.0005, n_points=20, feature=DrawnFeature("D1"))
    assert d.verdict == "compensate"
    assert d.gain == pytest.approx(1.0, abs=1e-6)
    assert d.correction == pytest.approx(-0.006, abs=1e-8)
    assert d.u_correction == pytest.approx(0.0005)
    assert d.p_exceed > 0.999 and d.significant
    assert d.conformance_after.state == "conforms"
    assert d.best_action in ("full", "grubbs", "grubbs_prior", "bayes")
    assert d.reasons[-1].startswith("compensate with gain 1.00: the finish cut moves by -6.0 µm")
    assert "expected on nominal ± 1.0 µm, which conforms" in d.reasons[-1]


def test_deviation_inside_noise_is_not_compensated():
    d = decide(tolerance=TOL, mean=0.0005, sd=0.0008, n_points=20, feature=DrawnFeature("D2"))
    assert d.verdict == "do not compensate"
    assert d.gain == 0.0 and d.correction == 0.0
    assert d.p_exceed < 0.05
    assert d.conformance_before.state == "conforms"


def test_significance_is_required_without_a_prior():
    # 1.6 sigma above the null band: cheaper to adjust, but not significant
    d = decide(
        tolerance=TOL,
        mean=0.0035,
        sd=0.001,
        settings=DecisionSettings(adjustment_cost=0.0),
        n_points=20,
    )
    bayes = d.actions[-1]
    assert bayes.correction != 0.0  # the loss alone would adjust ...
    assert 0.5 < d.p_exceed < 0.95
    assert d.verdict == "do not compensate"  # ... but the evidence is too weak
    assert d.reasons[-1] == (
        "do not compensate: the deviation is not significant (without a prior, a correction "
        "must be significant, or it would chase noise)"
    )
    assert "expected cost: " in d.reasons[2] and "adjusting with gain 1.00" in d.reasons[2]
    assert "below the required 0.95: not significant" in d.reasons[1]


def test_reasons_are_stated_as_drawn():
    """The same decision on a diameter (drawn = 2 x normal): the verdict does not change,
    the reasons speak of the diameter in µm; a bore (scale -2) flips the signs."""
    kw = dict(tolerance=(-0.005, 0.005), mean=0.004, sd=0.0004, n_points=20)
    normal = decide(**kw)
    dia = decide(**kw, feature=DrawnFeature(coordinate="diameter", scale=2.0))
    bore = decide(**kw, feature=DrawnFeature(coordinate="diameter", scale=-2.0))
    assert normal.verdict == dia.verdict == bore.verdict == "compensate"
    assert dia.gain == normal.gain and dia.correction == normal.correction
    assert dia.drawn_tolerance == (-0.01, 0.01) and dia.drawn_estimate == 0.008
    assert dia.reasons[0].startswith("as measured +8.0 ± 1.6 µm on the diameter")
    assert "tolerance -10.0 … +10.0 µm" in dia.reasons[0]
    assert "the finish cut moves by -8.0 µm on the diameter" in dia.reasons[-1]
    assert bore.reasons[0].startswith("as measured -8.0 ± 1.6 µm on the diameter")
    assert "moves by +8.0 µm on the diameter" in bore.reasons[-1]
    row = dia.as_row()
    assert row["coordinate"] == "diameter" and row["deviation_drawn_mm"] == 0.008
    assert (row["tolerance_drawn_lower_mm"], row["tolerance_drawn_upper_mm"]) == (-0.01, 0.01)
    assert row["null_band_drawn_mm"] == pytest.approx(0.002)


def test_near_tolerance_with_large_uncertainty_measures_more():
    d = decide(tolerance=TOL, mean=0.009, sd=0.006, n_points=10, feature=DrawnFeature("D3"))
    assert d.verdict == "measure more"
    assert d.conformance_before.state == "ambiguous"
    assert d.more_points == 9
    assert "9 more probe points (10 -> 19" in d.reasons[-1]
    # with the extra points (u ~ 1/sqrt(n)) the same estimate is decided
    after = decide(tolerance=TOL, mean=0.009, sd=0.006 * math.sqrt(10 / 19), n_points=19)
    assert after.verdict == "compensate"
    one_less = decide(tolerance=TOL, mean=0.009, sd=0.006 * math.sqrt(10 / 18), n_points=18)
    assert one_less.verdict == "measure more"


def test_measure_more_without_point_count_says_so():
    d = decide(tolerance=TOL, mean=0.009, sd=0.006)
    assert d.verdict == "measure more" and d.more_points is None
    assert "give n_points" in d.reasons[-1]


def test_a_correction_above_the_limit_is_blocked():
    d = decide(tolerance=TOL, mean=0.05, sd=0.001, n_points=12)
    assert d.verdict == "do not compensate" and d.blocked
    assert "exceeds max_correction, the largest allowed (20.0 µm)" in d.reasons[-1]
    assert all(a.blocked for a in d.actions if a.correction != 0.0)


def test_one_shot_rule_from_the_design():
    # quadratic loss only: adjust iff m^2 > s_A^2 + C_A/k
    k, s_a, c_a = 1.0e4, 0.001, 0.03
    threshold = math.sqrt(s_a**2 + c_a / k)  # 0.002
    st = DecisionSettings(
        loss_k=k,
        adjustment_sd=s_a,
        adjustment_cost=c_a,
        out_of_tolerance_cost=0.0,
        require_significance=False,
    )
    for m, adjusts in ((0.98 * threshold, False), (1.02 * threshold, True)):
        d = decide(tolerance=(-1.0, 1.0), mean=m, sd=1e-4, settings=st)
        assert (d.actions[-1].correction != 0.0) is adjusts, m
        full, none = d.actions[1], d.actions[0]
        assert full.expected_loss - none.expected_loss == pytest.approx(
            k * (s_a**2 - m**2) + c_a, rel=1e-9
        )


def test_bayes_gain_equals_grubbs_prior_shrinkage():
    # quadratic loss, no costs: the Bayes correction is minus the posterior mean
    s_d, u = 0.003, 0.002
    st = DecisionSettings(prior_sd=s_d, adjustment_cost=0.0, out_of_tolerance_cost=0.0, loss_k=1.0)
    d = decide(tolerance=TOL, mean=0.004, sd=u, settings=st)
    shrink = 1.0 / (1.0 + u**2 / s_d**2)
    names = {a.name: a for a in d.actions}
    assert names["grubbs_prior"].gain == pytest.approx(shrink)
    assert names["bayes"].gain == pytest.approx(shrink, abs=1e-6)
    assert d.posterior_mean == pytest.approx(0.004 * shrink)
    assert d.verdict == "compensate" and d.gain == pytest.approx(shrink, abs=1e-6)
    # Grubbs' harmonic rule for the 3rd adjustment: -y/3, prior form -y/(3 + u^2/s_d^2)
    d3 = decide(tolerance=TOL, mean=0.004, sd=u, settings=st, run_index=3)
    names = {a.name: a for a in d3.actions}
    assert names["grubbs"].gain == pytest.approx(1 / 3)
    assert names["grubbs_prior"].gain == pytest.approx(1 / (3 + u**2 / s_d**2))


def test_samples_agree_with_mean_and_sd():
    rng = np.random.default_rng(0)
    draws = rng.normal(0.006, 0.0005, 20000)
    a = decide(tolerance=TOL, samples=draws)
    b = decide(tolerance=TOL, mean=float(draws.mean()), sd=float(draws.std(ddof=1)))
    assert a.verdict == b.verdict == "compensate"
    assert a.p_exceed == pytest.approx(b.p_exceed, abs=1e-3)
    assert a.correction == pytest.approx(b.correction, abs=1e-5)
    for x, y in zip(a.actions, b.actions, strict=True):
        assert x.expected_loss == pytest.approx(y.expected_loss, rel=0.05)


def test_iso_14253_conformance():
    c = conformance(0.007, 0.001, TOL)  # U = 0.002: acceptance [-0.008, 0.008]
    assert c.state == "conforms" and c.acceptance == pytest.approx((-0.008, 0.008))
    assert c.p_conform == pytest.approx(special.ndtr(3.0) - special.ndtr(-17.0))
    assert conformance(0.009, 0.001, TOL).state == "ambiguous"
    assert conformance(0.0125, 0.001, TOL).state == "does not conform"
    assert conformance(0.0, 0.006, TOL).acceptance[0] > 0.0  # empty zone: U too large
    assert conformance(0.0, 0.006, TOL).state == "ambiguous"


def test_settings_from_spec_validates_keys_and_values():
    st = settings_from_spec({"null_band": 0.001, "feedback_gain": 0.7, "parts_per_decision": 5})
    assert st.null_band == 0.001 and st.feedback_gain == 0.7 and st.parts_per_decision == 5
    assert settings_from_spec(None) == DecisionSettings()
    with pytest.raises(InputError, match=r"unknown decision setting 'nul_band' \(value 0.001\)"):
        settings_from_spec({"nul_band": 0.001})
    with pytest.raises(
        InputError, match=r"'feedback_gain': expected a number in \(0, 1\], got 1.5"
    ):
        settings_from_spec({"feedback_gain": 1.5})
    with pytest.raises(InputError, match=r"study.toml: decision setting 'prior_sd'.*got -0.1"):
        settings_from_spec({"prior_sd": -0.1}, file="study.toml")
    with pytest.raises(InputError, match="'parts_per_decision': expected an integer >= 1"):
        settings_from_spec({"parts_per_decision": 2.5})
    with pytest.raises(InputError, match="'adjustment_cost'.*got True"):
        settings_from_spec({"adjustment_cost": True})


def test_bad_arguments_are_named():
    with pytest.raises(InputError, match="feature 'F7'.*sd must be a finite number > 0"):
        decide(tolerance=TOL, mean=0.0, sd=0.0, feature=DrawnFeature("F7"))
    with pytest.raises(InputError, match="lower < upper"):
        decide(tolerance=(0.01, -0.01), mean=0.0, sd=0.001)
    with pytest.raises(InputError, match="either mean and sd or samples"):
        decide(tolerance=TOL, mean=0.0, sd=0.001, samples=[0.0, 0.1])


def _realised_loss(delta, c, st, tol):
    """Loss actually suffered for true deviations `delta` and corrections `c`."""
    lo, hi = tol
    k = st.out_of_tolerance_cost / ((hi - lo) / 2) ** 2
    adj = c != 0.0
    d = delta + c
    tau = np.sqrt(st.process_sd**2 + st.adjustment_sd**2 * adj)
    p_out = special.ndtr((lo - d) / tau) + special.ndtr((d - hi) / tau)
    return k * (d**2 + tau**2) + st.out_of_tolerance_cost * p_out + st.adjustment_cost * adj


@pytest.mark.parametrize(
    "s_d, u, extra",
    [
        (0.005, 0.002, {}),  # deviations mostly far above the noise
        (0.003, 0.002, {}),  # comparable
        (0.004, 0.002, {"adjustment_sd": 0.001, "adjustment_cost": 0.2}),  # costly changes
    ],
)
def test_realised_loss_no_worse_than_best_fixed_policy(s_d, u, extra):
    """Deviations drawn from the prior, measured with known sd; a 'measure more'
    verdict takes the extra points (new, smaller noise) and decides again."""
    rng = np.random.default_rng(12345)
    st = DecisionSettings(prior_sd=s_d, process_sd=0.002, **extra)
    runs, n = 1000, 10
    delta = rng.normal(0.0, s_d, runs)
    y = delta + rng.normal(0.0, u, runs)
    chosen = np.zeros(runs)
    for i in range(runs):
        d = decide(tolerance=TOL, mean=y[i], sd=u, settings=st, n_points=n)
        if d.verdict == "measure more" and d.more_points:
            u2 = u * math.sqrt(n / (n + d.more_points))
            y2 = delta[i] + rng.normal(0.0, u2)
            d = decide(tolerance=TOL, mean=y2, sd=u2, settings=st, n_points=n + d.more_points)
        chosen[i] = d.correction
    fixed = {
        "none": np.zeros(runs),
        "full": -y,
        "fraction": -st.feedback_gain * y,
    }
    loss = _realised_loss(delta, chosen, st, TOL)
    best = min(fixed, key=lambda p: _realised_loss(delta, fixed[p], st, TOL).mean())
    diff = loss - _realised_loss(delta, fixed[best], st, TOL)  # paired: same deviations
    se = diff.std(ddof=1) / math.sqrt(runs)
    assert diff.mean() <= 2 * se, (best, diff.mean(), se)


def test_best_action_ties_to_rounding_go_to_the_first_listed():
    """`bayes` at gain 1 is `full`: a last-bit difference must not flip the choice."""
    from types import SimpleNamespace as A

    from piecs_bayes.decide._decision import _best_action

    loss = 0.06235607048
    acts = [A(name="none", expected_loss=2.0), A(name="full", expected_loss=loss),
            A(name="bayes", expected_loss=loss * (1 - 2e-16))]  # fmt: skip
    assert _best_action(acts) == "full"
    acts[-1] = A(name="bayes", expected_loss=loss * (1 - 1e-6))
    assert _best_action(acts) == "bayes"


def test_more_points_grow_the_degrees_of_freedom():
    """A line from n = 5 points has dof = n - 2 = 3; with n' points it has n' - 2, and
    the count of more points is the smallest n' - n that a direct decision with sd
    * sqrt(n / n') and dof n' - 2 decides (it kept dof = 3: 15 more points, not 6)."""
    n, p, mean, sd = 5, 2, 0.009, 0.006
    d = decide(tolerance=TOL, mean=mean, sd=sd, n_points=n, dof=float(n - p))
    assert d.verdict == "measure more"

    def decided(n_new):
        direct = decide(tolerance=TOL, mean=mean, sd=sd * math.sqrt(n / n_new), dof=n_new - p)
        return direct.verdict != "measure more"

    first = next(k for k in range(n + 1, 50 * n) if decided(k))
    assert d.more_points == first - n
    fixed = decide(tolerance=TOL, mean=mean, sd=sd * math.sqrt(n / first), dof=float(n - p))
    assert fixed.verdict == "measure more"  # at the old fixed dof it was not decided yet


def test_drawn_feature_defaults_and_refusal():
    """`DrawnFeature` holds what `decide` took as `feature`, `coordinate`, `scale`, with
    the same defaults; a scale that is not a finite number is refused."""
    assert DrawnFeature() == DrawnFeature(None, "normal", 1.0)
    d = _decide(tolerance=TOL, mean=0.004, sd=0.0015)
    assert (d.feature, d.coordinate, d.scale) == (None, "normal", 1.0)
    d = _decide(tolerance=TOL, mean=0.004, sd=0.0015, feature=DrawnFeature("D9", "diameter", 2))
    assert (d.feature, d.coordinate, d.scale) == ("D9", "diameter", 2.0)
    with pytest.raises(InputError, match="feature 'D9'.*scale must be a finite number, got nan"):
        DrawnFeature("D9", "diameter", float("nan"))


@pytest.mark.parametrize("mean", [0.004, 0.0085, 0.012, -0.0095])
def test_each_conformity_decision_carries_its_specific_risk(mean):
    """The decision on the feature as measured (ISO 14253-1's acceptance zone, the
    tolerance less U): accepted, the consumer's risk is P(out | data) = 1 - p_conform;
    rejected, the producer's risk is P(in | data) = p_conform (JCGM 106, 9.3). After
    the correction the same from conformance_after. Closed form: the normal CDF."""
    from scipy.stats import norm

    d = decide(tolerance=TOL, mean=mean, sd=0.0008, n_points=20)
    for when, c in (("before", d.conformance_before), ("after", d.conformance_after)):
        r = d.risk(when)
        assert r.acceptance == pytest.approx(c.acceptance, abs=1e-15)
        inside = c.acceptance[0] <= c.value <= c.acceptance[1]
        p_in = norm.cdf((TOL[1] - c.value) / c.u) - norm.cdf((TOL[0] - c.value) / c.u)
        assert r.decision == ("accept" if inside else "reject")
        if inside:
            assert r.specific_consumer_risk == pytest.approx(1 - p_in, rel=1e-9, abs=1e-15)
            assert r.specific_producer_risk == 0.0
        else:
            assert r.specific_producer_risk == pytest.approx(p_in, rel=1e-9, abs=1e-15)
            assert r.specific_consumer_risk == 0.0
        assert r.specific_consumer_risk + r.specific_producer_risk == pytest.approx(
            (1 - c.p_conform) if inside else c.p_conform, rel=1e-9, abs=1e-15
        )
    row = d.as_row()
    assert row["decision_before"] == d.risk("before").decision
    assert row["consumer_risk_after"] == d.risk("after").specific_consumer_risk
