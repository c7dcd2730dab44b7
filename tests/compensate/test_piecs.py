"""The PIECS path end to end, against known answers."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.cli import main
from piecs_bayes.compensate import adjusted_path
from piecs_bayes.errors import AnalysisError
from piecs_bayes.fit import fit_profile
from piecs_bayes.geometry import Arc, Line, Profile, make_feature, profile_side
from piecs_bayes.io import load_study
from piecs_bayes.jobs import compensate_study, fit_study
from piecs_bayes.simulate import (
    DEMO_ERRORS,
    DEMO_POINTS,
    DEMO_TRANSFORM,
    demo_profile,
    process_deviations,
    simulate_probe,
)

DATA = Path(__file__).resolve().parents[2] / "data"

PROFILE = demo_profile()
TRUTH = process_deviations(PROFILE, DEMO_ERRORS)


def _machine_to_part_fit(sim, **kw):
    from piecs_bayes.fit import to_part_frame

    return fit_profile(
        PROFILE, sim["feature"], to_part_frame(DEMO_TRANSFORM, sim["points"]), ball_radius=1.0, **kw
    )


def test_noise_free_fit_recovers_the_true_deviations_to_1e9_mm():
    sim = simulate_probe(
        PROFILE, TRUTH, ball_radius=1.0, transform=DEMO_TRANSFORM, points=DEMO_POINTS, noise_sd=0.0
    )
    fit = _machine_to_part_fit(sim)
    for fid, dev in TRUTH.items():
        assert np.max(np.abs(fit[fid].values - dev)) < 1e-9, fid
    assert fit.unmeasured == ()


def test_noisy_fit_recovers_the_truth_within_three_standard_uncertainties():
    sim = simulate_probe(
        PROFILE,
        TRUTH,
        ball_radius=1.0,
        transform=DEMO_TRANSFORM,
        points=DEMO_POINTS,
        noise_sd=0.0015,
        rng=11,
    )
    fit = _machine_to_part_fit(sim)
    for fid, dev in TRUTH.items():
        z = (fit[fid].values - dev) / fit[fid].std_errors
        assert np.all(np.abs(z) < 3.0), (fid, z)
        # and the uncertainty is of the size the noise implies, not vanishing
        assert np.all(fit[fid].std_errors > 1e-5)


def _cylinder_profile():
    # face at z=0 (X 40 -> 50 diameter), cylinder D50 from z=0 to z=-50, shoulder face to D60
    specs = [
        dict(id="face", p0=(20.0, 0.0), p1=(25.0, 0.0)),
        dict(id="cyl", p0=(25.0, 0.0), p1=(25.0, -50.0)),
        dict(id="shoulder", p0=(25.0, -50.0), p1=(30.0, -50.0)),
    ]
    side = profile_side(specs)
    return Profile(tuple(make_feature(s, side) for s in specs))


def test_hand_computed_mirror_of_a_tapered_cylinder():
    """Measured radius 25.010 at z=0 growing linearly to 25.030 at z=-50: the
    mirrored line runs 24.990 -> 24.970 and meets the (as-drawn) faces there."""
    prof = _cylinder_profile()
    z = np.linspace(-2.0, -48.0, 9)
    radius = 25.010 + (25.030 - 25.010) * (-z) / 50.0
    rb = 1.5
    slope = 0.020 / 50.0
    normal = np.array([1.0, slope]) / np.hypot(1.0, slope)  # outward normal of the real surface
    centres = np.column_stack([radius, z]) + rb * normal
    fit = fit_profile(prof, ["cyl"] * len(z), centres, ball_radius=rb)
    assert fit.unmeasured == ("face", "shoulder")
    assert fit["cyl"].values[0] == pytest.approx(0.020, abs=1e-12)  # offset at mid-point z=-25
    path = adjusted_path(prof, fit.deviations)
    expected = np.array([[20.0, 0.0], [24.990, 0.0], [24.970, -50.0], [30.0, -50.0]])
    assert np.max(np.abs(path.vertices - expected)) < 1e-9
    half = adjusted_path(prof, fit.deviations, gain=0.5)
    assert half.vertices[1, 0] == pytest.approx(24.995, abs=1e-9)
    assert half.vertices[2, 0] == pytest.approx(24.985, abs=1e-9)


def test_tangent_fillet_is_replaced_tangent_to_its_compensated_neighbours():
    dev = {
        "dia_30": np.array([0.010, 0.0]),
        "shoulder": np.array([-0.004, 0.0]),
        "fillet": np.array([0.0, 0.0, 0.006]),
    }
    path = adjusted_path(PROFILE, dev)
    fillet = path.profile["fillet"]
    r_c = 3.0 - 0.006
    # compensated D30 at x = 14.990, shoulder face at z = -60 + 0.004
    assert fillet.center == pytest.approx((14.990 + r_c, -59.996 + r_c), abs=1e-12)
    assert fillet.p0 == pytest.approx((14.990, -59.996 + r_c), abs=1e-12)
    assert fillet.p1 == pytest.approx((14.990 + r_c, -59.996), abs=1e-12)
    assert path.profile.junctions == PROFILE.junctions  # still tangent
    # the sharp corner D24/taper moves along the taper: hand-computed intersection
    dev2 = {"dia_24": np.array([0.010, 0.0])}
    v = adjusted_path(PROFILE, dev2).vertices[2]
    assert v == pytest.approx((11.990, -30.0 + 0.010 * 15.0 / 3.0), abs=1e-12)


def test_adjusted_path_dataframe_is_toolpath_csv():
    import io

    import pandas as pd

    from piecs_bayes.export.tables import path_csv

    path = adjusted_path(PROFILE, TRUTH)
    df = path.to_dataframe()
    pd.testing.assert_frame_equal(df, pd.read_csv(io.StringIO(path_csv(path))))
    assert len(df) == len(PROFILE) + 1 and list(df["vertex"]) == list(range(len(df)))
    assert df["dx_radius_mm"].to_numpy() == pytest.approx(path.shift[:, 0])
    assert df["nominal_x_radius_mm"].to_numpy() == pytest.approx(PROFILE.vertices[:, 0])
    assert df.loc[1, "between"] == f"{PROFILE.ids[0]}|{PROFILE.ids[1]}"


def test_compensation_above_the_limit_is_refused():
    with pytest.raises(
        AnalysisError,
        match=r"feature 'dia_24' would be corrected by 0\.3000 mm, more than the configured maximum correction 0\.1 mm",
    ):
        adjusted_path(PROFILE, {"dia_24": np.array([0.3, 0.0])}, max_correction=0.1)


def test_demo_study_robust_fit_flags_the_chip_and_matches_the_truth():
    study = load_study(DATA / "demo" / "study.toml")
    truth = json.loads((DATA / "demo" / "truth.json").read_text())
    fit = fit_study(study, method="robust")
    chip = truth["outliers"][0]
    assert [list(f.outliers) for f in fit if len(f.outliers)] == [[chip["index"]]]
    assert fit[chip["feature"]].outliers.tolist() == [chip["index"]]
    for f in fit:
        true = np.array(list(truth["deviations"][f.id].values()))
        assert np.all(np.abs(f.values - true) < 3.5 * f.std_errors), f.id
    # plain least squares is pulled by the 150 um chip on dia_30
    plain = fit_study(study, method="lsq")
    true30 = truth["deviations"]["dia_30"]["offset"]
    assert abs(plain["dia_30"].values[0] - true30) > 0.005  # robust: within 1 um
    path = compensate_study(study, fit)
    assert np.all(path.correction < study.compensation.max_correction)


def test_cli_fit_and_compensate_write_their_outputs(tmp_path, capsys):
    study = DATA / "demo" / "study.toml"
    assert main(["compensate", str(study), "--out", str(tmp_path), "--quiet"]) == 0
    doc = json.loads((tmp_path / "fit.json").read_text())
    assert [f["feature"] for f in doc["features"]] == list(PROFILE.ids)
    rows = (tmp_path / "toolpath.csv").read_text().splitlines()
    assert rows[0].startswith(
        "vertex,between,junction,nominal_x_radius_mm,nominal_z_mm,x_radius_mm,z_mm,"
        "dx_radius_mm,dz_mm"
    )
    assert len(rows) == 1 + len(PROFILE) + 1
    assert main(["fit", str(tmp_path / "missing.toml")]) == 2
    assert "missing.toml: study file not found" in capsys.readouterr().err


def test_cli_refuses_to_overwrite_an_input(tmp_path, capsys):
    import shutil

    for name in ("study.toml", "probe_part01.csv", "finish.ngc"):
        shutil.copy(DATA / "demo" / name, tmp_path / name)
    # an output folder that is the data folder: fit.csv is new, but guard the inputs
    (tmp_path / "fit.json").symlink_to(tmp_path / "study.toml")
    assert main(["fit", str(tmp_path / "study.toml"), "--out", str(tmp_path), "--quiet"]) == 2
    assert "refusing to overwrite an input file" in capsys.readouterr().err
    assert (tmp_path / "study.toml").read_text() == (DATA / "demo" / "study.toml").read_text()


def test_an_arc_between_tangent_neighbours_is_rebuilt_through_its_vertices():
    """LinuxCNC's pawn (lathe_g70_71_demo.ngc): a face meeting arc_4 at its tangent
    point, arc_4 tangent to arc_5. The join of a circle with a tangent neighbour is
    ill-conditioned, so the rebuilt vertices came 4 nm apart in radius from the
    compensated centre and the Arc refused itself: an internal error for a measured
    arc beside unmeasured neighbours. The centre now moves onto the vertices'
    perpendicular bisector (by far less than 0.1 um); the vertices stay shared."""
    import jax

    from piecs_bayes.compensate import _mirror

    face = Line("face_z8p732", (4.0, -8.732), (4.5, -8.732), -1, (-0.2, 0.2))
    arc4 = Arc("arc_4", (4.5, -8.732), (6.285, -12.982), (4.499946446785, -11.23187249235),
               True, -1, (-0.2, 0.2))  # fmt: skip
    arc5 = Arc("arc_5", (6.285, -12.982), (6.285, -19.982), (9.85571, -16.482), False, -1,
               (-0.5, 0.5))  # fmt: skip
    prof = Profile((face, arc4, arc5))
    dev = {"face_z8p732": np.zeros(2), "arc_5": np.zeros(3),
           "arc_4": np.array([0.0016079406262258925, 5.876794120690458e-05, 0.002204928748982066])}  # fmt: skip
    verts, centres, _ = jax.device_get(
        _mirror.adjusted_geometry(prof, _mirror.compensated_deviations(prof, dev, 1.0))
    )
    c = np.asarray(centres[1])
    gap = abs(np.hypot(*(verts[1] - c)) - np.hypot(*(verts[2] - c)))
    assert gap < 1e-5  # ill-conditioned: 4e-6 mm here, rounding-dependent elsewhere
    path = adjusted_path(prof, dev)
    a = path.profile["arc_4"]
    np.testing.assert_allclose(a.p0, verts[1], atol=0)
    np.testing.assert_allclose(a.p1, verts[2], atol=0)
    assert abs(math.dist(a.p0, a.center) - math.dist(a.p1, a.center)) < 1e-12
    assert math.dist(a.center, c) < 1e-4
    # the projection itself, on vertices 4 nm apart in radius (machine-independent)
    v0, v1, cc = (4.5, -8.732), (6.285, -12.982), (4.5015, -11.2318)
    d0 = math.dist(v0, cc)
    v1 = tuple(cc[k] + (v1[k] - cc[k]) * (d0 + 4e-6) / math.dist(v1, cc) for k in (0, 1))
    moved = _mirror._equidistant_centre("arc", v0, v1, cc)
    assert abs(math.dist(v0, moved) - math.dist(v1, moved)) < 1e-12
    assert 0 < math.dist(moved, cc) < 1e-4
    with pytest.raises(AnalysisError, match="compensated arc 'arc': its end vertices lie"):
        _mirror._equidistant_centre("arc", v0, (v1[0] + 0.001, v1[1]), cc)
