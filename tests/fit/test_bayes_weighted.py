"""Points left out of a Bayesian batch by weight: one compiled log posterior for parts
that differ only in which points the robust fit flagged.

`fit_profiles_bayes(inlier=...)` weighs the flagged points 0 in the likelihood, so the
log posterior of a part equals that of its inliers alone (the model the part would
get without the weights) at every parameter vector, and all parts of one trigger
pattern share one model. A part that would lose every point of a feature is fitted on
its inliers alone (that feature then has no parameters).
"""

from __future__ import annotations

from dataclasses import replace

import jax
import numpy as np

from piecs_bayes.fit import (
    BAYES_SAMPLING,
    BayesOptions,
    fit_profiles_bayes,
    profile_log_posterior,
)
from piecs_bayes.fit import _bayes_profile as bp
from piecs_bayes.geometry import MachineTransform
from piecs_bayes.simulate import (
    DEMO_ERRORS,
    SimulatedProbing,
    demo_profile,
    process_deviations,
    simulate_parts,
)

PROFILE = demo_profile()
FEW = {"face_end": 3, "dia_24": 8, "taper": 4, "dia_30": 5, "fillet": 5, "shoulder": 6, "dia_44": 7}
SOURCES = {
    "x_centre": {"dist": "normal", "mean": 0.0, "sd": 0.001},
    "repeatability": {"dist": "scaled_inv_chi2", "nu": 8.0, "scale": 0.0015},
}


def _sim(n_parts=3, seed=5):
    truth = process_deviations(PROFILE, DEMO_ERRORS)
    return simulate_parts(PROFILE, truth, n_parts, rng=seed, probing=SimulatedProbing(
        ball_radius=1.0, points=FEW, noise_sd=0.0015, margin=0.12))  # fmt: skip


def _model(ids, weighted=False):
    """The log posterior (jitted: one program, not one per operation), its layout, ..."""
    log_prob, *rest = profile_log_posterior(
        PROFILE, ids, options=BayesOptions(sources=SOURCES, ball_radius=1.0,
                                           transform=MachineTransform(), sigma=0.0015),
        weighted=weighted,
    )  # fmt: skip
    return (jax.jit(log_prob), *rest)


def test_weighted_log_posterior_equals_the_inliers_alone():
    sim = _sim(1)
    ids, pts = sim["feature"], sim["points"]
    keep = np.ones(ids.size, bool)
    keep[[1, 9, 20]] = False  # three points of three features, each keeps others
    full, lay, _ = _model(ids, weighted=True)
    sub, lay_sub, _ = _model(ids[keep])
    assert lay.names == lay_sub.names
    rng = np.random.default_rng(0)
    for _ in range(5):
        theta = rng.normal(0.0, 0.002, len(lay.names))
        theta[lay.sigma_index] = 0.0015 * rng.uniform(0.5, 2.0)
        a = float(full(theta, (pts, None, keep * 1.0)))
        b = float(sub(theta, (pts[keep], None)))
        assert abs(a - b) <= 1e-10 * abs(b), (a, b)
        # all weights 1: the plain model
        c = float(full(theta, (pts, None, np.ones(ids.size))))
        d = float(_model(ids)[0](theta, (pts, None)))
        assert abs(c - d) <= 1e-10 * abs(d)


def test_parts_that_flag_other_points_share_one_model():
    sim = _sim(4)  # part 3 flags nothing
    part, ids, pts = sim["part"], sim["feature"], sim["points"]
    n = ids.size // 4
    keep = np.ones(ids.size, bool)
    keep[[2, n + 5]] = False  # parts 0 and 1 flag one point each (other features)
    keep[2 * n : 2 * n + 3] = False  # part 2 flags every point of face_end
    starts = {p: {f.id: np.zeros(f.nparams) for f in PROFILE.features} for p in np.unique(part)}
    bp._model.cache_clear()
    posts = fit_profiles_bayes(
        PROFILE, part, ids, pts, starts=starts,
        options=BayesOptions(sources=SOURCES, ball_radius=1.0, sigma=0.0015),
        sampling=replace(BAYES_SAMPLING, nsteps=60, n_ensembles=1, progress=False,
                         on_fail="ignore"), inlier=keep,
    )  # fmt: skip
    # one weighted model for parts 0 and 1 (and any part that flags nothing), one of
    # part 2's inliers alone
    assert bp._model.cache_info().currsize == 2
    p0, p1, p2, p3 = (posts[p] for p in dict.fromkeys(part.tolist()))
    assert len(p3.data.feature_ids) == n
    assert len(p0.data.feature_ids) == len(p1.data.feature_ids) == n - 1
    assert np.array_equal(p0.data.machine_points, pts[:n][keep[:n]])
    assert "face_end" in p0.deviation_samples and "face_end" not in p2.deviation_samples
    # the stored data give the log likelihood of the points fitted, summed as sampled
    ll = p0.log_likelihood()
    assert ll.shape[-1] == n - 1 and np.all(np.isfinite(ll))
