"""Capability studies as drawn (issue 15): values, limits and indices on each feature's
`tolerance_on` (twice the normal deviation on a diameter, its sign per the outward
normal), against hand-computed Cp, Cpk, Pp, Ppk and a simulated run with known truth.
"""

import io
import json
import math
from pathlib import Path

import numpy as np
import pytest

import piecs_bayes.jobs as D
from piecs_bayes.capability import CapabilityOptions, d2_constant
from piecs_bayes.errors import InputError
from piecs_bayes.export.figures import capability_chart_figure
from piecs_bayes.export.tables import capability_csvs, capability_json, capability_text
from piecs_bayes.geometry import Profile, drawn_limits, drawn_scale, make_feature, profile_side
from piecs_bayes.io import load_study

BATCH = Path(__file__).resolve().parents[2] / "data" / "batch" / "study.toml"


def _profile(specs, internal=False) -> Profile:
    side = profile_side(specs, internal=internal)
    return Profile(tuple(make_feature(s, side) for s in specs))


# a shaft: Ø24 ±0.02 (scale +2), a shoulder facing -Z with Z -0.03/+0.05 (scale -1:
# its limits of the normal deviation are -0.05/+0.03), a taper ±0.02 along the normal
SHAFT = _profile(
    [
        {"id": "dia", "p0": (12.0, 0.0), "p1": (12.0, -20.0), "tolerance": (-0.02, 0.02),
         "tolerance_on": "diameter"},
        {"id": "face", "p0": (12.0, -20.0), "p1": (8.0, -20.0), "tolerance": (-0.03, 0.05),
         "tolerance_on": "length"},
        {"id": "taper", "p0": (8.0, -20.0), "p1": (10.0, -30.0), "tolerance": (-0.02, 0.02),
         "tolerance_on": "normal"},
    ]
)  # fmt: skip
# a bore: Ø20 -0.01/+0.03 (scale -2: more material is a smaller diameter)
BORE = _profile(
    [
        {"id": "bore", "p0": (10.0, 0.0), "p1": (10.0, -20.0), "tolerance": (-0.01, 0.03),
         "tolerance_on": "diameter"},
        {"id": "bottom", "p0": (10.0, -20.0), "p1": (6.0, -20.0), "tolerance": (-0.05, 0.05),
         "tolerance_on": "length"},
    ],
    internal=True,
)  # fmt: skip


def _hand(y, lo, hi) -> dict:
    """Cp, Cpk (moving-range sigma, d2(2) = 2/sqrt(pi)), Pp, Ppk by hand."""
    sw = np.mean(np.abs(np.diff(y))) / (2.0 / math.sqrt(math.pi))
    so = np.std(y, ddof=1)
    m = np.mean(y)
    return {
        "cp": (hi - lo) / (6 * sw),
        "cpk": min(m - lo, hi - m) / (3 * sw),
        "pp": (hi - lo) / (6 * so),
        "ppk": min(m - lo, hi - m) / (3 * so),
        "cpl": (m - lo) / (3 * sw),
        "cpu": (hi - m) / (3 * sw),
        "mean": m,
        "sigma_within": sw,
    }


def test_the_profiles_scales():
    assert [drawn_scale(f) for f in SHAFT.features] == [2.0, -1.0, 1.0]
    assert drawn_scale(BORE["bore"]) == -2.0
    assert SHAFT["face"].tolerance == pytest.approx((-0.05, 0.03))
    assert d2_constant(2) == pytest.approx(2.0 / math.sqrt(math.pi), rel=1e-15)


