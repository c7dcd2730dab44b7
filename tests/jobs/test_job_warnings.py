"""The main job's recorded warnings (the report's "Warnings issued during the run"): the
Bayesian step records every warning its sampler raises, but arviz's import notice,
which the CLI's prefetch thread can raise while the step records (the golden demo's
report listed it whenever the fit was done before arviz was imported)."""

from __future__ import annotations

import warnings
from types import SimpleNamespace

from piecs_bayes.jobs import _main

NOTICE = (
    "\nArviZ is undergoing a major refactor to improve flexibility and extensibility "
    "while maintaining a user-friendly interface."
)


class _Say:
    bar = False

    def __call__(self, *args, **kwargs):
        pass


def test_the_bayesian_step_records_its_warnings_but_arvizs_notice(monkeypatch):
    def bayes_study(*args, **kwargs):
        warnings.warn(NOTICE, FutureWarning, stacklevel=1)  # as arviz's import does
        warnings.warn("the chains did not converge", UserWarning, stacklevel=1)

    monkeypatch.setattr(_main, "bayes_study", bayes_study)
    study = SimpleNamespace(fit=SimpleNamespace(bayes_steps=10, bayes_ensembles=2))
    run = _main._Run(study=study, probe=None, say=_Say(), fit=SimpleNamespace(part=None))
    with warnings.catch_warnings(record=True) as outside:
        warnings.simplefilter("always")
        _main._step_bayes(run, True, None, 0)
    assert run.caught == ["the chains did not converge"]
    assert [str(w.message) for w in outside] == ["the chains did not converge"]
    assert run.out["bayes"] is None
