"""Decisions, capability studies and machine files through studies and fits (issue 6).

Fits are expensive (the first compiles for seconds), so the demo fit, the scenario
fit and the batch capability study are module-scoped and shared.
"""

import csv
import json
import math
import re
from dataclasses import replace
from pathlib import Path
from types import MappingProxyType

import numpy as np
import pytest

import piecs_bayes.jobs as D
import piecs_bayes.uncertainty as U
from piecs_bayes.capability import CapabilityOptions
from piecs_bayes.cli import main
from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.export.machine import (
    linuxcnc_comp_text,
    offsets_from_json,
    read_errspec,
    read_linuxcnc_comp,
    write_compensation_outputs,
)
from piecs_bayes.export.tables import (
    capability_csvs,
    capability_json,
    capability_text,
    decisions_csv,
    decisions_json,
    decisions_text,
)
from piecs_bayes.io import load_study
from piecs_bayes.jobs import fit_study
from piecs_bayes.simulate import (
    DEMO_EXTRA,
    DEMO_POINTS,
    DEMO_TRANSFORM,
    demo_profile,
    probe_csv_text,
    simulate_probe,
    study_toml_text,
)

DATA = Path(__file__).resolve().parents[2] / "data"
DEMO = DATA / "demo" / "study.toml"
BATCH = DATA / "batch" / "study.toml"


@pytest.fixture(scope="module")
def demo():
    study = load_study(DEMO)
    return study, fit_study(study)


# Known-truth scenarios on one simulated part (a probe with 5 um repeatability,
# covariances from it): far above the noise, inside the noise, near the tolerance,
# large uncertainty (3 points on a diameter), a correction above max_correction.
SCENARIO_TRUTH = {
    "face_end": np.array([-0.001, 0.0]),  # inside the noise (tolerance +-50 um)
    "dia_24": np.array([0.020, 0.0]),  # far above the noise, out of tolerance (+-10)
    "taper": np.array([0.017, 0.0]),  # near the tolerance (+-20)
    "dia_30": np.array([0.009, 0.0]),  # near the tolerance, 3 points: large uncertainty
    "fillet": np.zeros(3),
    "shoulder": np.array([-0.150, 0.0]),  # above max_correction (0.1): investigate
    "dia_44": np.array([0.0003, 0.0]),  # inside the noise (+-15)
}


def _write_scenario(folder: Path, *, seed: int = 9, extra_toml: str = "") -> Path:
    profile = demo_profile()
    points = {**DEMO_POINTS, "dia_30": 3}
    sim = simulate_probe(
        profile,
        SCENARIO_TRUTH,
        ball_radius=1.0,
        transform=DEMO_TRANSFORM,
        points=points,
        noise_sd=0.005,
        rng=seed,
    )
    (folder / "part.csv").write_text(probe_csv_text(sim))
    extra = DEMO_EXTRA.replace('loss = "huber"', 'loss = "huber"\nknown_sigma = true')
    text = study_toml_text(
        profile,
        name="scenarios",
        probe_files=["part.csv"],
        program=None,
        ball_radius=1.0,
        ball_radius_u=0.0005,
        repeatability=0.005,
        transform=DEMO_TRANSFORM,
        extra=extra + extra_toml,
    )
    (folder / "study.toml").write_text(text)
    return folder / "study.toml"


@pytest.fixture(scope="module")
def scenario(tmp_path_factory):
    study = load_study(_write_scenario(tmp_path_factory.mktemp("scenario")))
    return study, fit_study(study)


@pytest.fixture(scope="module")
def batch():
    study = load_study(BATCH)
    return study, D.capability_study(study, n_draws=20_000)


# --------------------------------------------------------------------------- characteristic


