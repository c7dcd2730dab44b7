"""Conformity risk (JCGM 106): specific and global risks and guard bands, against closed
forms (Owen's T), suncal (Sandia PSL) and simulated parts.

suncal's conventions, as read in suncal 1.7.1 (`suncal/risk/`):

- `risk.specific_risk(dist, LL, UL).total` is P(measurand outside [LL, UL]) for `dist`,
  the distribution of the measurand given the measured value: our `p_nonconforming`.
  `RiskModel.calculate().specific` is that probability when the measured value
  (the median of its measurement distribution) lies in the acceptance interval
  `[LL + GBL, UL - GBU]` (closed; `specific_accept` True), else P(inside the tolerance):
  JCGM 106's specific consumer's risk of an accepted item and producer's risk of a
  rejected one.
- `risk.PFA` / `risk.PFR` (Simpson's rule, 5001 nodes) are *joint* (unconditional)
  probabilities, P(out of tolerance and accepted) and P(in tolerance and rejected);
  `PFA_conditional` is P(out of tolerance | accepted). The test distribution is moved
  so that its median is the true value (measured = true + error).
- Guard bands are offsets from the limits (`GBL`, `GBU`: acceptance `[LL + GBL,
  UL - GBU]`); `guardband_tur` returns a guard band *factor* GBF of the half tolerance
  of a centred two-sided tolerance, `A = GBF * T`, i.e. `w = T (1 - GBF)`, with
  TUR = T / (2 u) (half tolerance over U at k = 2). `guardband.target` solves PFA(w) =
  target by `fsolve` from w = 0.1 (absolute): we call it in µm.
- suncal's Dobbert, 4:1 and `guardband.target` rules may return a negative guard band
  (acceptance wider than the tolerance) where the target is met without one; ours
  return 0 there.
"""

import json
import math
import subprocess
import sys
import warnings

import numpy as np
import pytest
from scipy import special, stats

from piecs_bayes.decide import (
    ConformityRisk,
    GuardBand,
    ProcessPrior,
    conformance,
    conformity_risk,
    global_risks,
    guard_band_width,
    p_nonconforming,
    tur,
)
from piecs_bayes.errors import InputError

INF = math.inf
UM = 1e3  # suncal is called in µm (its root finders start at an absolute 0.1)

#: the demo's budget (tests/data/golden/demo/decisions.json): the normal deviation of
#: dia_24 (Ø24 ±0.02, i.e. ±10 µm on the radius) and of the taper (±20 µm), u and dof
DIA_24 = dict(tol=(-0.010, 0.010), value=0.023769698092279662, u=0.0016559357726155432,
              dof=156.10633226540938)  # fmt: skip
TAPER_U = 0.0017361070915782096

#: name, tolerance (mm), process mean and sd (mm), u of the measurement (mm). The demo's
#: characteristics: u 1.5-3 µm on ±20 µm (TUR 6.7-3.3).
CASES = [
    ("demo dia_24 budget", DIA_24["tol"], 0.002, 0.004, DIA_24["u"]),
    ("demo taper budget", (-0.020, 0.020), 0.005, 0.008, TAPER_U),
    ("centred TUR 4", (-0.020, 0.020), 0.0, 0.008, 0.0025),
    ("centred TUR 2", (-0.020, 0.020), 0.0, 0.008, 0.005),
    ("centred TUR 1.5", (-0.020, 0.020), 0.0, 0.010, 0.020 / 3),
    ("off-centre u 1.5 um", (-0.020, 0.020), 0.006, 0.007, 0.0015),
    ("off-centre u 3 um", (-0.020, 0.020), -0.004, 0.009, 0.003),
    ("poor process TUR 2", (-0.020, 0.020), 0.003, 0.012, 0.005),
    ("asymmetric tolerance", (-0.030, 0.0), -0.012, 0.006, 0.002),
    ("upper limit only", (-INF, 0.020), 0.005, 0.006, 0.002),
    ("lower limit only", (0.0, INF), 0.010, 0.004, 0.0025),
]
IDS = [c[0] for c in CASES]


