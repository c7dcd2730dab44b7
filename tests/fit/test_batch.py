"""Batch fits of many parts (issue 8): the same numbers as the per-part loop, failures
reported by status, the loop's input errors; lockstep ensembles against emcee.

Compilation dominates: every batch test uses the batch study's first 12 parts so
that the groups (line/8, line/16, arc/8) compile once per loss.
"""

from dataclasses import replace
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.fit import FitOptions, fit_profiles, to_part_frame
from piecs_bayes.fit.lsq import Status
from piecs_bayes.fit.mcmc import SamplerOptions, sample_posterior, sample_posteriors
from piecs_bayes.io import load_study
from piecs_bayes.jobs import (
    fit_study,
    fit_study_batch,
    load_probe_data,
    path_uncertainty_batch,
    robust_scale,
)
from piecs_bayes.uncertainty import LinearisedOptions, linearised_toolpath

BATCH = Path(__file__).resolve().parents[2] / "data" / "batch" / "study.toml"


@pytest.fixture(scope="module")
def study_probe():
    study = load_study(BATCH)
    files = sorted(study.path.parent.glob("part*.csv"))[:12]
    probe = load_probe_data(study, files)
    pts = probe.points.copy()
    # a chip under the stylus on part03's dia_30 (pushed out 0.15 mm, radius X)
    rows = np.flatnonzero((probe.part == "part03") & (probe.feature == "dia_30"))
    pts[rows[4], 0] += 0.15
    # part05 did not measure the shoulder
    keep = ~((probe.part == "part05") & (probe.feature == "shoulder"))
    return study, replace(probe, points=pts).select(keep)


def _assert_same_fit(loop, batch):
    assert loop.part == batch.part and loop.unmeasured == batch.unmeasured
    assert list(loop.fits) == list(batch.fits)
    for fid, a in loop.fits.items():
        b = batch[fid]
        assert a.method == b.method and a.fixed == b.fixed
        assert a.result.status == b.result.status
        np.testing.assert_array_equal(a.lines, b.lines)
        np.testing.assert_array_equal(a.points, b.points)
        np.testing.assert_array_equal(a.outliers, b.outliers)
        # the same minimum, to the solver's own precision (~1e-10 mm on robust fits)
        np.testing.assert_allclose(b.values, a.values, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.std_errors, a.std_errors, rtol=1e-6)
        assert np.all(np.abs(b.values - a.values) <= 1e-5 * np.maximum(a.std_errors, 1e-12))
        np.testing.assert_allclose(b.residuals, a.residuals, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.weights, a.weights, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(b.error_vectors, a.error_vectors, rtol=0, atol=1e-9)
        assert b.result.n == a.result.n and b.result.dof == a.result.dof
        np.testing.assert_allclose(b.residual_sd, a.residual_sd, rtol=1e-6)


def test_robust_batch_equals_the_loop(study_probe):
    study, probe = study_probe
    study = replace(study, fit=replace(study.fit, fix=("fillet.radius",)))
    batch = fit_study_batch(study, probe)
    assert len(batch) == 12 and batch.method == "robust/huber"
    assert batch.ok.all() and batch.failures == []
    for i, part in enumerate(probe.parts):
        _assert_same_fit(
            fit_study(study, probe.for_part(part), solver="lm"), batch.profile_fit(part)
        )
        assert batch.part_error(i) is None
    # the chip is flagged, the unmeasured feature is NaN / status -1
    i3 = batch.parts.index("part03")
    assert batch.n_outliers("dia_30")[i3] == 1 and batch.n_outliers("dia_30").sum() == 1
    chip = np.flatnonzero((probe.part == "part03") & (probe.feature == "dia_30"))[4]
    assert np.flatnonzero(batch.outlier_mask).tolist() == [chip]
    i5 = batch.parts.index("part05")
    assert batch.status("shoulder")[i5] == -1 and np.isnan(batch.values("shoulder")[i5]).all()
    assert np.isnan(batch.covariance("shoulder")[i5]).all()
    assert batch.profile_fit("part05").unmeasured == ("shoulder",)
    assert np.all(batch.values("fillet")[:, 2] == 0.0)
    assert np.all(batch.covariance("fillet")[:, 2, :] == 0.0)
    rows = batch.rows()
    assert len(rows) == 12 * 15 - 2 and {r["status"] for r in rows} == {"SUCCESSFUL"}
    assert "12 parts" in repr(batch) and "0 failed" in repr(batch)


def test_densely_probed_features_equal_the_loop():
    """Features in a 64-point bucket are fitted by the batch kernel (it once hung in
    XLA's CPU runtime there, docs/xla_batched_svd_deadlock.md, and they went to LM), twice,
    the same, with no Levenberg-Marquardt retry (`"fast"` has none: the same)."""
    import sys

    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "benchmarks"))
    from _common import simulate_fleet

    from piecs_bayes.fit import fit_profile
    from piecs_bayes.simulate import DEMO_TRANSFORM

    fleet = simulate_fleet(3, seed=5, points=40)
    c = to_part_frame(DEMO_TRANSFORM, fleet["points"])
    opts = FitOptions(method="robust", loss="huber", scale=1.345 * 0.0015)
    kw = dict(ball_radius=1.0, options=opts)
    args = (fleet["profile"], fleet["part"], fleet["feature"], c)
    first, batch = (fit_profiles(*args, **kw) for _ in range(2))
    fast = fit_profiles(*args, ball_radius=1.0, options=replace(opts, solver="fast"))
    assert batch.ok.all() and fast.ok.all()
    assert {g.n_pad for g in batch.groups} == {64}
    for f in fleet["profile"]:
        np.testing.assert_array_equal(batch.values(f.id), first.values(f.id))
        np.testing.assert_array_equal(batch.values(f.id), fast.values(f.id))
    for part in np.unique(fleet["part"]):
        m = fleet["part"] == part
        loop = fit_profile(fleet["profile"], fleet["feature"][m], c[m], **kw)
        for f in fleet["profile"]:
            got = batch.profile_fit(str(part))[f.id]
            np.testing.assert_allclose(got.values, loop[f.id].values, rtol=0, atol=1e-9)
            np.testing.assert_allclose(got.std_errors, loop[f.id].std_errors, rtol=1e-6)