def test_characteristic_is_the_normal_deviation(demo):
    study, fit = demo
    f = fit["dia_24"]
    c = U.feature_characteristic(f, at="mid")
    # at the nominal mid-point of a line it is the fitted offset (times cos(rotation),
    # the distance is measured normal to the fitted line), with its uncertainty
    assert c.mean == pytest.approx(f.values[0] * math.cos(f.values[1]), abs=1e-15)
    assert c.u_fit == pytest.approx(f.std_errors[0], rel=1e-6)
    assert c.u_systematic == 0.0 and c.at == "mid"
    # the compiled model agrees with the geometry's own point_at / signed_distance
    for ff in (fit["taper"], fit["fillet"]):
        ts = np.array([0.0, 0.3, 1.0])
        val, jac = U.deviation_and_jacobian(ff.feature, ff.values, ts)
        ref = np.asarray(U.normal_deviation(ff.feature, ff.values, ts))
        np.testing.assert_allclose(val, ref, rtol=0, atol=1e-12)
        h = 1e-7
        for k in range(len(ff.values)):
            d = np.array(ff.values, dtype=float)
            d[k] += h
            fd = (np.asarray(U.normal_deviation(ff.feature, d, ts)) - ref) / h
            np.testing.assert_allclose(jac[:, k], fd, rtol=1e-5, atol=1e-6)
    # the worst point of a line is an end; systematic sources from the study
    w = D.characteristics(study, fit, at="worst")["dia_24"]
    assert w.at in ("start", "end") and abs(w.mean) >= abs(c.mean)
    # ball radius 0.5 um, centre line 1 um, X scale 5 ppm at radius 12 mm
    expected = math.sqrt(0.0005**2 + 0.001**2 + (5e-6 * 12.0) ** 2)
    assert w.u_systematic == pytest.approx(expected, rel=1e-9)
    face = D.characteristics(study, fit, at="mid")["face_end"]
    # a face: ball radius and the Z scale at z = 0; no centre-line sensitivity
    assert face.u_systematic == pytest.approx(0.0005, rel=1e-9)


# --------------------------------------------------------------------------- decisions


def test_scenarios_get_a_metrologists_verdicts(scenario):
    study, fit = scenario
    table = D.decide_study(study, fit)
    v = table.verdicts
    assert v["dia_24"] == "compensate"  # 20 um on +-10, u ~ 4 um
    d = table["dia_24"]
    assert d.gain == pytest.approx(1.0, abs=0.02)
    assert abs(d.correction + 0.020) < 3 * d.u_estimate
    assert v["taper"] == "compensate"  # near the tolerance, significant
    assert v["face_end"] == "do not compensate"  # inside the noise
    assert v["dia_44"] == "do not compensate"
    assert not table["dia_44"].significant
    assert v["dia_30"] == "measure more"  # 3 points: U larger than half the tolerance
    assert table["dia_30"].more_points >= 1
    assert v["shoulder"] == "do not compensate" and table["shoulder"].blocked
    assert v["fillet"] == "do not compensate"
    # the decision table's gains feed the adjusted path / error spec
    assert table.gains["dia_24"] > 0 and table.gains["dia_30"] == 0.0


def test_decision_table_outputs(demo):
    study, fit = demo
    table = D.decide_study(study, fit)
    assert [d.feature for d in table.decisions] == list(study.profile.ids)
    doc = json.loads(decisions_json(table))
    assert doc["schema"] == "piecs_bayes.decisions" and doc["characteristic"] == "worst"
    assert doc["settings"]["max_correction"] == study.compensation.max_correction
    row = {f["feature"]: f for f in doc["features"]}["dia_24"]
    assert row["verdict"] == "compensate" and row["characteristic"]["at"] in ("start", "end")
    assert {a["name"] for a in row["actions"]} >= {"none", "full", "fraction", "grubbs", "bayes"}
    rows = list(csv.DictReader(decisions_csv(table).splitlines()))
    assert len(rows) == 7 and rows[1]["verdict"] == "compensate"
    text = decisions_text(table)
    assert "COMPENSATE" in text and "dia_24" in text


def test_decision_table_dataframe_is_its_csv(demo):
    import io

    import pandas as pd

    study, fit = demo
    table = D.decide_study(study, fit)
    df = table.to_dataframe()
    pd.testing.assert_frame_equal(df, pd.read_csv(io.StringIO(decisions_csv(table))))
    assert list(df["feature"]) == list(study.profile.ids)
    assert df.set_index("feature").loc["dia_24", "verdict"] == table["dia_24"].verdict
    assert {"estimate_mm", "u_estimate_mm", "tolerance_lower_mm", "gain"} <= set(df.columns)