def test_indices_on_the_drawn_coordinate_match_hand_computation():
    rng = np.random.default_rng(15)
    truth = {"dia": (0.004, 0.0015), "face": (-0.006, 0.004), "taper": (0.002, 0.003)}
    delta = {f: rng.normal(m, s, 25) for f, (m, s) in truth.items()}
    cs = D.capability_from_values(delta, profile=SHAFT, options=CapabilityOptions(n_draws=20_000))
    assert {f: cs[f].coordinate for f in cs.features} == {
        "dia": "diameter", "face": "length", "taper": "normal"
    }  # fmt: skip
    for fid, y in delta.items():
        f, k = cs[fid], drawn_scale(SHAFT[fid])
        lo, hi = drawn_limits(SHAFT[fid])
        assert f.scale == k and f.tolerance == pytest.approx((lo, hi), abs=1e-15)
        np.testing.assert_allclose(f.values, k * y, rtol=0, atol=1e-15)
        np.testing.assert_allclose(f.normal_values, y, rtol=1e-15, atol=1e-18)
        want = _hand(k * y, lo, hi)
        c = f.capability
        assert (c.lsl, c.usl) == pytest.approx((lo, hi), abs=1e-15)
        for name in ("cp", "cpk", "pp", "ppk", "cpl", "cpu", "mean", "sigma_within"):
            assert getattr(c, name) == pytest.approx(want[name], rel=1e-12), (fid, name)
    # the diameter: twice the normal deviation, on the drawn tolerance ±0.02
    assert cs["dia"].capability.mean == pytest.approx(2 * np.mean(delta["dia"]), rel=1e-12)
    assert cs["dia"].tolerance == (-0.02, 0.02)
    # the shoulder facing -Z: the sign flips, the limits are as drawn (-0.03/+0.05)
    assert cs["face"].tolerance == pytest.approx((-0.03, 0.05), abs=1e-15)
    assert cs["face"].capability.mean == pytest.approx(-np.mean(delta["face"]), rel=1e-12)


@pytest.mark.parametrize(("profile", "fid"), [(BORE, "bore"), (SHAFT, "face"), (SHAFT, "dia")])
def test_a_drawn_scale_keeps_cp_and_cpk(profile, fid):
    feat = profile[fid]
    k = drawn_scale(feat)
    rng = np.random.default_rng(7)
    y = np.r_[rng.normal(0.003, 0.001, 14), rng.normal(-0.002, 0.001, 14)]
    u = np.full(y.size, 3e-4)
    ids = [f"p{i:02d}" for i in range(y.size)]
    kw = dict(u={fid: u}, u_systematic={fid: 2e-4}, parts=ids)
    drawn = D.capability_from_values({fid: y}, profile=profile, **kw)[fid]
    normal = D.capability_from_values({fid: y}, {fid: feat.tolerance}, **kw)[fid]
    assert normal.coordinate == "normal" and normal.scale == 1.0
    a, b = drawn.capability, normal.capability
    # the indices do not change (Cpl and Cpu trade places where the scale is negative)
    for name in ("cp", "cpk", "pp", "ppk", "cpm"):
        assert getattr(a, name) == pytest.approx(getattr(b, name), rel=1e-12), name
        ci_a, ci_b = tuple(getattr(a, f"{name}_ci")), tuple(getattr(b, f"{name}_ci"))
        assert ci_a == pytest.approx(ci_b, rel=1e-12), name
    lower, upper = ("cpu", "cpl") if k < 0 else ("cpl", "cpu")
    assert a.cpl == pytest.approx(getattr(b, lower), rel=1e-12)
    assert a.cpu == pytest.approx(getattr(b, upper), rel=1e-12)
    for tag in ("predicted", "predicted_within"):
        p, q = getattr(drawn, tag), getattr(normal, tag)
        assert p.cpk == pytest.approx(q.cpk, rel=1e-12)
        assert tuple(p.cpk_ci) == pytest.approx(tuple(q.cpk_ci), rel=1e-12)
        assert p.mean_after == pytest.approx(k * q.mean_after, abs=1e-15)
        assert p.u_offset == pytest.approx(abs(k) * q.u_offset, rel=1e-12)
    # Bayesian: Cp in closed form, Cpk from draws (mirrored where k < 0: Monte Carlo noise)
    assert a.bayes.cp == pytest.approx(b.bayes.cp, rel=1e-12)
    assert a.bayes.cpk == pytest.approx(b.bayes.cpk, rel=5e-3)
    assert tuple(a.bayes.cpk_interval) == pytest.approx(tuple(b.bayes.cpk_interval), rel=1e-2)
    # values, limits and control chart as drawn
    np.testing.assert_allclose(drawn.values, k * y, rtol=0, atol=1e-15)
    np.testing.assert_allclose(drawn.u, abs(k) * u, rtol=1e-15)
    assert drawn.tolerance == pytest.approx(drawn_limits(feat), abs=1e-15)
    assert drawn.normal_tolerance == pytest.approx(feat.tolerance, abs=1e-15)
    assert (a.lsl, a.usl) == pytest.approx(drawn_limits(feat), abs=1e-15)
    assert a.mean == pytest.approx(k * b.mean, rel=1e-12)
    assert a.sigma_within == pytest.approx(abs(k) * b.sigma_within, rel=1e-12)
    s, t = drawn.stability, normal.stability
    assert s.center == pytest.approx(k * t.center, rel=1e-12)
    assert sorted((s.lcl, s.ucl)) == pytest.approx(sorted((k * t.lcl, k * t.ucl)), rel=1e-12)
    assert s.step_size == pytest.approx(k * t.step_size, rel=1e-12)
    assert drawn.step_part == normal.step_part == "p14"
    assert s.out_of_control == t.out_of_control
    # the tables: as drawn first, then the normal deviation
    cs = D.capability_from_values({fid: y}, profile=profile, **kw)
    row = cs.summary_rows()[0]
    assert row["coordinate"] == feat.tolerance_on
    assert (row["lsl_drawn_mm"], row["usl_drawn_mm"]) == pytest.approx(drawn_limits(feat))
    assert (row["lsl_mm"], row["usl_mm"]) == pytest.approx(feat.tolerance)
    assert row["mean_mm"] == pytest.approx(b.mean, rel=1e-12)
    assert row["step_drawn_mm"] == pytest.approx(k * t.step_size, rel=1e-12)
    assert row["step_mm"] == pytest.approx(t.step_size, rel=1e-12)
    parts = cs.part_rows()
    np.testing.assert_allclose([r["value_drawn_mm"] for r in parts], k * y, atol=1e-15)
    np.testing.assert_allclose([r["value_mm"] for r in parts], y, rtol=1e-14)
    assert parts[0]["lcl_mm"] == pytest.approx(t.lcl, rel=1e-12)
    assert parts[0]["ucl_mm"] == pytest.approx(t.ucl, rel=1e-12)
    assert {r["coordinate"] for r in cs.index_rows()} == {feat.tolerance_on}


