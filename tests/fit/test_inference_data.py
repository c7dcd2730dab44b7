"""posterior.nc as an ArviZ InferenceData: groups, dims, units, attrs, the pointwise
log likelihood (the fit's own, for `az.loo`) and R-hat / ESS parity with the report.

One short run of the demo part (2 ensembles x 200 steps: not converged, which does
not matter here) is shared by the tests.
"""

from __future__ import annotations

import dataclasses
import functools
import json
import warnings
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.fit import BayesOptions
from piecs_bayes.fit._bayes_profile import _model, _model_key
from piecs_bayes.fit._inference_data import keep_bits, parameter_locations
from piecs_bayes.fit.mcmc._posterior import import_arviz
from piecs_bayes.io import load_study
from piecs_bayes.jobs import bayes_study, fit_study, load_probe_data

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"
UNITS = {"mm", "rad", "1"}


@functools.cache
def _demo_fit():
    study = load_study(DEMO)
    probe = load_probe_data(study)
    fit = fit_study(study, probe)
    bayes = bayes_study(
        study, fit, probe, nsteps=200, n_ensembles=2, seed=3, progress=False, on_fail="ignore"
    )
    return study, bayes, bayes.to_arviz()


@pytest.fixture
def demo():
    return _demo_fit()


def test_groups_dims_and_units(demo):
    study, bayes, idata = demo
    assert set(idata.groups()) == {
        "posterior", "sample_stats", "observed_data", "log_likelihood", "prior"
    }  # fmt: skip
    post = idata.posterior
    k, n = bayes.posterior.arviz_chains.shape[:2]
    assert (post.sizes["chain"], post.sizes["draw"]) == (2, n) and k == 2
    lines = [f.id for f in study.profile.features if f.kind == "line"]
    assert post["offset"].dims == ("chain", "draw", "line_feature")
    assert post["line_feature"].values.tolist() == lines
    assert post["radius"].dims == ("chain", "draw", "arc_feature")
    assert post["rotation"].attrs["units"] == "rad" and post["offset"].attrs["units"] == "mm"
    assert post["sigma"].dims == ("chain", "draw") and post["scale_x"].attrs["units"] == "1"
    for group in idata.groups():
        for name, var in idata[group].data_vars.items():
            assert var.attrs.get("units") in UNITS, (group, name)
    # every parameter appears once, at its place
    locs = parameter_locations(bayes.layout, bayes.units)
    assert [loc[0] for loc in locs] == list(bayes.names)


def test_observed_data_are_the_points_used_with_their_file_lines(demo):
    study, bayes, idata = demo
    obs = idata.observed_data["ball_centre"]
    d = bayes.data
    assert obs.dims == ("point", "axis") and obs.shape == (len(d.feature_ids), 2)
    assert obs["feature"].values.tolist() == d.feature_ids.tolist()
    assert obs["line"].values.tolist() == np.asarray(d.lines).tolist()
    assert obs["line"].values.min() > 1  # file lines, after the header
    from piecs_bayes.fit import to_part_frame

    assert np.allclose(obs.values, to_part_frame(study.transform, d.machine_points))


def test_attrs_name_the_run_and_the_priors(demo):
    study, bayes, idata = demo
    post = bayes.posterior
    for attrs in (idata.attrs, idata.posterior.attrs):
        assert attrs["piecs_bayes_version"]
        assert attrs["sampler"].startswith("piecs_bayes lockstep") and attrs["moves"] == "de"
        run = (attrs["nsteps"], attrs["burn"], attrs["thin"])
        assert run == (post.nsteps, post.burn, post.thin)
        assert (attrs["n_ensembles"], attrs["nwalkers"]) == (2, post.nwalkers)
    assert json.loads(idata.attrs["prior_sources"]) == bayes.data.sources
    assert "repeatability" in bayes.data.sources  # the demo estimates sigma: drawn as `sigma`
    assert idata.prior["sigma"].shape[0] == 1 and np.all(idata.prior["sigma"].values > 0)


