"""`fit_probe_calibration` against known answers: simulated lobing, the coverage of
r(theta)'s intervals, the closed forms of a ring, a diameter and a face pair, the
refusals of orders the directions cannot separate, and Bayes against least squares."""

from __future__ import annotations

import math
import time
from dataclasses import replace

import numpy as np
import pytest
from scipy import stats

from piecs_bayes.errors import InputError
from piecs_bayes.fit import CALIBRATION_SAMPLING, CalibrationOptions, fit_probe_calibration
from piecs_bayes.io import CalibrationArtefact, lobe_basis
from piecs_bayes.simulate import simulate_calibration

SPHERE = CalibrationArtefact("sphere", 25.0004, 0.0005, 2.0, (0.0, -40.0))
SIGMA = 0.0015


def _fit(sim, sampling=CALIBRATION_SAMPLING, **kw):
    return fit_probe_calibration(SPHERE, sim["points"], sim["approach"], sigma_declared=SIGMA,
                                 options=CalibrationOptions(**kw), sampling=sampling)  # fmt: skip


def test_known_lobing_is_found_within_3u():
    """r0 4 um off nominal, a 3-lobe term of 1.5 um, 1.5 um repeatability, 24 directions:
    every coefficient within 3 u of the truth (five data sets)."""
    worst = 0.0
    for seed in range(5):
        sim = simulate_calibration(seed=seed, directions="full")
        cal = _fit(sim)
        assert cal.orders == (2, 3) and cal.dof == 24 - 7 and cal.n_points == 24
        z = (cal.coefficients - sim["coefficients"]) / np.sqrt(np.diag(cal.cov))
        worst = max(worst, float(np.abs(z).max()))
        assert np.all(np.abs(z) < 3.0), (seed, z)
        # u(r0) carries u(R) = U / 2k = 0.125 um on top of the fit's
        assert cal.cov[0, 0] > (0.0005 / 4) ** 2
        assert 0.0 < cal.probing_error < 0.008
    print(f"largest |error| / u over 5 data sets: {worst:.2f}")


def _simulate_batch(rng, m, theta, d_true, centre, coef):
    a = np.c_[np.cos(theta), np.sin(theta)]
    c0 = np.array(SPHERE.centre)
    c = c0 + rng.normal(0.0, 0.02, (m, 2))
    r = lobe_basis(theta, (2, 3)) @ coef
    d = c0 - c  # (m, 2)
    b = d @ a.T  # (m, n)
    rad = d_true[:, None] / 2.0 + r[None]
    t = b + np.sqrt(b * b - np.sum(d * d, axis=1)[:, None] + rad * rad)
    t += rng.normal(0.0, SIGMA, t.shape)
    return c0 - t[..., None] * a  # (m, n, 2)


def _gauss_newton(points, theta, radius, steps=5):
    """Linear-loss least squares of the sphere model for many calibrations at once:
    (estimates (m, 7), covariances (m, 7, 7) with s^2 of the residuals, u(R) added)."""
    m, n, _ = points.shape
    basis = lobe_basis(theta, (2, 3))
    c = np.broadcast_to(np.array(SPHERE.centre), (m, 2)).copy()
    coef = np.zeros((m, 5))
    coef[:, 0] = np.median(np.linalg.norm(points - c[:, None], axis=2), axis=1) - radius
    y = np.c_[c, coef]
    for _ in range(steps):
        d = points - y[:, None, :2]
        dist = np.linalg.norm(d, axis=2)
        e = dist - radius - y[:, 2:] @ basis.T
        jac = np.concatenate([-d / dist[..., None], -np.broadcast_to(basis, (m, n, 5))], axis=2)
        jtj = np.einsum("mni,mnj->mij", jac, jac)
        y = y - np.linalg.solve(jtj, np.einsum("mni,mn->mi", jac, e)[..., None])[..., 0]
    d = points - y[:, None, :2]
    e = np.linalg.norm(d, axis=2) - radius - y[:, 2:] @ basis.T
    s2 = np.sum(e * e, axis=1) / (n - 7)
    cov = s2[:, None, None] * np.linalg.inv(jtj)
    cov[:, 2, 2] += SPHERE.radius_u**2
    return y, cov


def test_the_batch_gauss_newton_is_the_fit():
    rng = np.random.default_rng(11)
    theta = np.radians(np.arange(24) * 15.0)
    coef = simulate_calibration()["coefficients"]
    pts = _simulate_batch(rng, 3, theta, np.full(3, SPHERE.diameter), SPHERE.centre, coef)
    y, cov = _gauss_newton(pts, theta, SPHERE.diameter / 2)
    a = np.c_[np.cos(theta), np.sin(theta)]
    for k in range(3):
        cal = fit_probe_calibration(SPHERE, pts[k], a, sigma_declared=SIGMA,
                                    options=CalibrationOptions(orders=(2, 3), loss="linear"))  # fmt: skip
        np.testing.assert_allclose(cal.coefficients, y[k, 2:], rtol=0, atol=1e-10)
        np.testing.assert_allclose(cal.cov, cov[k, 2:, 2:], rtol=1e-6, atol=1e-16)