def test_features_outside_the_profile_are_refused():
    with pytest.raises(InputError, match="not a feature of the profile"):
        D.capability_from_values({"nope": [0.0, 0.001, 0.002]}, profile=SHAFT)
    with pytest.raises(InputError, match="needs the tolerances or the profile"):
        D.capability_from_values({"dia": [0.0, 0.001, 0.002]})


@pytest.fixture(scope="module")
def run():
    """The first ten parts of the simulated run (before its tool change), with truth."""
    study = load_study(BATCH)
    files = sorted(BATCH.parent.glob("part*.csv"))[:10]
    probe = D.load_probe_data(study, files)
    cs = D.capability_study(study, probe, n_draws=20_000)
    truth = json.loads((BATCH.parent / "truth.json").read_text())["parts"][:10]
    return study, probe, cs, truth


def test_a_simulated_run_is_studied_as_drawn(run):
    study, probe, cs, truth = run
    assert cs.parts == tuple(f"part{i:02d}" for i in range(1, 11))
    values, us, _, _, _ = D.capability_values(
        study, probe, method="robust", at="mid", sources=D.source_sds(study)
    )
    for fid in ("dia_24", "face_end", "taper"):
        feat, f = study.profile[fid], cs[fid]
        k = drawn_scale(feat)
        assert f.coordinate == feat.tolerance_on and f.scale == k
        np.testing.assert_allclose(f.values, k * np.asarray(values[fid]), rtol=0, atol=1e-15)
        np.testing.assert_allclose(f.u, abs(k) * np.asarray(us[fid]), rtol=1e-15)
        # known truth: the drawn value is k times the true offset, within its uncertainty
        true = np.array([k * t["deviations"][fid]["offset"] for t in truth])
        z = (f.values - true) / f.u
        assert np.median(np.abs(z)) < 1.5 and np.max(np.abs(z)) < 5.0, fid
        lo, hi = drawn_limits(feat)
        assert f.tolerance == pytest.approx((lo, hi))
        want = _hand(f.values, lo, hi)
        for name in ("cp", "cpk", "pp", "ppk"):
            assert getattr(f.capability, name) == pytest.approx(want[name], rel=1e-12)
    assert cs["dia_24"].tolerance == (-0.02, 0.02)  # Ø24 ±0.02 as on the drawing
    assert cs["dia_24"].coordinate == "diameter" and cs["face_end"].coordinate == "length"