def _dia_24_as_drawn(folder: Path, tol: str) -> Path:
    """The demo study with dia_24's tolerance replaced (as drawn on the diameter)."""
    text = DEMO.read_text()
    head, rest = text.split('id = "dia_24"', 1)
    old = 'tolerance = [-0.0200, 0.0200]\ntolerance_on = "diameter"'
    assert old in rest.split("[[profile.feature]]", 1)[0]
    (folder / "study.toml").write_text(head + 'id = "dia_24"' + rest.replace(old, tol, 1))
    for f in ("probe_part01.csv", "finish.ngc"):
        (folder / f).write_text((DEMO.parent / f).read_text())
    return folder / "study.toml"


def test_a_diameter_tolerance_is_decided_as_drawn(tmp_path):
    """Ø24 ±0.010 as drawn: the decision's limits are ±0.005 on the radius (the normal
    deviation), every table states the diameter, ±10 µm."""
    study = load_study(
        _dia_24_as_drawn(tmp_path, 'tolerance = [-0.010, 0.010]\ntolerance_on = "diameter"')
    )
    table = D.decide_study(study, fit_study(study))
    d = table["dia_24"]
    assert d.tolerance == (-0.005, 0.005) and d.drawn_tolerance == (-0.01, 0.01)
    assert d.coordinate == "diameter" and d.drawn_estimate == 2 * d.estimate
    assert d.drawn_null_band == pytest.approx(0.002)  # 10 % of the drawn width
    assert "tolerance -10.0 … +10.0 µm" in d.reasons[0] and "on the diameter" in d.reasons[0]
    row = {r["feature"]: r for r in table.rows()}["dia_24"]
    assert row["coordinate"] == "diameter"
    assert (row["tolerance_drawn_lower_mm"], row["tolerance_drawn_upper_mm"]) == (-0.01, 0.01)
    assert row["deviation_drawn_mm"] == 2 * row["estimate_mm"]
    doc = {f["feature"]: f for f in json.loads(decisions_json(table))["features"]}
    assert doc["dia_24"]["characteristic"]["coordinate"] == "diameter"
    assert doc["dia_24"]["characteristic"]["scale"] == 2.0
    assert doc["face_end"]["coordinate"] == "length" and doc["taper"]["coordinate"] == "normal"
    line = next(x for x in decisions_text(table).splitlines() if x.startswith("dia_24 "))
    assert "diameter" in line and "[-10,+10]" in line
    # the same band on the radius is the same decision
    radius = load_study(
        _dia_24_as_drawn(tmp_path, 'tolerance = [-0.005, 0.005]\ntolerance_on = "radius"')
    )
    r = D.decide_study(radius, fit_study(radius))["dia_24"]
    assert r.tolerance == d.tolerance and r.verdict == d.verdict and r.gain == d.gain
    assert r.drawn_tolerance == (-0.005, 0.005) and "on the radius" in r.reasons[0]


def test_decide_from_posterior_estimates(demo):
    study, fit = demo
    rng = np.random.default_rng(1)
    est = {
        "dia_24": (0.020, 0.001),
        "dia_30": {"mean": 0.0002, "sd": 0.001, "n_points": 8},
        "dia_44": rng.normal(0.012, 0.008, 4000),  # posterior draws, U > half the tolerance
    }
    t = D.decide_study(study, estimates=est)
    assert t.method == "posterior" and t.unmeasured == ("face_end", "taper", "fillet", "shoulder")
    assert t.verdicts == {
        "dia_24": "compensate",
        "dia_30": "do not compensate",
        "dia_44": "measure more",
    }
    mixed = D.decide_study(study, fit, estimates={"dia_24": (0.0001, 0.001)})
    assert mixed["dia_24"].verdict == "do not compensate"
    assert mixed["dia_30"].verdict == "compensate"  # from the fit
    with pytest.raises(InputError, match="unknown feature id 'dia_99'"):
        D.decide_study(study, estimates={"dia_99": (0.0, 0.001)})
    with pytest.raises(InputError, match="estimate"):
        D.decide_features({"a": "x"}, {"a": (-0.01, 0.01)})