def guard_bands(u):
    """Guard bands each case is checked with (mm): none, U = 2u (ISO 14253-1), 1 µm."""
    return (0.0, 2.0 * u, 0.001)


@pytest.fixture(scope="module")
def suncal_risk():
    with warnings.catch_warnings():  # suncal imports scipy.odr, deprecated in scipy 1.17
        warnings.simplefilter("ignore", DeprecationWarning)
        return pytest.importorskip("suncal.risk")


@pytest.fixture(scope="module")
def suncal_model():
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)
        model = pytest.importorskip("suncal.risk.risk_model")
        dists = pytest.importorskip("suncal.common.distributions")
    return model.RiskModel, dists.get_distribution


# ------------------------------------------------------------------ exact reference


def _phi2(h, k, rho):
    """P(X < h, Y < k) for a standard bivariate normal with correlation rho (Owen 1956:
    Owen's T function); h, k nonzero or infinite."""
    if h == -INF or k == -INF:
        return 0.0
    if h == INF:
        return float(special.ndtr(k))
    if k == INF:
        return float(special.ndtr(h))
    r = math.sqrt(1.0 - rho * rho)
    beta = 0.0 if h * k > 0 else 0.5
    return (
        0.5 * special.ndtr(h) + 0.5 * special.ndtr(k)
        - special.owens_t(h, (k - rho * h) / (h * r))
        - special.owens_t(k, (h - rho * k) / (k * r))
        - beta
    )  # fmt: skip


def exact_global(tol, acc, mean, sd, u):
    """R_C, R_P as rectangle probabilities of (true value, measured value), jointly
    normal: x ~ N(mean, sd^2), y = x + N(0, u^2), corr(x, y) = sd / sqrt(sd^2 + u^2)."""
    sy = math.hypot(sd, u)
    rho = sd / sy

    def rect(x1, x2, y1, y2):
        h1, h2 = (x1 - mean) / sd, (x2 - mean) / sd
        k1, k2 = (y1 - mean) / sy, (y2 - mean) / sy
        return _phi2(h2, k2, rho) - _phi2(h1, k2, rho) - _phi2(h2, k1, rho) + _phi2(h1, k1, rho)

    (tl, tu), (al, au) = tol, acc
    consumer = rect(-INF, tl, al, au) + rect(tu, INF, al, au)
    producer = rect(tl, tu, -INF, al) + rect(tl, tu, au, INF)
    return consumer, producer


# ------------------------------------------------------------------ global risks


@pytest.mark.parametrize("name, tol, mean, sd, u", CASES, ids=IDS)
def test_global_risks_equal_the_bivariate_normal_closed_form(name, tol, mean, sd, u):
    process = ProcessPrior(mean, sd)
    for w in guard_bands(u):
        acc = (tol[0] + w, tol[1] - w)
        rc, rp = global_risks(tol, acc, u=u, process=process)
        ref_c, ref_p = exact_global(tol, acc, mean, sd, u)
        assert rc == pytest.approx(ref_c, abs=1e-12, rel=1e-9), (name, w)
        assert rp == pytest.approx(ref_p, abs=1e-12, rel=1e-9), (name, w)


@pytest.mark.parametrize(
    "mean, sd, u",
    [(0.001, 0.010, 1e-6), (0.001, 0.010, 1e-5), (0.003, 0.001, 0.020), (0.019, 0.0005, 1e-4),
     (0.0, 0.050, 0.002), (0.030, 0.004, 0.002)],
)  # fmt: skip
def test_global_risks_stay_exact_at_extreme_ratios(mean, sd, u):
    """u/sd from 1e-4 (a step in P(accept | x) a few nm wide) to 20, a process wider
    than the tolerance and one centred beyond a limit; relaxed and guarded acceptance."""
    tol, process = (-0.020, 0.020), ProcessPrior(mean, sd)
    for w in (-0.002, 0.0, 0.003):
        acc = (tol[0] + w, tol[1] - w)
        got = global_risks(tol, acc, u=u, process=process)
        ref = exact_global(tol, acc, mean, sd, u)
        assert got == pytest.approx(ref, abs=1e-12, rel=1e-9), w