def test_the_files_say_the_coordinate(run):
    import pandas as pd

    _, _, cs, _ = run
    dia = cs["dia_24"]
    doc = json.loads(capability_json(cs))
    fj = {x["feature"]: x for x in doc["features"]}
    assert fj["dia_24"]["coordinate"] == "diameter" and fj["dia_24"]["scale"] == 2.0
    assert (fj["dia_24"]["lsl_drawn_mm"], fj["dia_24"]["usl_drawn_mm"]) == (-0.02, 0.02)
    assert (fj["dia_24"]["lsl_mm"], fj["dia_24"]["usl_mm"]) == (-0.01, 0.01)
    assert fj["face_end"]["coordinate"] == "length" and fj["taper"]["coordinate"] == "normal"
    v0 = fj["dia_24"]["values"][0]
    assert v0["value_drawn_mm"] == pytest.approx(2 * v0["value_mm"], rel=1e-15)
    assert fj["dia_24"]["stability"]["center_drawn_mm"] == pytest.approx(dia.capability.mean)
    assert fj["dia_24"]["predicted"]["mean_after_drawn_mm"] == pytest.approx(0.0, abs=1e-12)
    csvs = capability_csvs(cs)
    summary = pd.read_csv(io.StringIO(csvs["capability_summary.csv"]))
    head = ["feature", "at", "coordinate", "n", "lsl_drawn_mm", "usl_drawn_mm"]
    assert list(summary.columns[:6]) == head
    row = summary.set_index("feature").loc["dia_24"]
    assert row["coordinate"] == "diameter"
    assert row["mean_drawn_mm"] == pytest.approx(2 * row["mean_mm"], rel=1e-12)
    parts = pd.read_csv(io.StringIO(csvs["capability_parts.csv"]))
    assert list(parts.columns[:4]) == ["part", "feature", "coordinate", "value_drawn_mm"]
    indices = pd.read_csv(io.StringIO(csvs["capability.csv"]))
    assert list(indices.columns[:3]) == ["feature", "coordinate", "index"]
    text = capability_text(cs)
    line = next(ln for ln in text.splitlines() if ln.startswith("dia_24    diameter"))
    assert "[-20,+20]" in line and f"{dia.capability.mean * 1e3:+.2f}" in line
    assert "Values as drawn (um): on the diameter for diameters" in text


def test_the_chart_is_labelled_as_drawn(run):
    _, _, cs, _ = run
    fig = capability_chart_figure(cs)
    labels = {ax.get_title().split(" ")[0]: ax.get_ylabel() for ax in fig.axes if ax.get_visible()}
    assert labels["dia_24"] == "deviation of Ø (µm)"
    assert labels["face_end"] == "deviation of Z (µm)"
    assert labels["taper"] == "normal deviation (µm)"
    ax = next(a for a in fig.axes if a.get_title().startswith("dia_24"))
    red = [ln.get_ydata()[0] for ln in ax.get_lines() if ln.get_color() == "C3"]
    assert sorted(red) == pytest.approx([-20.0, 20.0])  # the tolerance, as drawn


