"""The ensemble sampler's `SamplerOptions`: the defaults `sample_posterior` and
`sample_posteriors` had as keywords, and their refusals (the samplers' messages)."""

from __future__ import annotations

import inspect

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.fit.mcmc import SamplerOptions, sample_posterior, sample_posteriors


def test_defaults_are_the_keywords_they_replace():
    s = SamplerOptions()
    assert (s.nwalkers, s.nsteps, s.burn, s.thin, s.seed, s.progress) == (
        None, 2000, None, "auto", 0, True
    )  # fmt: skip
    assert (s.n_ensembles, s.init_scale, s.on_fail) == (4, 1.0, "warn")
    assert (s.rhat_max, s.min_ess, s.tau_factor, s.moves, s.sampler) == (
        1.01, 400.0, 50.0, None, "emcee"
    )  # fmt: skip
    for fn in (sample_posterior, sample_posteriors):
        assert inspect.signature(fn).parameters["options"].default == s
    assert inspect.signature(sample_posteriors).parameters["backend"].default == "jax"
    assert s.criteria == {"rhat_max": 1.01, "min_ess": 400.0, "tau_factor": 50.0}


def test_for_dim_fills_the_defaults_that_depend_on_the_dimension():
    s = SamplerOptions(nsteps=400).for_dim(3)
    assert (s.nwalkers, s.burn, s.moves, s.thin) == (64, 100, "stretch", "auto")
    assert SamplerOptions().for_dim(21).nwalkers == 84
    assert SamplerOptions(nwalkers=10, burn=7, moves="de", thin=3).for_dim(2).nwalkers == 10


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"on_fail": "maybe"}, r"^on_fail: got 'maybe', expected 'warn', 'raise' or 'ignore'$"),
        ({"thin": 0}, r"^thin: got 0, expected an integer >= 1 or 'auto'$"),
        ({"thin": True}, r"^thin: got True, expected an integer >= 1 or 'auto'$"),
        ({"moves": "de_snooker"}, r"^moves: got 'de_snooker', expected None, 'stretch', 'de'; "),
        ({"nsteps": 9}, r"^nsteps=9, burn=2, thin=1: expected 0 <= burn < nsteps, thin >= 1 "),
        ({"nsteps": 100, "burn": 100}, r"^nsteps=100, burn=100, thin=1: expected"),
        ({"nsteps": 100, "thin": 10}, r"^nsteps=100, burn=25, thin=10: expected"),
        ({"n_ensembles": 0}, r"^n_ensembles: got 0, expected >= 1$"),
        ({"sampler": "nuts"}, r"^sampler: got 'nuts', expected 'emcee' or 'lockstep'$"),
    ],
)
def test_bad_values_are_refused_as_before(kwargs, match):
    with pytest.raises(InputError, match=match):
        SamplerOptions(**kwargs)
