"""``orders = "auto"`` judged at the directions the parts are probed from, the warning of
a calibration that spans 180 degrees or less, and one radius per axis from a ring with
a face pair (issue 42, items 3 and 4).

The half-sphere data set: a sphere on the spindle axis probed from +X and both sides
along Z, 24 directions from -90 to +90 degrees about +X (approach angles 90 to 270),
a 2 um 3-lobe probe, 1.5 um repeatability. There the lobing is confounded with the
sphere's centre: orders 2 and orders 3 fit the data alike (their lack-of-fit
noncentrality differs by 0.5) yet differ by 10 um at +-X. Measured (300 calibrations,
orders forced): one radius covers the true r at the lathe's four directions 54 % of
the time, orders 2 60 %, r0 + a2 63 %, orders 3 (the truth's model) 96 %; `auto`,
which keeps orders 2 and 3, 95 %.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from helpers import run_cli, three_sds, window_pass_rate
from scipy import stats

from piecs_bayes.errors import InputError
from piecs_bayes.fit import (
    LATHE_DIRECTIONS,
    CalibrationDesign,
    CalibrationOptions,
    choose_orders,
    direction_check,
    fit_probe_calibration,
)
from piecs_bayes.io import CalibrationArtefact, lobe_basis, read_probe_calibration
from piecs_bayes.simulate import simulate_calibration

SPHERE = CalibrationArtefact("sphere", 25.0004, 0.0005, 2.0, (0.0, -40.0))
SIGMA = 0.0015
LOBE3 = 0.002
TARGETS = np.radians(LATHE_DIRECTIONS)


def _half_sphere(seed=0, **kw):
    return simulate_calibration(seed=seed, lobe3=LOBE3, directions="lathe", **kw)


def _nominal_u(theta, orders, at):
    """The u of r at angles `at` of a sphere fit of `orders` with a free centre, at the
    declared sigma, from the textbook design (ball centre = c - (R + r) a): rows
    (a_x, a_z, -1, -cos k theta, -sin k theta), cov = sigma^2 (X^T X)^-1 + u(R)^2 on r0."""
    a = np.c_[np.cos(theta), np.sin(theta)]
    x = np.c_[a, -lobe_basis(theta, orders)]
    cov = SIGMA**2 * np.linalg.inv(x.T @ x)[2:, 2:]
    cov[0, 0] += SPHERE.radius_u**2
    b = lobe_basis(at, orders)
    return np.sqrt(np.einsum("ti,ij,tj->t", b, cov, b))


def test_auto_on_the_half_sphere_keeps_the_orders_the_data_can_vouch_for():
    """The candidates' u of r at the lathe's +X, +Z, -X, -Z: each reduced model's u is
    the reference's combined with the shift its omitted terms make there (Gauss-Markov:
    a model nested in the reference adds exactly the shift's variance to its own), so
    no model with fewer orders beats (2, 3) here; the reference's u is the textbook
    design's (24.7, 1.7, 18.1, 1.7 um); the chosen is the smallest."""
    sim = _half_sphere()
    cal = fit_probe_calibration(SPHERE, sim["points"], sim["approach"], sigma_declared=SIGMA)
    choice = cal.orders_choice
    assert cal.orders == (2, 3) and choice["chosen"] == [2, 3]
    assert choice["targets_deg"] == [0.0, 90.0, 180.0, -90.0]
    assert choice["targets_from"].startswith("the lathe's axis approaches")
    rows = {str(r["orders"]): r for r in choice["candidates"]}
    assert list(rows) == ["[2, 3]", "[3]", "[2]", "a2", "[]"]
    ref = np.array(rows["[2, 3]"]["u_each_mm"])
    want = _nominal_u(sim["theta"], (2, 3), TARGETS)
    np.testing.assert_allclose(ref, want, rtol=1e-9)
    np.testing.assert_allclose(ref * 1e3, [24.67, 1.74, 18.12, 1.74], atol=0.01)
    orders = {"[2, 3]": (2, 3), "[3]": (3,), "[2]": (2,), "[]": ()}
    for name, row in rows.items():
        if name in orders:  # its own u is the textbook's for its orders
            own = _nominal_u(sim["theta"], orders[name], TARGETS)
            np.testing.assert_allclose(row["u_model_mm"], np.sqrt(np.mean(own**2)), rtol=1e-9)
        assert row["u_mm"] >= rows["[2, 3]"]["u_mm"] * (1 - 1e-12)
        assert row["u_mm"] >= row["u_model_mm"] * (1 - 1e-12)  # equal where no shift
    assert min(r["u_mm"] for r in rows.values()) == rows["[2, 3]"]["u_mm"]
    # what the reduced models would state if they held: one radius 0.66 um, orders 3 0.96
    assert rows["[]"]["u_model_mm"] == pytest.approx(0.00066, abs=1e-5)
    assert rows["[3]"]["u_model_mm"] == pytest.approx(0.00096, abs=1e-5)