# --------------------------------------------------------------------------- study sections


def _study_with(tmp_path, text: str, units: str = "mm") -> Path:
    src = DEMO.read_text()
    if units != "mm":
        src = src.replace('units = "mm"', f'units = "{units}"')
    p = tmp_path / "study.toml"
    p.write_text(src + "\n" + text)
    for f in ("probe_part01.csv", "finish.ngc"):
        (tmp_path / f).write_text((DEMO.parent / f).read_text())
    return p


@pytest.mark.parametrize(
    "text, message",
    [
        ("[decision]\nnull_band = -1", "decision.null_band: expected a number >= 0, got -1"),
        ("[decision]\np_significant = 1.2", r"decision.p_significant: expected a number in \(0.5"),
        ("[decision]\ncharacteristic = 'best'", "decision.characteristic: unknown value 'best'"),
        ("[decision]\nnul_band = 0.1", "decision.nul_band: unknown key 'nul_band'"),
        ("[decision]\nrequire_significance = 1", "decision.require_significance: expected true"),
        ("[capability]\nconfidence = 95", r"capability.confidence: expected a number in \(0, 1\)"),
        ("[capability]\nn_draws = 10.5", "capability.n_draws: expected an integer, got 10.5"),
        ("[offsets]\ntool = 0", "offsets.tool: expected a number >= 1, got 0"),
        ("[offsets]\nx_features = ['dia_99']", "offsets.x_features: unknown feature id 'dia_99'"),
        ("[offsets]\nx_mode = 'diam'", "offsets.x_mode: unknown value 'diam'"),
        ("[errspec]\ncomp_type = 2", r"errspec.comp_type: expected a number in \[0, 1\], got 2"),
    ],
)
def test_study_sections_are_validated(tmp_path, text, message):
    with pytest.raises(InputError, match=message):
        load_study(_study_with(tmp_path, text))


def test_study_sections_in_inches_and_settings(tmp_path):
    text = (
        "[decision]\nnull_band = 0.0001\nloss_k = 1.0\ncharacteristic = 'mid'\n"
        "[offsets]\nupper_limit = 0.001\nnull_band = 0.0002\ntool = 3\n"
    )
    # only the new sections matter here; the profile in inches is simply 25.4x larger
    study = load_study(_study_with(tmp_path, text, units="in"))
    assert study.decision["null_band"] == pytest.approx(0.00254)
    assert study.decision["loss_k"] == pytest.approx(1.0 / 25.4**2)
    st = D.decision_settings(study)
    # max_correction defaults to compensation.max_correction (0.1 in)
    assert st.null_band == pytest.approx(0.00254) and st.max_correction == pytest.approx(2.54)
    assert D.offset_settings(study).upper_limit == pytest.approx(0.0254)
    bad = replace(study, offsets=MappingProxyType({"upper_limit": 0.001, "null_band": 0.002}))
    with pytest.raises(InputError, match="upper_limit .* must be above null_band"):
        D.offset_settings(bad)


# --------------------------------------------------------------------------- capability