def test_coverage_of_r_theta_intervals():
    """1,000 calibrations (the sphere's true diameter drawn from its certificate, a
    random centre): the 95 % intervals r(theta) +- t(0.975, n - p) u(theta) at 12
    angles cover the true r(theta) 93.5-96.5 % of the time."""
    t0 = time.perf_counter()
    rng = np.random.default_rng(20261130)
    m = 1000
    theta = np.radians(np.arange(24) * 15.0)
    coef = simulate_calibration()["coefficients"]
    d_true = SPHERE.diameter + rng.normal(0.0, 2 * SPHERE.radius_u, m)  # u(D) = 2 u(R)
    pts = _simulate_batch(rng, m, theta, d_true, SPHERE.centre, coef)
    y, cov = _gauss_newton(pts, theta, SPHERE.diameter / 2)
    at = np.radians(np.arange(12) * 30.0 + 7.0)
    b = lobe_basis(at, (2, 3))
    est = y[:, 2:] @ b.T
    u = np.sqrt(np.einsum("ai,mij,aj->ma", b, cov[:, 2:, 2:], b))
    k = stats.t.ppf(0.975, 24 - 7)
    rate = float(np.mean(np.abs(est - b @ coef) <= k * u))
    print(f"coverage {rate:.4f} in {time.perf_counter() - t0:.2f} s")
    assert 0.935 <= rate <= 0.965


def test_ring_k0_is_the_closed_form():
    """A bore probed once at +X and once at -X: r0 = (D - (x_plus - x_minus)) / 2, X a
    radius in the part frame; with the sigma known, u(r0)^2 = sigma^2 / 2 + u(R)^2."""
    ring = CalibrationArtefact("ring", 50.0012, 0.0008, 2.0, (0.0, 0.0))
    x_plus, x_minus = 25.0006 + 0.003 - 2.9952, -25.0006 + 0.003 + 2.9952 + 0.0007
    cal = fit_probe_calibration(ring, [[x_plus, 5.0], [x_minus, 5.0]], [[1, 0], [-1, 0]],
                                sigma_declared=SIGMA,
                                options=CalibrationOptions(orders=(), sigma_known=True))  # fmt: skip
    assert abs(cal.r0 - (ring.diameter - (x_plus - x_minus)) / 2) < 1e-9
    assert abs(cal.cov[0, 0] - (SIGMA**2 / 2 + 0.0002**2)) < 1e-15
    # three points a side with noise, the residuals' sigma: the means' closed form
    rng = np.random.default_rng(4)
    xp = x_plus + rng.normal(0, SIGMA, 3)
    xm = x_minus + rng.normal(0, SIGMA, 3)
    pts = np.c_[np.r_[xp, xm], np.zeros(6)]
    app = np.r_[[[1, 0]] * 3, [[-1, 0]] * 3]
    cal = fit_probe_calibration(ring, pts, app, sigma_declared=SIGMA,
                                options=CalibrationOptions(orders="auto", loss="linear"))  # fmt: skip
    assert cal.orders == () and cal.dof == 4
    assert abs(cal.r0 - (ring.diameter - (xp.mean() - xm.mean())) / 2) < 1e-9
    # a diameter from outside: r0 = ((x_plus - x_minus) - D) / 2
    dia = CalibrationArtefact("diameter", 30.0021, 0.002, 2.0)
    xp, xm = 15.0 + 3.001, -15.002 - 3.001
    cal = fit_probe_calibration(dia, [[xp, 0], [xm, 0]], [[-1, 0], [1, 0]], sigma_declared=SIGMA,
                                options=CalibrationOptions(orders=(), sigma_known=True))  # fmt: skip
    assert abs(cal.r0 - ((xp - xm) - dia.diameter) / 2) < 1e-9


def test_ring_with_a_face_pair_averages_the_two_closed_forms():
    """Ring at +-X and a face pair of width W at -+Z: r0 is the mean of the ring's
    (D - (x+ - x-)) / 2 and the faces' ((z+ - z-) - W) / 2, and each certificate
    enters u(r0)^2 with a quarter of its variance."""
    art = CalibrationArtefact("ring", 50.0012, 0.0008, 2.0, (0.0, -10.0), 10.0004, 0.0006, 2.0)
    xp, xm, zp, zm = 22.0071, -22.0049, -10.0 + 5.0002 + 3.0015, -10.0 - 5.0002 - 2.9992
    pts = [[xp, -10.0], [xm, -10.0], [0.0, zp], [0.0, zm]]
    app = [[1, 0], [-1, 0], [0, -1], [0, 1]]
    cal = fit_probe_calibration(art, pts, app, sigma_declared=SIGMA,
                                options=CalibrationOptions(orders=(), sigma_known=True))  # fmt: skip
    want = 0.5 * ((art.diameter - (xp - xm)) / 2 + ((zp - zm) - art.face_width) / 2)
    assert abs(cal.r0 - want) < 1e-9
    u2 = SIGMA**2 / 4 + (0.0002**2 + 0.00015**2) / 4
    assert abs(cal.cov[0, 0] - u2) < 1e-15
    with pytest.raises(InputError, match="order 2 needs a sphere"):
        fit_probe_calibration(art, pts, app, sigma_declared=SIGMA,
                              options=CalibrationOptions(orders=(2,), sigma_known=True))  # fmt: skip