def test_a_reduced_models_u_is_the_references_with_its_shift():
    """With one certified size the identity is exact: u_K(theta)^2 = u_ref(theta)^2 +
    shift_K(theta)^2 at every target (here a plan's directions, 180 and +-90)."""
    sim = _half_sphere(seed=5)
    design = CalibrationDesign(SPHERE, sim["points"], sim["approach"])
    spec, choice = choose_orders(design, SIGMA, targets_deg=[180.0, 90.0, -90.0])
    assert spec == (2, 3) and choice["targets_from"] == "given"
    ref = np.array(choice["candidates"][0]["u_each_mm"])
    for row in choice["candidates"][1:]:
        u = np.array(row["u_each_mm"])
        shift = np.sqrt(np.maximum(u**2 - ref**2, 0.0))
        assert np.max(shift) == pytest.approx(row["shift_mm"], rel=1e-6)


def _coverage(m: int, seed: int):
    """`m` half-sphere calibrations with `auto` (Huber, sigma from the residuals), the
    sphere's true diameter drawn from its certificate and a random centre: the rate at
    which r(theta) +- t(0.975, dof) u(theta) covers the truth at the lathe's four
    directions, pooled and per direction, and the orders chosen."""
    rng = np.random.default_rng(seed)
    hits, chosen = [], set()
    for i in range(m):
        sim = _half_sphere(seed=seed * 100_000 + i, centre_offset=rng.normal(0.0, 0.02, 2),
                           diameter=SPHERE.diameter + rng.normal(0.0, 2 * SPHERE.radius_u))  # fmt: skip
        cal = fit_probe_calibration(SPHERE, sim["points"], sim["approach"], sigma_declared=SIGMA)
        truth = lobe_basis(TARGETS, (2, 3)) @ sim["coefficients"]
        k = stats.t.ppf(0.975, cal.dof)
        hits.append(np.abs(cal.radius(TARGETS) - truth) <= k * cal.radius_u(TARGETS))
        chosen.add(cal.orders)
    hits = np.array(hits)
    print(f"coverage {hits.mean():.4f}, per direction {hits.mean(axis=0).round(4)}, {chosen}")
    return float(hits.mean()), hits.mean(axis=0), chosen


#: per tier: calibrations, window of the pooled rate, how often a true 95 % passes at
#: least, a coverage the window must catch and how often at least (exact binomial
#: over the calibrations: the four directions of one calibration are not independent,
#: so counting calibrations, not intervals, understates the power)
TIERS = {"fast": (300, three_sds(300), 0.995, 0.88, 0.95),
         "slow": (1000, (0.935, 0.965), 0.97, 0.92, 0.85)}  # fmt: skip


@pytest.mark.parametrize("tier", TIERS)
def test_the_coverage_windows_have_the_stated_power(tier):
    n, window, level, worse, power = TIERS[tier]
    assert window_pass_rate(window, n, 0.95) >= level
    assert 1.0 - window_pass_rate(window, n, worse) >= power