def test_capability_over_the_batch_finds_the_tool_change(batch):
    study, cs = batch
    truth = json.loads((BATCH.parent / "truth.json").read_text())
    change = truth["tool_change_part"]
    assert len(cs.parts) == 36 and cs.method == "robust"
    for fid in ("dia_24", "dia_30", "dia_44", "face_end", "shoulder"):
        f = cs[fid]
        assert f.step_part == change, fid
        assert not f.stability.in_control
        assert change in cs.steps and fid in cs.steps[change]
    f = cs["dia_24"]
    c, b = f.capability, f.capability.bayes
    for name in ("cp", "cpk", "pp", "ppk"):
        lo, hi = getattr(c, f"{name}_ci")
        assert lo < getattr(c, name) < hi, name
    assert c.cp > c.pp  # the step and the drift inflate the overall spread
    assert b is not None and b.cpk_interval.lower < b.cpk < b.cpk_interval.upper
    assert 0.0 <= b.p_cpk_above <= 1.0
    # centring the off-centre diameter predicts a better Cpk (its interval included)
    p = f.predicted
    assert p.mean_after == pytest.approx(0.0, abs=1e-12)
    assert p.cpk > c.ppk and p.cpk_ci.lower < p.cpk < p.cpk_ci.upper
    assert f.predicted_within.cpk == pytest.approx(c.cp, rel=1e-9)
    # the measured characteristic follows the truth (offset at the mid-point), on the
    # normal deviation; as drawn it is the diameter: twice as much
    z = [
        (v - t["deviations"]["dia_24"]["offset"]) / u
        for v, u, t in zip(f.normal_values, f.normal_u, truth["parts"], strict=True)
    ]
    np.testing.assert_allclose(f.values, 2.0 * np.asarray(f.normal_values), rtol=1e-12)
    assert np.median(np.abs(z)) < 1.5 and np.max(np.abs(z)) < 5.0
    doc = json.loads(capability_json(cs))
    assert doc["schema"] == "piecs_bayes.capability" and doc["steps"][change]
    fj = {x["feature"]: x for x in doc["features"]}["dia_24"]
    assert fj["stability"]["step_before_part"] == change and len(fj["values"]) == 36
    text = capability_text(cs)
    assert f"STEP before {change}" in text
    assert len(cs.part_rows()) == 36 * 7 and len(cs.summary_rows()) == 7


def test_the_batch_states_whether_its_probe_is_capable_of_each_tolerance(batch):
    """data/batch (issue 40): every feature's Q_MP = 2 k u_MP / T is stated, the probe
    is capable of every tolerance (Q_MP <= 30 %), the Ø ±10 um diameters take the most
    of theirs (about a quarter: u_systematic 2.2 um as drawn), and the verdicts read
    Ppk because the tool change leaves no feature in statistical control."""
    _, cs = batch
    doc = {x["feature"]: x for x in json.loads(capability_json(cs))["features"]}
    for fid, f in cs.features.items():
        lo, hi = f.tolerance
        assert f.q_mp == pytest.approx(4 * f.u_mp / (hi - lo), rel=1e-12)
        assert 0.0 < f.q_mp <= 0.30 and f.measuring_process_capable, fid
        assert doc[fid]["q_mp"] == pytest.approx(f.q_mp, rel=1e-12)
        assert doc[fid]["verdict"] == f.verdict and doc[fid]["verdict_reason"]
    assert {max(cs.features.values(), key=lambda f: f.q_mp).feature} <= {"dia_24", "dia_30"}
    assert 0.15 < cs["dia_24"].q_mp <= 0.30
    assert cs["dia_24"].verdict == "not capable" and cs["face_end"].verdict == "capable"
    assert "Ppk" in cs["dia_24"].verdict_reason()
    assert "Q_MP" in capability_text(cs)


def test_capability_dataframes_are_its_csvs(batch):
    import io

    import pandas as pd

    _, cs = batch
    csvs = capability_csvs(cs)
    for table, name in (
        ("summary", "capability_summary.csv"),
        ("indices", "capability.csv"),
        ("parts", "capability_parts.csv"),
    ):
        df = cs.to_dataframe(table)
        pd.testing.assert_frame_equal(df, pd.read_csv(io.StringIO(csvs[name])), obj=name)
    parts = cs.to_dataframe("parts")
    assert len(parts) == 36 * 7 and {"value_mm", "u_mm", "lcl_mm", "ucl_mm"} <= set(parts)
    assert list(cs.to_dataframe()["feature"]) == list(cs.features)
    with pytest.raises(ValueError, match="unknown table 'index'"):
        cs.to_dataframe("index")