@pytest.mark.parametrize("name, tol, mean, sd, u", CASES, ids=IDS)
def test_global_risks_match_suncal(name, tol, mean, sd, u, suncal_risk):
    # suncal's PFA/PFR are joint probabilities (see the module docstring); measured:
    # max |difference| 1.5e-14 (PFA), 2.1e-14 (PFR) over these cases
    process = ProcessPrior(mean, sd)
    d_proc, d_test = stats.norm(mean * UM, sd * UM), stats.norm(0.0, u * UM)
    for w in guard_bands(u):
        rc, rp = global_risks(tol, (tol[0] + w, tol[1] - w), u=u, process=process)
        args = (d_proc, d_test, tol[0] * UM, tol[1] * UM, w * UM, w * UM)
        assert abs(rc - suncal_risk.PFA(*args)) < 1e-6, (name, w)
        assert abs(rp - suncal_risk.PFR(*args)) < 1e-6, (name, w)


@pytest.mark.parametrize("dof", [3, 5, 12])
def test_global_risks_with_student_t_errors_match_suncal(dof, suncal_risk):
    tol, process, u = (-0.020, 0.020), ProcessPrior(0.003, 0.008), 0.003
    d_proc = stats.norm(3.0, 8.0)
    d_test = stats.t(df=dof, loc=0.0, scale=u * UM)
    for w in (0.0, 0.002):
        rc, rp = global_risks(tol, (tol[0] + w, tol[1] - w), u=u, process=process, dof=dof)
        args = (d_proc, d_test, -20.0, 20.0, w * UM, w * UM)
        assert abs(rc - suncal_risk.PFA(*args)) < 1e-6
        assert abs(rp - suncal_risk.PFR(*args)) < 1e-6
    normal = global_risks(tol, tol, u=u, process=process)
    heavy = global_risks(tol, tol, u=u, process=process, dof=dof)
    assert heavy.consumer > normal.consumer and heavy.producer > normal.producer


def test_global_risks_trade_one_for_the_other():
    tol, process, u = (-0.020, 0.020), ProcessPrior(0.002, 0.009), 0.003
    ws = np.linspace(-0.002, 0.010, 13)
    risks = [global_risks(tol, (tol[0] + w, tol[1] - w), u=u, process=process) for w in ws]
    consumer = [r.consumer for r in risks]
    producer = [r.producer for r in risks]
    assert np.all(np.diff(consumer) < 0) and np.all(np.diff(producer) > 0)
    # an empty acceptance zone accepts nothing: R_C = 0, R_P = P(in tolerance)
    rc, rp = global_risks(tol, (0.0, 0.0), u=u, process=process)
    p_in = special.ndtr((0.020 - 0.002) / 0.009) - special.ndtr((-0.020 - 0.002) / 0.009)
    assert rc == 0.0 and rp == pytest.approx(p_in, abs=1e-12)


# ------------------------------------------------------------------ simulated parts


def _simulate(tol, acc, mean, sd, u, seed, dof=INF, n=100_000):
    rng = np.random.default_rng(seed)
    x = rng.normal(mean, sd, n)
    e = rng.standard_t(dof, n) if math.isfinite(dof) else rng.standard_normal(n)
    y = x + u * e
    accepted = (y >= acc[0]) & (y <= acc[1])
    inside = (x >= tol[0]) & (x <= tol[1])
    return np.count_nonzero(~inside & accepted), np.count_nonzero(inside & ~accepted), n


def _z(count, n, p):
    return (count / n - p) / math.sqrt(p * (1.0 - p) / n)


MC_CASES = [
    ("centred TUR 2", (-0.020, 0.020), 0.0, 0.008, 0.005, INF),
    ("off-centre u 3 um", (-0.020, 0.020), -0.004, 0.009, 0.003, INF),
    ("poor process TUR 2", (-0.020, 0.020), 0.003, 0.012, 0.005, INF),
    ("upper limit only", (-INF, 0.020), 0.005, 0.006, 0.002, INF),
    ("student t, 4 dof", (-0.020, 0.020), 0.003, 0.010, 0.004, 4.0),
]