def test_auto_on_the_half_sphere_covers_at_300_calibrations():
    """Fast tier: 300 calibrations, the pooled rate within 3 binomial sds of 95 %
    (91.2-98.8 %): a true 95 % passes 99.5 % of the time, a coverage of 88 % fails at
    least 95 % of the time (`test_the_coverage_windows_have_the_stated_power`).
    Measured: 94.8 % (the directions 95.7, 93.3, 95.3, 95.0 %)."""
    rate, each, chosen = _coverage(300, 1)
    lo, hi = TIERS["fast"][1]
    assert chosen == {(2, 3)}
    assert lo <= rate <= hi
    assert np.all(each >= 0.95 - 3 * np.sqrt(0.95 * 0.05 / 300))


@pytest.mark.slow
def test_auto_on_the_half_sphere_covers_at_1000_calibrations():
    """Slow tier: 1,000 calibrations, the pooled rate within 93.5-96.5 % (a true 95 %
    passes at least 97 % of the time; 92 % fails at least 85 % of the time).
    Measured: 95.2 % (95.3, 94.7, 95.5, 95.3 %)."""
    rate, each, chosen = _coverage(1000, 2)
    assert chosen == {(2, 3)}
    assert 0.935 <= rate <= 0.965
    assert np.all(each >= 0.95 - 3 * np.sqrt(0.95 * 0.05 / 1000))


class _Cal:
    """A stand-in calibration with given directions (`direction_check` reads
    `directions`, `orders_choice` and `radius_u`)."""

    def __init__(self, directions_deg, u=0.001):
        self.directions = tuple(directions_deg)
        self.orders_choice = None
        self._u = u

    def radius_u(self, theta):
        return np.full(np.size(theta), self._u)


def test_the_half_sphere_warning_names_the_missing_directions_and_the_ring():
    sim = _half_sphere()
    cal = fit_probe_calibration(SPHERE, sim["points"], sim["approach"], sigma_declared=SIGMA)
    assert len(cal.directions) == 24 and {-90.0, 90.0} <= set(cal.directions)
    msg = direction_check(cal)
    assert msg.startswith("the calibration's approach directions span 180 degrees (90 to 270)")
    assert "none along +X (0 degrees: the ball travelling +X, from the -X side)" in msg
    assert "A ring gauge, probed from inside along +X and -X, adds the X approaches" in msg
    assert "face pair" not in msg
    u = cal.radius_u(TARGETS) * 1e3
    assert f"0: {u[0]:.2f}, 90: {u[1]:.2f}, 180: {u[2]:.2f}, -90: {u[3]:.2f}" in msg


@pytest.mark.parametrize(
    ("directions", "missing", "artefact"),
    [
        ([0.0, 180.0], ["+Z (90", "-Z (-90"], "face pair ([artefact.face]"),  # a ring
        (np.linspace(-45.0, 45.0, 13), ["+Z", "-X (180", "-Z"], "A ring gauge"),  # a quarter
        (np.linspace(-60.0, 60.0, 9), ["-X (180"], "A ring gauge"),  # 120 degrees
    ],
    ids=["ring", "quarter", "third"],
)
def test_the_warning_names_what_is_missing_and_what_adds_it(directions, missing, artefact):
    msg = direction_check(_Cal(directions))
    for m in missing:
        assert m in msg
    assert artefact in msg


@pytest.mark.parametrize(
    "directions", [np.arange(24) * 15.0, [0.0, 90.0, 180.0, -90.0], np.arange(8) * 45.0 - 22.5]
)
def test_no_warning_when_the_directions_span_more_than_half_the_circle(directions):
    assert direction_check(_Cal(directions)) is None