def test_capability_from_values_is_pure():
    rng = np.random.default_rng(3)
    y = np.r_[rng.normal(0.002, 0.001, 15), rng.normal(-0.004, 0.001, 15)]
    cs = D.capability_from_values(
        {"d": y, "short": [0.0, 0.001]},
        {"d": (-0.01, 0.01), "short": (-0.01, 0.01)},
        parts={"d": [f"p{i:02d}" for i in range(30)], "short": ["p00", "p01"]},
        options=CapabilityOptions(n_draws=5000),
    )
    assert cs["d"].step_part == "p15"
    assert any("short: only 2 value(s)" in n for n in cs.notes)
    with pytest.raises(InputError, match="2 part ids for 30 values"):
        D.capability_from_values({"d": y}, {"d": (-0.01, 0.01)}, parts=["a", "b"])


# --------------------------------------------------------------------------- machine files


def _independent_comp_check(text: str) -> list[tuple[float, float, float]]:
    """LinuxCNC comp-file rules checked without the package's parser: three numbers
    per line, then only `#` notes (LinuxCNC stops reading at the first), which state
    the range, the end values held outside it and that every move is affected."""
    assert text.endswith("\n") and "\r" not in text
    lines = text[:-1].split("\n")
    first_note = next((i for i, line in enumerate(lines) if line.startswith("#")), len(lines))
    lines, notes = lines[:first_note], "\n".join(lines[first_note:])
    assert all(line.startswith("# ") and len(line) < 254 for line in notes.splitlines())
    if notes:
        assert f"Range: nominal {lines[0].split()[0]} to {lines[-1].split()[0]}" in notes
        assert "holds the end" in notes and "every move" in notes and "probing" in notes
    assert 1 <= len(lines) <= 256
    num = r"-?\d+\.\d+"
    rows = []
    for line in lines:
        assert re.fullmatch(rf"{num} {num} {num}", line), line
        rows.append(tuple(float(v) for v in line.split()))
    nominal = [r[0] for r in rows]
    assert all(b > a for a, b in zip(nominal, nominal[1:], strict=False))
    return rows


def test_compensation_outputs_are_written_and_validated(demo, tmp_path):
    study, fit = demo
    out = write_compensation_outputs(study, D.machine_data(study, fit), tmp_path)
    names = {p.name for p in out.written}
    assert {"compensation.errspec.json", "compensation.x_dia_24.csv"} <= names
    assert {"linuxcnc_x.comp", "linuxcnc_z.comp", "linuxcnc_comp.ini"} <= names
    assert {"tool_offsets.json", "tool_offsets_fanuc.ngc"} <= names
    assert "tool_offsets_linuxcnc.ngc" not in names  # needs the current tool-table values
    # native error spec: exact round trip
    back = read_errspec(tmp_path / "compensation.errspec.json")
    for t in out.errspec.tables:
        r = back.table(t.name)
        np.testing.assert_array_equal(r.position, t.position)
        np.testing.assert_array_equal(r.correction, t.correction)
        np.testing.assert_array_equal(r.u_correction, t.u_correction)
    # X across diameters: -gain x radial error at each diameter's mid-point, ascending radius
    xr = out.errspec.table("x_radius")
    assert xr.feature == ("dia_24", "dia_30", "dia_44")
    expected = [-fit[f].values[0] * math.cos(fit[f].values[1]) for f in xr.feature]
    np.testing.assert_allclose(xr.correction, expected, rtol=0, atol=1e-12)
    np.testing.assert_allclose(xr.position, np.array([12.0, 15.0, 22.0]) + 0.0021, atol=1e-9)
    # the LinuxCNC tables pass independent format checks and LinuxCNC's rules
    rows = _independent_comp_check((tmp_path / "linuxcnc_x.comp").read_text())
    assert len(rows) == 3
    for (nom, fwd, rev), c in zip(rows, xr.correction, strict=True):
        assert nom - fwd == pytest.approx(c, abs=1.5e-6) and fwd == rev  # type 0
    comp = read_linuxcnc_comp(tmp_path / "linuxcnc_x.comp", comp_type=0)
    assert comp.valid and len(comp) == 3
    _independent_comp_check((tmp_path / "linuxcnc_z.comp").read_text())
    # what LinuxCNC cannot express is refused, and the INI says why
    assert any(r.startswith("x_dia_24:") and "own position" in r for r in out.refused)
    with pytest.raises(AnalysisError, match="depends only on the joint's own position"):
        linuxcnc_comp_text(out.errspec.table("x_taper"))
    ini = (tmp_path / "linuxcnc_comp.ini").read_text()
    assert "COMP_FILE = linuxcnc_x.comp" in ini and "x_dia_24" in ini
    # tool offsets: the mean diameter error, Fanuc incremental without current values
    upd = offsets_from_json((tmp_path / "tool_offsets.json").read_text())
    xs = D.characteristics(study, fit, at="mid")
    radial = [xs[f].mean for f in ("dia_24", "dia_30", "dia_44")]
    assert min(radial) < upd.x.error / 2 < max(radial)
    assert upd.x.correction == pytest.approx(-upd.x.error) and upd.x.applied
    assert upd.z.error == pytest.approx(
        np.mean([xs["face_end"].mean, xs["shoulder"].mean]), abs=2e-3
    )
    # the program's finish tool, N20 T0202: tool 2, wear offset 2 (G10 P<wear offset>)
    assert "G10 P2 U-0.0372" in (tmp_path / "tool_offsets_fanuc.ngc").read_text()
    assert (upd.tool, upd.offset) == (2, 2)
    assert any("diameters disagree" in n for n in out.notes)
    assert any("nose radius not updated" in n for n in out.notes)