@pytest.mark.parametrize("case", range(len(MC_CASES)), ids=[c[0] for c in MC_CASES])
def test_global_risks_agree_with_simulated_parts(case):
    """Over 100,000 simulated parts the fractions accepted out of tolerance and
    rejected in tolerance are within 3 binomial sds of R_C, R_P, with and without the
    guard band that cuts the consumer's risk to a third. Each (case, guard band) has its
    own seed."""
    name, tol, mean, sd, u, dof = MC_CASES[case]
    process = ProcessPrior(mean, sd)
    rc0 = global_risks(tol, tol, u=u, process=process, dof=dof).consumer
    gb = GuardBand("target", target=rc0 / 3.0)
    w_target = guard_band_width(tol, gb, u=u, process=process, dof=dof)
    assert w_target > 0
    for j, w in enumerate((0.0, w_target)):
        acc = (tol[0] + w, tol[1] - w)
        rc, rp = global_risks(tol, acc, u=u, process=process, dof=dof)
        fa, fr, n = _simulate(tol, acc, mean, sd, u, seed=(2012, case, j), dof=dof)
        z_c, z_p = _z(fa, n, rc), _z(fr, n, rp)
        print(f"{name}, w {w * 1e3:.3f} µm: z consumer {z_c:+.2f}, producer {z_p:+.2f}")
        assert abs(z_c) < 3.0, (name, w, fa / n, rc)
        assert abs(z_p) < 3.0, (name, w, fr / n, rp)


# ------------------------------------------------------------------ specific risk


@pytest.mark.parametrize("dof", [INF, 4.0, 30.0, DIA_24["dof"]])
def test_specific_risk_matches_suncal(dof, suncal_risk):
    # suncal's specific_risk(...).total: P(measurand outside the tolerance | value)
    tol, u = (-0.020, 0.020), 0.0025
    for y in np.linspace(-0.030, 0.030, 61):
        ours = p_nonconforming(tol, value=float(y), u=u, dof=dof)
        scale = dict(loc=y * UM, scale=u * UM)
        dist = stats.norm(**scale) if math.isinf(dof) else stats.t(df=dof, **scale)
        theirs = suncal_risk.specific_risk(dist, -20.0, 20.0).total
        assert abs(ours - theirs) < 1e-9, y
    one = p_nonconforming((None, 0.020), value=0.017, u=u)
    assert one == pytest.approx(special.ndtr((0.017 - 0.020) / u), abs=1e-15)


@pytest.mark.parametrize("name, tol, mean, sd, u", CASES[:9], ids=IDS[:9])
def test_specific_accept_and_reject_risks_match_suncal_model(name, tol, mean, sd, u, suncal_model):
    """With a guard band: the decision, and the specific consumer's risk of an accepted
    value or producer's risk of a rejected one, as suncal's RiskModel states them."""
    risk_model, dist = suncal_model
    w = 2.0 * u
    process = ProcessPrior(mean, sd)
    for y in np.linspace(tol[0] - 3 * u, tol[1] + 3 * u, 23):
        r = conformity_risk(tol, value=float(y), u=u, process=process,
                            guard_band=GuardBand("fixed", width=w))  # fmt: skip
        m = risk_model(dist("normal", loc=mean * UM, std=sd * UM),
                       dist("normal", loc=y * UM, std=u * UM),
                       (tol[0] * UM, tol[1] * UM), (w * UM, w * UM))  # fmt: skip
        s = m.calculate()
        assert (r.decision == "accept") == bool(s.specific_accept), y
        ours = r.specific_consumer_risk if r.decision == "accept" else r.specific_producer_risk
        assert abs(ours - s.specific) < 1e-9, y
        assert abs(r.global_consumer_risk - s.pfa) < 1e-6
        assert abs(r.global_producer_risk - s.pfr) < 1e-6