def test_a_plan_direction_in_a_gap_warns_even_over_a_wide_span():
    """-60 to 180 degrees (a span of 240, a gap of 120): with the lathe's directions it
    warns of -Z; a plan probing at 180 and 0 only is served; one probing at -120 (a
    chamfer) is not."""
    cal = _Cal(np.arange(-60.0, 181.0, 15.0))
    assert "none along -Z (-90 degrees" in direction_check(cal)
    assert direction_check(cal, targets_deg=[180.0, 0.0]) is None
    msg = direction_check(cal, targets_deg=[180.0, -120.0])
    assert msg.startswith("the calibration's approach directions span 240 degrees (-60 to 180)")
    assert "; -120 degrees. There" in msg and "A face pair ([artefact.face]" in msg


def _ring_and_face(noise):
    """A ring (D 50.0012) at +-X and its face pair (W 10.0004) at -+Z, two points per
    direction: (artefact, points, approach, x+, x-, z+, z- means)."""
    art = CalibrationArtefact("ring", 50.0012, 0.0008, 2.0, (0.0, -10.0), 10.0004, 0.0006, 2.0)
    xp = 25.0006 - 2.9971 + noise[0:2]
    xm = -25.0006 + 2.9949 + noise[2:4]
    zp = -10.0 + 5.0002 + 3.0015 + noise[4:6]
    zm = -10.0 - 5.0002 - 2.9992 + noise[6:8]
    pts = np.r_[np.c_[xp, [-10.0] * 2], np.c_[xm, [-10.0] * 2], np.c_[[0.0] * 2, zp],
                np.c_[[0.0] * 2, zm]]  # fmt: skip
    app = np.repeat([[1, 0], [-1, 0], [0, -1], [0, 1]], 2, axis=0)
    return art, pts, app, xp.mean(), xm.mean(), zp.mean(), zm.mean()


@pytest.mark.parametrize("sigma_known", [True, False], ids=["known", "estimated"])
def test_ring_and_face_give_both_axis_radii_the_closed_form(sigma_known):
    """One radius per axis, r0 + a2 cos 2 theta (b2 held at 0): r along X is the ring's
    (D - (x+ - x-)) / 2, along Z the faces' ((z+ - z-) - W) / 2 (means of two points a
    direction), to 1e-9 mm; their u^2 = s^2 / 4 + u(cert)^2 (s: sigma known, or the
    residual sd about the four direction means with n - 4 dof; linear loss),
    uncorrelated, to 1e-9 relative. `auto`
    chooses this model: one radius would shift r by -+a2 at the axes."""
    noise = np.array([0.4, -0.3, 0.2, -0.5, 0.1, 0.6, -0.2, 0.3]) * 1e-3
    art, pts, app, xp, xm, zp, zm = _ring_and_face(noise)
    opts = CalibrationOptions(orders="auto", sigma_known=sigma_known, loss="linear")
    cal = fit_probe_calibration(art, pts, app, sigma_declared=SIGMA, options=opts)
    assert cal.orders == (2,) and cal.fixed == ("b2",) and cal.orders_choice["chosen"] == "a2"
    assert cal.coefficients[2] == 0.0 and np.all(cal.cov[2] == 0.0)
    r_x, r_z = (art.diameter - (xp - xm)) / 2, ((zp - zm) - art.face_width) / 2
    got = cal.radius(np.radians([0.0, 180.0, 90.0, -90.0]))
    np.testing.assert_allclose(got, [r_x, r_x, r_z, r_z], rtol=0, atol=1e-9)
    groups = noise.reshape(4, 2)
    s2 = SIGMA**2 if sigma_known else np.sum((groups - groups.mean(1, keepdims=True)) ** 2) / 4
    if not sigma_known:
        assert cal.dof == 4 and cal.residual_sd == pytest.approx(np.sqrt(s2), rel=1e-9)
    u_x2, u_z2 = s2 / 4 + art.radius_u**2, s2 / 4 + art.face_half_width_u**2
    b = lobe_basis(np.radians([0.0, 90.0]), (2,))
    cov = b @ cal.cov @ b.T
    np.testing.assert_allclose(np.diag(cov), [u_x2, u_z2], rtol=1e-9)
    assert abs(cov[0, 1]) < 1e-12 * u_x2
    rows = {str(r["orders"]): r for r in cal.orders_choice["candidates"]}
    assert list(rows) == ["a2", "[]"]
    assert rows["[]"]["shift_mm"] == pytest.approx(abs(r_x - r_z) / 2, rel=1e-6)
    assert direction_check(cal) is None