def test_tool_offsets_with_current_values_nose_radius_and_block(demo, tmp_path):
    study, fit = demo
    cur = {"current_x": 0.1234, "current_z": -2.5, "current_r": 0.4, "tool": 2}
    s1 = replace(study, offsets=MappingProxyType(cur))
    out = write_compensation_outputs(s1, D.machine_data(s1, fit, gain=0.5), tmp_path / "a")
    g10 = (tmp_path / "a" / "tool_offsets_linuxcnc.ngc").read_text()
    assert "G10 L1 P2 X0.0862 Z-2.4893" in g10 and "G21 G7" in g10  # as the program's T0202
    off, rot = fit["dia_24"].values
    assert out.errspec.table("x_radius").correction[0] == pytest.approx(
        -0.5 * off * math.cos(rot), abs=1e-15
    )
    # the nose radius, when used, takes its share off X and Z
    base, _ = D.tool_offsets(s1, fit)
    s2 = replace(study, offsets=MappingProxyType({**cur, "nose_radius": "always"}))
    upd, notes = D.tool_offsets(s2, fit)
    d_r = upd.r.correction
    assert upd.r.applied and d_r == pytest.approx(
        -fit["fillet"].feature.sense * fit["fillet"].values[2]
    )
    assert upd.x.error == pytest.approx(base.x.error + 2 * d_r)
    assert upd.z.error == pytest.approx(base.z.error + d_r)
    assert any("nose-radius change" in n for n in notes)
    # an error above the upper limit blocks the update: JSON only, no G10
    s3 = replace(study, offsets=MappingProxyType({"upper_limit": 0.03}))
    out = write_compensation_outputs(s3, D.machine_data(s3, fit), tmp_path / "b")
    names = {p.name for p in out.written}
    assert "tool_offsets.json" in names and "tool_offsets_fanuc.ngc" not in names
    assert out.offsets.blocked and any("no G10 written" in n for n in out.notes)


# --------------------------------------------------------------------------- CLI