def test_a_capability_study_states_the_global_risks_of_judging_its_parts():
    """60 parts of N(4 um, 6 um) on +-20 um, each measured with u = 1.5 um (and a
    wider run, N(4 um, 15 um) measured with u = 6 um, consumer's risk 3.5 %): the process
    prior takes the gauge's share off the overall spread (sigma_p^2 = s^2 - u^2) and
    the global risks are decide.global_risks' with it (JCGM 106, 9.5); the guard band
    for a 2 % consumer's risk is 0 when the plain acceptance already meets it, and
    positive when it does not (a wider process). A gauge as wide as the spread gives
    no risks (the process cannot be told from the gauge)."""
    from piecs_bayes.decide import ProcessPrior, global_risks

    rng = np.random.default_rng(3)
    for sd, um, meets in ((0.006, 0.0015, True), (0.015, 0.006, False)):
        y = 0.004 + sd * rng.standard_normal(60)
        f = D.capability_from_values(
            {"d": y}, {"d": (-0.02, 0.02)}, u={"d": np.full(60, um)},
            options=CapabilityOptions(n_draws=2_000),
        )["d"]  # fmt: skip
        plain, guarded = f.risks()
        c = f.capability
        sp = math.sqrt(c.sigma_overall**2 - um**2)
        assert plain.process.sd == pytest.approx(sp, rel=1e-12)
        tol = (-0.02, 0.02)
        ref = global_risks(tol, tol, u=um, process=ProcessPrior(c.mean, sp))
        assert plain.global_consumer_risk == pytest.approx(ref.consumer, rel=1e-9, abs=1e-15)
        assert plain.global_producer_risk == pytest.approx(ref.producer, rel=1e-9, abs=1e-15)
        assert (guarded.guard_band == 0.0) == meets == (plain.global_consumer_risk <= 0.02)
        if not meets:
            assert guarded.global_consumer_risk == pytest.approx(0.02, abs=1e-9)
        row = f.summary()
        assert row["global_consumer_risk"] == plain.global_consumer_risk
        assert row["guard_band_2pct_drawn_mm"] == guarded.guard_band
    wide = D.capability_from_values({"d": y}, {"d": (-0.02, 0.02)}, u={"d": np.full(60, 0.05)})
    assert wide["d"].risks() is None and math.isnan(wide["d"].summary()["global_consumer_risk"])


def test_q_mp_states_whether_the_measuring_process_is_capable_of_the_tolerance():
    """Q_MP = 2 k u_MP / T with u_MP^2 = rms(u)^2 + u_systematic^2 (VDA 5 /
    ISO 22514-7), by hand: u = 1.2, 1.6 um alternating (rms 1.4142), u_systematic
    1 um, k = 2: u_MP = 1.7321 um, U_MP = 3.4641 um, on +-20 um Q_MP = 17.3 %:
    capable of the tolerance. On +-10 um (34.6 % > 30 %) the study refuses to call the
    process capable, though its Cpk is far above 1.33, and says why; a limit of 40 %
    set in the study's [capability] table lets it judge again."""
    rng = np.random.default_rng(5)
    y = 0.001 * rng.standard_normal(40)  # Cpk ~ 3 on +-10 um
    u = np.where(np.arange(40) % 2, 0.0012, 0.0016)
    kw = dict(u={"d": u}, u_systematic={"d": 0.001}, options=CapabilityOptions(bayes=False))
    wide = D.capability_from_values({"d": y}, {"d": (-0.02, 0.02)}, **kw)["d"]
    u_mp = math.sqrt((0.0012**2 + 0.0016**2) / 2 + 0.001**2)
    assert wide.u_mp == pytest.approx(u_mp, rel=1e-12)
    assert wide.U_mp == pytest.approx(2 * u_mp, rel=1e-12)
    assert wide.q_mp == pytest.approx(4 * u_mp / 0.04, rel=1e-12)  # 17.3 %
    assert wide.measuring_process_capable and wide.verdict == "capable"
    narrow = D.capability_from_values({"d": y}, {"d": (-0.01, 0.01)}, **kw)["d"]
    assert narrow.q_mp == pytest.approx(4 * u_mp / 0.02, rel=1e-12)  # 34.6 %
    assert narrow.capability.cpk > 2.0 and narrow.stability.in_control
    assert narrow.verdict == "measuring process not capable"
    assert "Q_MP = 35% > 30%" in narrow.verdict_reason()
    row = narrow.summary()
    assert row["q_mp"] == narrow.q_mp and row["measuring_process_capable"] is False
    assert row["verdict"] == "measuring process not capable"
    text = capability_text(D.capability_from_values({"d": y}, {"d": (-0.01, 0.01)}, **kw))
    assert "measuring process not capable" in text and "34.6%" in text
    lenient = CapabilityOptions(bayes=False, q_mp_limit=0.40)
    kw["options"] = lenient
    assert D.capability_from_values({"d": y}, {"d": (-0.01, 0.01)}, **kw)["d"].verdict == (
        "capable"
    )
    with pytest.raises(InputError, match="q_mp_limit"):
        CapabilityOptions(q_mp_limit=0.0)