def test_one_radius_per_axis_round_trips_through_probe_cal_json(tmp_path):
    noise = np.zeros(8)
    art, pts, app, *_ = _ring_and_face(noise)
    opts = CalibrationOptions(orders="a2", sigma_known=True, loss="linear")  # shapes reused
    cal = fit_probe_calibration(art, pts, app, sigma_declared=SIGMA, options=opts)
    assert cal.orders_choice is None
    path = tmp_path / "probe_cal.json"
    path.write_text(cal.to_json_text())
    obj = json.loads(path.read_text())
    assert obj["fixed_at_zero"] == ["b2"] and obj["orders"] == [2]
    assert obj["directions_deg"] == [-90.0, 0.0, 90.0, 180.0]
    back = read_probe_calibration(path)
    assert back.fixed == ("b2",) and back.directions == cal.directions
    np.testing.assert_array_equal(back.coefficients, cal.coefficients)
    obj["coefficients"]["b2"] = 1e-4
    path.write_text(json.dumps(obj))
    with pytest.raises(InputError, match=r"b2 is held at zero \(fixed_at_zero\) but its value"):
        read_probe_calibration(path)


def test_one_radius_per_axis_needs_a_face_pair_beside_a_ring():
    ring = CalibrationArtefact("ring", 50.0012, 0.0008, 2.0)
    pts = [[22.0, 0.0], [-22.0, 0.0], [22.0, 1.0], [-22.0, 1.0]]
    with pytest.raises(InputError, match=r"one radius per axis\) needs approaches along X and "
                       r"along Z: a ring or diameter with a face pair"):  # fmt: skip
        fit_probe_calibration(ring, pts, [[1, 0], [-1, 0]] * 2, sigma_declared=SIGMA,
                              options=CalibrationOptions(orders="a2", sigma_known=True))  # fmt: skip


def test_simulated_directions_default_to_what_a_lathe_reaches(capsys, tmp_path):
    rc, text = run_cli(capsys, ["simulate", "calibration", "--out", tmp_path / "lathe"])
    assert rc == 0, text
    truth = json.loads((tmp_path / "lathe" / "truth.json").read_text())
    assert truth["directions"] == "lathe"
    np.testing.assert_allclose(truth["approach_deg"], 180.0 + np.linspace(-90, 90, 24))
    rc, text = run_cli(capsys, ["simulate", "calibration", "--out", tmp_path / "full",
                                "--full-circle"])  # fmt: skip
    assert rc == 0, text
    truth = json.loads((tmp_path / "full" / "truth.json").read_text())
    assert truth["directions"] == "full"
    np.testing.assert_allclose(truth["approach_deg"], np.arange(24) * 15.0)
    rc, text = run_cli(capsys, ["simulate", "--help"])
    assert "--full-circle" in text and "-90 to +90 degrees about +X" in " ".join(text.split())


@pytest.mark.parametrize("orders", ["a3", (1,), (2, 2), "2,3"])
def test_an_unknown_model_is_refused_by_name(orders):
    sim = _half_sphere()
    with pytest.raises(InputError, match=r"orders .*; expected \"auto\", \"a2\" or distinct"):
        fit_probe_calibration(SPHERE, sim["points"], sim["approach"], sigma_declared=SIGMA,
                              options=CalibrationOptions(orders=orders))  # fmt: skip