def test_log_likelihood_sums_to_the_fits_own_and_loo_runs(demo):
    _, bayes, idata = demo
    ll = bayes.log_likelihood()  # (chain, draw, point), float64
    lp = bayes.posterior.arviz_log_prob
    chains = bayes.posterior.arviz_chains
    priors = bayes._model().priors
    log_prior = sum(
        np.asarray(priors[name].log_pdf(chains[..., k])) for name, k in bayes.layout.nuisance
    ) + np.asarray(priors["repeatability"].log_pdf(chains[..., bayes.layout.sigma_index]))
    assert np.allclose(ll.sum(axis=-1) + log_prior, lp, rtol=0, atol=1e-8)
    stored = idata.log_likelihood["ball_centre"]
    assert stored.dims == ("chain", "draw", "point") and stored.dtype == np.float64
    assert np.allclose(stored.values, ll, rtol=2.0**-24, atol=0)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", UserWarning)  # Pareto k of a 200-step run
        loo = import_arviz().loo(idata)
    assert np.isfinite(loo.elpd_loo) and loo.n_data_points == ll.shape[-1]


def test_pointwise_log_likelihood_is_the_model_likelihood_student_t(demo):
    """The Gaussian case is checked on every draw above; the Student-t one here."""
    study, bayes, _ = demo
    likelihood = "student_t"
    d = bayes.data
    options = BayesOptions(
        sources=d.sources, ball_radius=d.ball_radius, sigma=d.sigma, transform=d.transform,
        likelihood=likelihood, nu=4.0, file=d.file,
    )  # fmt: skip
    key = _model_key(study.profile, d.feature_ids, options, d.approach is not None)
    m = _model(*key)
    theta = jnp.asarray(bayes.posterior.samples[7])
    args = (jnp.asarray(d.machine_points), None)
    point = np.asarray(jax.jit(m.pointwise)(theta, args))  # one program, not op by op
    lay = m.layout
    log_prior = sum(float(m.priors[n].log_pdf(theta[k])) for n, k in lay.nuisance)
    log_prior += float(m.priors["repeatability"].log_pdf(theta[lay.sigma_index]))
    assert point.shape == (len(d.feature_ids),) and np.all(np.isfinite(point))
    assert point.sum() + log_prior == pytest.approx(
        float(jax.jit(m.log_prob)(theta, args)), abs=1e-9
    )


def test_posterior_nc_gives_the_reported_rhat_and_ess(demo, tmp_path):
    """Parity on the stored file: `az.summary` of posterior.nc shows the R-hat and ESS
    the package reports (`Posterior.rhat`, `.ess`), parameter by parameter."""
    _, bayes, _ = demo
    az = import_arviz()
    back = az.from_netcdf(bayes.to_netcdf(tmp_path / "posterior.nc"))
    table = az.summary(back, round_to="none")
    post = bayes.posterior
    for name, var, dim, coord, col, _ in parameter_locations(bayes.layout, bayes.units):
        row = var if dim is None else f"{var}[{coord}]"
        assert table.loc[row, "r_hat"] == pytest.approx(post.rhat[col], rel=1e-12), name
        assert table.loc[row, "ess_bulk"] == pytest.approx(post.ess[col], rel=1e-9), name
        stored = back.posterior[var] if dim is None else back.posterior[var].sel({dim: coord})
        assert np.array_equal(stored.values, post.arviz_chains[..., col])
    assert back.observed_data["line"].dtype.kind == "i"


def test_a_fit_without_data_points_to_the_plain_form(demo):
    _, bayes, _ = demo
    bare = dataclasses.replace(bayes, data=None)
    with pytest.raises(InputError, match="posterior.to_arviz"):
        bare.to_arviz()
    assert "posterior" in bare.posterior.to_arviz().groups()


def test_keep_bits_rounds_to_the_kept_mantissa_and_keeps_inf_and_nan():
    rng = np.random.default_rng(0)
    x = rng.normal(scale=1e3, size=10_000)
    y = keep_bits(x, 23)
    assert np.max(np.abs(y / x - 1)) <= 2.0**-24
    assert np.all(y.view(np.uint64) & np.uint64((1 << 29) - 1) == 0)  # low 29 bits cleared
    assert np.array_equal(keep_bits(y, 23), y)  # idempotent
    special = keep_bits(np.array([np.inf, -np.inf, np.nan, 0.0, 1.0]), 23)
    assert special[0] == np.inf and special[1] == -np.inf and np.isnan(special[2])
    assert special[3:].tolist() == [0.0, 1.0]