def test_orders_the_directions_cannot_separate_are_refused():
    th = np.radians([0.0, 180.0] * 6)
    a = np.c_[np.cos(th), np.sin(th)]
    p = np.array(SPHERE.centre) - (12.5002 + 3.0) * a
    with pytest.raises(InputError, match=r"order 3 needs approach directions spread over at "
                       r"least 7 distinct angles.*every 45 degrees.*the data have 0, 180 "
                       r"degrees only"):  # fmt: skip
        fit_probe_calibration(SPHERE, p, a, sigma_declared=SIGMA,
                              options=CalibrationOptions(orders=(2, 3)))  # fmt: skip
    # a quarter circle: full rank, badly conditioned
    th = np.radians(np.linspace(-45.0, 45.0, 24))
    a = np.c_[np.cos(th), np.sin(th)]
    p = np.array(SPHERE.centre) - (12.5002 + 3.0) * a
    with pytest.raises(InputError, match=r"condition number .* > 100"):
        fit_probe_calibration(SPHERE, p, a, sigma_declared=SIGMA,
                              options=CalibrationOptions(orders=(2, 3)))  # fmt: skip
    cal = fit_probe_calibration(SPHERE, p, a, sigma_declared=SIGMA)  # auto steps down
    assert cal.orders in ((), (2,))


def test_bayes_agrees_with_least_squares():
    sim = simulate_calibration(seed=2, directions="full")
    lsq = _fit(sim, loss="linear", sigma_known=True)
    bay = _fit(sim, method="bayes", sigma_known=True,
               sampling=replace(CALIBRATION_SAMPLING, nsteps=4000, seed=1))  # fmt: skip
    u = np.sqrt(np.diag(lsq.cov))
    assert np.all(np.abs(bay.coefficients - lsq.coefficients) < 0.1 * u)
    np.testing.assert_allclose(np.sqrt(np.diag(bay.cov)), u, rtol=0.1)
    assert math.isinf(bay.dof)


def test_a_controls_probeopen_file_read_against_its_plan_gives_the_csvs_calibration(tmp_path):
    """The same sphere run written as LinuxCNC's PROBEOPEN file (6 decimals) and read
    against the plan of its 24 probe moves (approach from the plan): the calibration
    equals the CSV's to the file's rounding (1e-6 mm)."""
    import json

    from piecs_bayes.jobs import calibrate_probe
    from piecs_bayes.simulate import write_calibration_sim

    write_calibration_sim(tmp_path, seed=3)
    csv_cal = calibrate_probe(tmp_path / "calibration.toml")
    rows = np.loadtxt(tmp_path / "cal_points.csv", delimiter=",", skiprows=1, usecols=(1, 2))
    centre = np.array([0.0, -40.0])
    a = (centre - rows) / np.linalg.norm(centre - rows, axis=1)[:, None]
    nominal = centre - (12.5002 + 3.0) * a
    pts = [{"index": i + 1, "feature": "sphere", "contact": list(nominal[i] + 3.0 * a[i]),
            "centre": list(nominal[i]), "approach": list(a[i]), "start": list(nominal[i] - a[i]),
            "target": list(nominal[i] + 0.5 * a[i])} for i in range(len(rows))]  # fmt: skip
    plan = {"format": "piecs_bayes probe plan 1", "units": "mm", "x": "radius",
            "program_x_mode": "radius", "controller": "linuxcnc", "points": pts}  # fmt: skip
    (tmp_path / "plan.json").write_text(json.dumps(plan))
    (tmp_path / "probe_points.txt").write_text("".join(
        f"{x:f} 0.000000 {z:f} 0.000000 0.000000 0.000000 0.000000 0.000000 0.000000\n"
        for x, z in rows))  # fmt: skip
    text = (tmp_path / "calibration.toml").read_text()
    text = text.replace(
        'file = "cal_points.csv"\nformat = "csv"\nx_mode = "radius"',
        'file = "probe_points.txt"\nformat = "linuxcnc"\nplan = "plan.json"',
    )
    (tmp_path / "control.toml").write_text(text)
    cal = calibrate_probe(tmp_path / "control.toml")
    assert cal.orders == csv_cal.orders
    np.testing.assert_allclose(cal.coefficients, csv_cal.coefficients, atol=1e-6)
    np.testing.assert_allclose(np.sqrt(np.diag(cal.cov)), np.sqrt(np.diag(csv_cal.cov)), rtol=1e-3)