def test_cli_decide_capability_and_compensate(demo, tmp_path, capsys):
    assert main(["decide", str(DEMO), "--out", str(tmp_path / "d")]) == 0
    printed = capsys.readouterr().out
    assert "COMPENSATE" in printed and "dia_24" in printed
    rows = list(csv.DictReader((tmp_path / "d" / "decisions.csv").read_text().splitlines()))
    assert [r["feature"] for r in rows] == list(demo[0].profile.ids)
    assert json.loads((tmp_path / "d" / "decisions.json").read_text())["part"] == "probe_part01"

    rc = main(["capability", str(BATCH), "--glob", "part0*.csv", "--out", str(tmp_path / "c")])
    assert rc == 0
    printed = capsys.readouterr().out
    assert "fitted 9/9 parts" in printed and "Bayes Cpk" in printed
    doc = json.loads((tmp_path / "c" / "capability.json").read_text())
    assert len(doc["parts"]) == 9
    for name in ("capability.csv", "capability_summary.csv", "capability_parts.csv"):
        assert (tmp_path / "c" / name).is_file()

    # compensate writes the route's machine files; with --alternatives the others too
    argv = ["compensate", str(DEMO), "--out", str(tmp_path / "p"), "-q", "--alternatives"]
    assert main(argv) == 0
    for name in ("toolpath.csv", "compensation.errspec.json", "linuxcnc_comp.ini"):
        assert (tmp_path / "p" / name).is_file(), name
    read_errspec(tmp_path / "p" / "compensation.errspec.json")
    _independent_comp_check((tmp_path / "p" / "linuxcnc_x.comp").read_text())
    assert offsets_from_json((tmp_path / "p" / "tool_offsets.json").read_text()).x.applied

    assert main(["capability", str(BATCH), "--glob", "nothing*.csv", "-q"]) == 2
    assert "matches no file" in capsys.readouterr().err
    assert main(["capability", str(DEMO), "-q", "--out", str(tmp_path / "e")]) == 2
    assert "at least 3 parts" in capsys.readouterr().err


def test_a_failed_part_fit_falls_back_or_is_left_out(monkeypatch):
    # capability_study fits in batches (piecs_bayes._distributed, issue 8): a failed
    # fit is a non-zero status of its batch problems, simulated here
    import piecs_bayes.jobs._batch as dist
    from piecs_bayes.fit.lsq import Status

    study = load_study(BATCH)
    files = sorted(BATCH.parent.glob("part0[1-5].csv"))
    real = dist._fit_job

    def flaky(job, part_ids, feature_ids, points, lines, method):
        batch = real(job, part_ids, feature_ids, points, lines, method)
        fail = ["part03"] + (["part02"] if method != "lsq" else [])
        for g in batch.groups:
            hit = np.isin(np.asarray(batch.parts)[g.part], fail)
            g.arrays["status_code"][hit] = int(Status.MAX_STEPS_REACHED)
        return batch

    monkeypatch.setattr(dist, "_fit_job", flaky)
    cs = D.capability_study(study, files=files, n_draws=2000)
    assert cs.parts == ("part01", "part02", "part04", "part05")
    assert any(n.startswith("part02: robust fit failed") for n in cs.notes)
    assert any(n.startswith("part03: left out") for n in cs.notes)
    assert "notes:" in capability_text(cs)


def test_the_nose_radius_significance_uses_t_at_the_sigma_dof(demo):
    """|e| > t_0.975(nu) u, nu the dof of the probe sigma the arcs' covariances carry
    (it was a fixed 2): e = 2.2 u is significant with a known sigma (1.96), not at 5
    dof (t = 2.571); through `tool_offsets`, the fit's sigma dof is the one used."""
    from types import SimpleNamespace

    from scipy import stats

    from piecs_bayes.jobs._machine import _nose_radius_error

    study, fit = demo
    arc = study.profile["fillet"]
    u = 1e-3
    fake = SimpleNamespace(
        id="fillet", feature=arc, fixed=(), covariance=np.diag([1.0, 1.0, u**2]),
        values=np.array([0.0, 0.0, -arc.sense * 2.2 * u]),
    )  # fmt: skip
    notes: list = []
    assert _nose_radius_error({"fillet": fake}, "auto", notes, math.inf) == pytest.approx(
        (2.2 * u, u)
    )
    notes = []
    assert _nose_radius_error({"fillet": fake}, "auto", notes, 5.0) == (None, None)
    k = stats.t.ppf(0.975, 5)
    assert notes == [
        f"nose radius not updated: the radius change of fillet gives +2.20 ± 1.00 um, "
        f"not significant (|e| <= {k:.3g} u, t 97.5 % at 5 dof)"
    ]
    _, notes = D.tool_offsets(study, fit)
    (note,) = [n for n in notes if n.startswith("nose radius")]
    k = stats.t.ppf(0.975, fit.sigma.dof)
    assert f"(|e| <= {k:.3g} u, t 97.5 % at {fit.sigma.dof:.3g} dof)" in note, note