def test_an_unstable_process_is_judged_by_its_performance():
    """A run with a step half-way is not in statistical control: its within-sigma Cpk
    says what it could do if stable (high), the verdict reads Ppk (this run)."""
    rng = np.random.default_rng(8)
    y = 0.0005 * rng.standard_normal(40) + np.where(np.arange(40) < 20, -0.006, 0.006)
    f = D.capability_from_values({"d": y}, {"d": (-0.02, 0.02)},
                                 options=CapabilityOptions(bayes=False))["d"]  # fmt: skip
    assert not f.stability.in_control
    assert f.capability.cpk > 1.33 > f.capability.ppk
    assert f.judged_by == ("Ppk", f.capability.ppk)
    assert f.verdict == "not capable" and "not in statistical control" in f.verdict_reason()


def test_indices_corrected_for_measurement_variation_recover_the_process():
    """Observed = process + measurement: 400 simulated runs of 50 parts, process
    N(0, 2 um), each part measured with u = 1.5 um known. The observed overall variance
    is sigma_p^2 + u^2 on average (6.25 um^2, Pp biased low); the corrected one,
    s^2 - rms(u)^2, is sigma_p^2 = 4 um^2 within 3 Monte Carlo sds (a closed form:
    the sd of s^2 is sigma^2 sqrt(2 / (n - 1))). The correction by hand on one run:
    Cp_corr = T / (6 sqrt(s_w^2 - u^2)), Pp_corr = T / (6 sqrt(s^2 - u^2))."""
    rng = np.random.default_rng(11)
    sp, um, n, runs = 0.002, 0.0015, 50, 400
    opts = CapabilityOptions(bayes=False)
    var_obs, var_corr = [], []
    for _ in range(runs):
        y = sp * rng.standard_normal(n) + um * rng.standard_normal(n)
        f = D.capability_from_values({"d": y}, {"d": (-0.02, 0.02)},
                                     u={"d": np.full(n, um)}, options=opts)["d"]  # fmt: skip
        var_obs.append(f.capability.sigma_overall**2)
        var_corr.append(f.corrected.sigma_overall**2)
    mc_sd = (sp**2 + um**2) * math.sqrt(2 / (n - 1)) / math.sqrt(runs)
    assert abs(np.mean(var_corr) - sp**2) < 3 * mc_sd
    assert np.mean(var_obs) - sp**2 > 10 * mc_sd  # the observed variance is inflated
    c, cc = f.capability, f.corrected
    assert cc.cp == pytest.approx(0.04 / (6 * math.sqrt(c.sigma_within**2 - um**2)), rel=1e-12)
    assert cc.pp == pytest.approx(0.04 / (6 * math.sqrt(c.sigma_overall**2 - um**2)), rel=1e-12)
    row = f.summary()
    assert row["cp_corrected"] == cc.cp and row["ppk_corrected"] == cc.ppk
    # a gauge wider than the spread: no corrected indices, said in the notes
    g = D.capability_from_values({"d": y}, {"d": (-0.02, 0.02)},
                                 u={"d": np.full(n, 0.01)}, options=opts)["d"]  # fmt: skip
    assert g.corrected is None and math.isnan(g.summary()["cp_corrected"])
    assert any("corrected for measurement variation" in s for s in g.notes)