def test_plain_batch_and_its_path_uncertainty_equal_the_loop(study_probe):
    study, probe = study_probe
    study = replace(study, fit=replace(study.fit, known_sigma=True))
    probe = probe.select(np.isin(probe.feature, ["dia_24", "fillet"]))  # two groups: faster
    batch = fit_study_batch(study, probe, method="lsq", chunk_size=5)
    assert batch.method == "lsq" and batch.feature_ids == ("dia_24", "fillet")
    for part in probe.parts[:6]:
        loop = fit_study(study, probe.for_part(part), method="lsq", solver="lm")
        _assert_same_fit(loop, batch.profile_fit(part))
    # GUM through the adjusted path, all parts at once, against the one-part
    # propagation from the probe points (known sigma: the same covariance)
    paths = path_uncertainty_batch(batch, gain=0.8)
    one = probe.for_part("part04")
    ref = linearised_toolpath(
        study.profile, one.feature, one.points, batch.profile_fit("part04").deviations,
        sigma=study.probe.repeatability, options=LinearisedOptions(
            ball_radius=study.probe.ball_radius, transform=study.transform, gain=0.8),
    )  # fmt: skip
    i = batch.parts.index("part04")
    np.testing.assert_allclose(paths.offset[i], ref.offset, rtol=0, atol=1e-12)
    np.testing.assert_allclose(paths.vertices[i], ref.vertices, rtol=0, atol=1e-12)
    np.testing.assert_allclose(paths.offset_sd[i], ref.offset_sd, rtol=1e-6, atol=1e-12)
    np.testing.assert_allclose(paths.vertex_sd[i], ref.vertex_sd, rtol=1e-6, atol=1e-12)


def test_failures_are_reported_with_the_loops_message(study_probe):
    study, probe = study_probe
    on = probe.feature == "dia_24"
    pts = np.array(to_part_frame(study.transform, probe.points[on]))
    part = probe.part[on]
    bad = np.flatnonzero(part == "part07")[2]
    pts[bad] = np.nan
    opts = FitOptions(method="robust", loss="huber", scale=robust_scale(study))
    kw = dict(ball_radius=study.probe.ball_radius, options=opts)
    batch = fit_profiles(study.profile, part, probe.feature[on], pts, **kw)
    i7 = batch.parts.index("part07")
    assert batch.failures == [("part07", "dia_24", Status.NONFINITE)]
    assert batch.ok.tolist() == [i != i7 for i in range(12)]
    assert batch.status("dia_24")[i7] == Status.NONFINITE
    mask = part == "part07"
    with pytest.raises(AnalysisError) as exc:
        from piecs_bayes.fit import fit_profile

        fit_profile(study.profile, probe.feature[on][mask], pts[mask], part="part07", **kw)
    assert batch.part_error("part07") == str(exc.value)
    assert "1 failed" in repr(batch) and "NONFINITE" in repr(batch)


def _three_point_faces(n_parts, seed=1):
    """`n_parts` parts of the demo's end face probed at 3 points (1 residual dof), each
    point 1.5 um of noise off the face: under Huber with the scale estimated, most
    such fits keep fewer effective points than parameters + 1 (DEGENERATE)."""
    from piecs_bayes.simulate import demo_profile

    profile = demo_profile()
    face = next(f for f in profile.features if f.id == "face_end")
    surface = np.asarray(face.point_at(jnp.array([0.2, 0.5, 0.8])))
    normal = np.asarray(face.outward_normal(surface))
    noise = np.random.default_rng(seed).normal(0.0, 0.0015, (n_parts, 3))
    pts = (surface[None] + (1.0 + noise)[..., None] * normal[None]).reshape(-1, 2)
    parts = np.repeat([f"p{i:02d}" for i in range(n_parts)], 3)
    return profile, parts, np.full(parts.size, "face_end"), pts