def test_specific_risk_agrees_with_the_verdicts_conformance_probability():
    """The demo's dia_24 as measured (+23.8 µm of normal deviation on ±10 µm, u 1.66 µm,
    156 dof): rejected, with the specific producer's risk equal to the verdict's
    P(conform) (`decide.conformance`, Student-t) to its last digits."""
    d = DIA_24
    r = conformity_risk(d["tol"], value=d["value"], u=d["u"], dof=d["dof"])
    c = conformance(d["value"], d["u"], d["tol"], dof=d["dof"])
    assert r.decision == "reject" and c.state == "does not conform"
    assert r.specific_producer_risk == pytest.approx(c.p_conform, rel=1e-9)
    assert 1e-15 < r.specific_producer_risk < 1e-13  # 2.1e-14, as decisions.json states
    for y in np.linspace(-0.014, 0.014, 29):
        p = p_nonconforming(d["tol"], value=float(y), u=d["u"], dof=d["dof"])
        c = conformance(float(y), d["u"], d["tol"], dof=d["dof"])
        assert p == pytest.approx(1.0 - c.p_conform, abs=1e-14)


def test_specific_risk_from_posterior_draws():
    tol, m, s = (-0.020, 0.020), 0.016, 0.003
    exact = p_nonconforming(tol, value=m, u=s)
    draws = np.random.default_rng(7).normal(m, s, 200_000)
    p = p_nonconforming(tol, samples=draws)
    assert abs(p - exact) < 3.0 * math.sqrt(exact * (1 - exact) / draws.size)
    r = conformity_risk(tol, samples=draws)
    assert r.estimate == pytest.approx(draws.mean()) and r.decision == "accept"
    assert r.u_measurement == pytest.approx(draws.std(ddof=1))
    assert r.p_nonconforming == p == r.specific_consumer_risk
    assert r.specific_producer_risk == 0.0


def test_specific_risk_is_tiny_far_inside_and_keeps_its_precision():
    # far from the limits the probability is a tail, not 1 - (almost 1)
    p = p_nonconforming((-0.020, 0.020), value=0.0, u=0.002)
    assert p == pytest.approx(2.0 * special.ndtr(-10.0), rel=1e-12)
    r = conformity_risk((-0.020, 0.020), value=0.030, u=0.001)
    assert r.decision == "reject"
    assert r.specific_producer_risk == pytest.approx(special.ndtr(-10.0), rel=1e-12)


# ------------------------------------------------------------------ guard bands


def _target_cases():
    out = []
    for name, tol, mean, sd, u in CASES:
        rc0 = global_risks(tol, tol, u=u, process=ProcessPrior(mean, sd)).consumer
        out.append((name, tol, mean, sd, u, 0.02 if rc0 > 0.02 else rc0 / 3.0))
    return out


@pytest.mark.parametrize("name, tol, mean, sd, u, target", _target_cases(), ids=IDS)
def test_guard_band_for_a_target_consumer_risk_matches_suncal(
    name, tol, mean, sd, u, target, suncal_risk
):
    # measured: max |w - suncal's| 2.0e-13 of the tolerance width (±20 µm: of 0.04 mm)
    process = ProcessPrior(mean, sd)
    w = guard_band_width(tol, GuardBand("target", target=target), u=u, process=process)
    d_proc, d_test = stats.norm(mean * UM, sd * UM), stats.norm(0.0, u * UM)
    theirs = suncal_risk.guardband.target(d_proc, d_test, tol[0] * UM, tol[1] * UM, target) / UM
    width = tol[1] - tol[0] if math.isfinite(tol[1] - tol[0]) else 0.040
    assert w > 0 and abs(w - theirs) < 1e-6 * width, (name, w, theirs)
    rc = global_risks(tol, (tol[0] + w, tol[1] - w), u=u, process=process).consumer
    assert rc == pytest.approx(target, abs=1e-11)


def test_default_target_is_two_percent_and_zero_when_the_tolerance_meets_it():
    tol = (-0.020, 0.020)
    poor = ProcessPrior(0.003, 0.012)  # R_C 2.4 % without a guard band
    r = conformity_risk(tol, u_measurement=0.005, process=poor, guard_band=GuardBand("target"))
    assert r.target_consumer_risk == 0.02 and r.guard_band > 0
    assert r.global_consumer_risk == pytest.approx(0.02, abs=1e-11)
    good = ProcessPrior(0.0, 0.008)  # R_C 0.28 %: no guard band needed
    r = conformity_risk(tol, u_measurement=0.0025, process=good, guard_band=GuardBand("target"))
    assert r.guard_band == 0.0 and r.acceptance == tol and r.global_consumer_risk < 0.02