def test_what_the_kernel_leaves_is_solved_as_the_loop_solves_it():
    """`solver="auto"` sends each problem the kernel did not solve to the loop's own
    Levenberg-Marquardt solve (`fit_feature`), one by one: such a part's status and
    failure message, or its fit, are the loop's; the rest keep the kernel's. Equally
    spaced 3-point faces under Huber are the hard case: most are DEGENERATE, and the
    kernel and LM part ways on which (their residual pattern puts the middle point
    on the edge of Huber's zone)."""
    from piecs_bayes.fit import _batch_solve, fit_profile

    profile, parts, ids, pts = _three_point_faces(24)
    opts = FitOptions(method="robust", loss="huber")
    batched_lm = _batch_solve._engine_group_solver.cache_info().misses
    auto = fit_profiles(profile, parts, ids, pts, ball_radius=1.0, options=opts)
    # no batched LM built for the retries (a compilation of 8-15 s)
    assert _batch_solve._engine_group_solver.cache_info().misses == batched_lm
    fast = fit_profiles(profile, parts, ids, pts, ball_radius=1.0,
                        options=replace(opts, solver="fast"))  # fmt: skip
    kernel_ok = fast.status("face_end") == Status.SUCCESSFUL
    retried_ok = ~kernel_ok & (auto.status("face_end") == Status.SUCCESSFUL)
    assert 5 <= np.sum(~kernel_ok) < 24 and retried_ok.any()  # LM solves some of them
    for i, part in enumerate(auto.parts):
        if kernel_ok[i]:
            assert auto.status("face_end")[i] == Status.SUCCESSFUL
            np.testing.assert_array_equal(auto.values("face_end")[i], fast.values("face_end")[i])
            continue
        rows = parts == part
        try:
            loop = fit_profile(profile, ids[rows], pts[rows], part=part, ball_radius=1.0,
                               options=replace(opts, solver="lm"),
                               lines=np.flatnonzero(rows) + 1)  # fmt: skip
        except AnalysisError as exc:
            assert auto.part_error(part) == str(exc)
        else:
            _assert_same_fit(loop, auto.profile_fit(part))


def test_input_errors_match_the_loop(study_probe):
    study, probe = study_probe
    few = ~((probe.part == "part02") & (probe.feature == "taper")) | (
        np.cumsum((probe.part == "part02") & (probe.feature == "taper")) <= 2
    )
    short = probe.select(few)
    with pytest.raises(InputError) as loop:
        fit_study(study, short.for_part("part02"))
    with pytest.raises(InputError) as batch:
        fit_study_batch(study, short)
    assert str(batch.value) == str(loop.value)
    assert "2 point(s) are too few for a line" in str(batch.value)
    with pytest.raises(InputError, match="unknown feature id 'groove'"):
        fit_profiles(study.profile, ["a"] * 3, ["groove"] * 3, np.zeros((3, 2)), ball_radius=1.0)


# --------------------------------------------------------------------------- Bayes


def _gauss(theta, args):
    mu, chol = args
    r = jnp.linalg.solve(chol, theta - mu)
    return -0.5 * r @ r


@pytest.mark.parametrize("backend", ["jax", "numpy"])
def test_lockstep_ensembles_sample_each_parts_posterior_like_emcee(backend):
    rng = np.random.default_rng(3)
    mus = rng.normal(size=(3, 2))
    base = np.array([[1.0, 0.0], [0.95, 0.3]])
    chols = np.stack([base * (1.0 + 0.5 * k) for k in range(3)])
    opts = SamplerOptions(nwalkers=32, nsteps=1500, progress=False, on_fail="ignore")
    kw = dict(names="ab", options=opts)
    posts = sample_posteriors(_gauss, mus, args=(mus, chols), names="ab",
                              options=replace(opts, seed=1), backend=backend)  # fmt: skip
    ref = sample_posterior(_gauss, mus[2], args=(jnp.asarray(mus[2]), jnp.asarray(chols[2])), **kw)
    for k, post in enumerate(posts):
        sd = np.sqrt(np.diag(chols[k] @ chols[k].T))
        assert np.all(np.abs(post.mean - mus[k]) < 5 * post.mcse)
        np.testing.assert_allclose(post.sd, sd, rtol=0.06)
        # thin="auto": about tau / 2 of the 1125 kept steps
        assert post.thin > 1 and post.chains.shape == (
            len(range(post.thin - 1, 1125, post.thin)),
            128,
            2,
        )
        assert post.n_ensembles == 4
        assert np.all(post.rhat < 1.02)
    # same moves and acceptance rule as emcee: the same acceptance and mixing
    assert abs(posts[2].acceptance_fraction.mean() - ref.acceptance_fraction.mean()) < 0.03
    np.testing.assert_allclose(posts[2].tau, ref.tau, rtol=0.35)
    if backend == "numpy":  # the DE moves (one more compilation of the jax chain: skipped)
        de = sample_posteriors(_gauss, mus, args=(mus, chols), names="ab",
                               options=replace(opts, moves="de"), backend=backend)  # fmt: skip
        for k, post in enumerate(de):
            assert np.all(np.abs(post.mean - mus[k]) < 5 * post.mcse)
    with pytest.raises(InputError, match="leading axis of 3 parts"):
        sample_posteriors(_gauss, mus, args=(mus[:2], chols), **kw)