@pytest.mark.parametrize("ratio", [1.2, 1.5, 2.0, 3.0, 4.0, 4.5])
def test_tur_rules_match_suncal(ratio, suncal_risk):
    # guardband_tur's factors GBF, as offsets w = T (1 - GBF); measured max |difference|
    # 2e-18 mm (RSS, Dobbert, RP-10, test95) and 2e-15 mm (4:1, root found)
    gt = suncal_risk.guardband_tur
    tol, process = (-0.020, 0.020), ProcessPrior(0.0, 0.008)
    u = 0.020 / (2.0 * ratio)
    assert tur(tol, u) == pytest.approx(ratio, rel=1e-14)
    itp = 1.0 - 2.0 * special.ndtr(-0.020 / 0.008)
    rules = {"rss": gt.rss, "dobbert": gt.dobbert, "rp10": gt.rp10, "test95": gt.test95,
             "4:1": lambda t: gt.four_to_1(t, itp)}  # fmt: skip
    for rule, factor in rules.items():
        w = guard_band_width(tol, GuardBand(rule), u=u, process=process)
        theirs = 0.020 * (1.0 - factor(ratio))
        assert abs(w - max(theirs, 0.0)) < 1e-6 * 0.040, (rule, w, theirs)


def test_tur_rules_never_widen_the_acceptance_zone():
    # suncal's Dobbert factor exceeds 1 above TUR 4.6 (M < 0), its 4:1 rule above TUR 4
    tol, process = (-0.020, 0.020), ProcessPrior(0.0, 0.008)
    for rule in ("dobbert", "4:1", "rp10", "test95"):
        assert guard_band_width(tol, GuardBand(rule), u=0.020 / 12, process=process) == 0.0
    r = conformity_risk(tol, u_measurement=0.020 / 6, process=process, guard_band=GuardBand("4:1"))
    four = global_risks(tol, tol, u=0.020 / 8, process=process).consumer
    assert r.target_consumer_risk == pytest.approx(four, rel=1e-14)
    assert r.global_consumer_risk == pytest.approx(four, abs=1e-11)


def test_a_guard_band_cannot_reach_the_target_within_max_width():
    tol, process = (-0.020, 0.020), ProcessPrior(0.003, 0.012)
    gb = GuardBand("target", target=0.005, max_width=0.001)
    with pytest.raises(InputError, match="no guard band up to 1 µm reaches") as e:
        guard_band_width(tol, gb, u=0.005, process=process)
    assert e.value.value == 0.001
    with pytest.raises(InputError, match="needs w = 10 µm, more than the 1 µm allowed"):
        guard_band_width(tol, GuardBand("test95", max_width=0.001), u=0.005)
    with pytest.raises(InputError, match="needs w = 25 µm, more than the 20 µm"):
        guard_band_width(tol, GuardBand("test95"), u=0.0125)  # TUR 0.8


# ------------------------------------------------------------------ the result


def test_conformity_risk_of_an_accepted_and_a_rejected_part():
    tol, process, u = (-0.020, 0.020), ProcessPrior(0.006, 0.007), 0.0015
    gb = GuardBand("fixed", width=2.0 * u)
    ok = conformity_risk(tol, value=0.016, u=u, process=process, guard_band=gb)
    assert ok.decision == "accept" and ok.acceptance == pytest.approx((-0.017, 0.017))
    assert ok.specific_consumer_risk == pytest.approx(special.ndtr(-4.0 / 1.5), rel=1e-12)
    assert ok.specific_producer_risk == 0.0
    assert ok.tur == pytest.approx(0.020 / 0.003)
    bad = conformity_risk(tol, value=0.0175, u=u, process=process, guard_band=gb)
    assert bad.decision == "reject" and bad.specific_consumer_risk == 0.0
    assert bad.specific_producer_risk == pytest.approx(1.0 - special.ndtr(-2.5 / 1.5))
    assert bad.global_consumer_risk == ok.global_consumer_risk
    assert isinstance(ok, ConformityRisk)
    text = repr(ok)
    assert "acceptance [-17.00, +17.00] µm" in text and "accept +16.00 µm" in text
    assert "global consumer's" in text


def test_as_dict_is_strict_json_with_one_sided_limits_as_null():
    r = conformity_risk((None, 0.020), value=0.012, u=0.002,
                        process=ProcessPrior(0.005, 0.006), guard_band=GuardBand("target"))  # fmt: skip
    d = r.as_dict()
    text = json.dumps(d, allow_nan=False)
    assert json.loads(text) == d
    assert d["tolerance_lower_mm"] is None and d["acceptance_lower_mm"] is None
    assert d["tur"] is None and d["rule"] == "target" and d["decision"] == "accept"
    assert "acceptance [-∞, +20.00] µm, w 0.00 µm" in repr(r)
    assert set(d) == {
        "rule", "decision", "estimate_mm", "tolerance_lower_mm", "tolerance_upper_mm",
        "acceptance_lower_mm", "acceptance_upper_mm", "guard_band_mm", "u_measurement_mm",
        "tur", "p_nonconforming", "specific_consumer_risk", "specific_producer_risk",
        "process_mean_mm", "process_sd_mm", "global_consumer_risk", "global_producer_risk",
        "target_consumer_risk",
    }  # fmt: skip
    bare = conformity_risk((-0.02, 0.02), value=0.0, u=0.002).as_dict()
    assert bare["global_consumer_risk"] is None and bare["process_sd_mm"] is None


def test_importing_decide_stays_light():
    code = "import sys, piecs_bayes.decide; print(any(m.startswith('scipy') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


# ------------------------------------------------------------------ bad input


@pytest.mark.parametrize(
    "call, match, value",
    [
        (lambda: p_nonconforming((-0.02, 0.02), value=0.0, u=0.0), "u must be a number > 0", 0.0),
        (lambda: p_nonconforming((-0.02, 0.02), value=0.0, u=-1e-3), "got -0.001", -1e-3),
        (lambda: ProcessPrior(0.0, 0.0), "process sd must be a number > 0, got 0.0", 0.0),
        (lambda: ProcessPrior(0.0, -0.004), "process sd", -0.004),
        (lambda: ProcessPrior(math.nan, 0.004), "process mean must be a finite", None),
        (lambda: p_nonconforming((0.02, -0.02), value=0.0, u=0.002), r"lower < upper, got \(0.02, -0.02\)", (0.02, -0.02)),
        (lambda: p_nonconforming((0.02, 0.02), value=0.0, u=0.002), "lower < upper", (0.02, 0.02)),
        (lambda: GuardBand("target", target=0.0), r"probability in \(0, 1\), got 0.0", 0.0),
        (lambda: GuardBand("target", target=1.0), r"probability in \(0, 1\), got 1.0", 1.0),
        (lambda: GuardBand("target", target=-0.02), "target consumer's risk", -0.02),
        (lambda: GuardBand("iso"), "unknown guard band rule 'iso'", "iso"),
        (lambda: GuardBand("fixed"), "give it with the rule 'fixed'", None),
        (lambda: GuardBand("target", width=0.001), "got rule 'target' and width 0.001", 0.001),
        (lambda: global_risks((-0.02, 0.02), (-0.02, 0.02), u=0.0, process=ProcessPrior(0, 0.01)), "u must be", 0.0),
        (lambda: guard_band_width((-0.02, 0.02), GuardBand("target"), u=0.002), "needs the process", None),
        (lambda: guard_band_width((None, 0.02), GuardBand("rss"), u=0.002), "two-sided tolerance", (-INF, 0.02)),
        (lambda: guard_band_width((-0.02, 0.02), GuardBand("rss"), u=0.01), "TUR > 1, got TUR 1", 1.0),
        (lambda: p_nonconforming((-0.02, 0.02), value=0.0, u=0.002, dof=0), "dof must be", 0),
        (lambda: p_nonconforming((-0.02, 0.02), samples=[0.0, 0.001], u=0.002), "not both", None),
    ],
)  # fmt: skip
def test_bad_input_is_named(call, match, value):
    with pytest.raises(InputError, match=match) as e:
        call()
    if value is not None:
        assert e.value.value == value
