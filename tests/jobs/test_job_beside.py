"""The main job computes the steps that need only the robust fit (decisions, the
adjusted path, its linearised uncertainty) in a thread while the sampler runs
(`jobs._main._Beside`): the same results as computed in turn, and a failure there is
the step's, as if it had run in turn."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.errors import AnalysisError
from piecs_bayes.io import load_study
from piecs_bayes.jobs import JobOptions, _main, run_job

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"
#: a short run (not converged, said and ignored here): only that the sampler runs beside
pytestmark = pytest.mark.filterwarnings("ignore:MCMC run has not converged")
OPTIONS = JobOptions(nsteps=400, program=False, errspec=False, capability=False)


@pytest.fixture(scope="module")
def study():
    return load_study(DEMO)


def _in_turn(monkeypatch):
    """Computed in the job's own thread, when the decisions step asks (as without the
    Bayesian fit)."""
    monkeypatch.setattr(_main._Beside, "start", lambda self: None)


def test_beside_the_sampler_equals_in_turn(study, monkeypatch):
    beside = run_job(study, OPTIONS)
    _in_turn(monkeypatch)
    turn = run_job(study, OPTIONS)
    assert dict(beside.gains) == dict(turn.gains)
    assert [d.verdict for d in beside.decisions.decisions] == [
        d.verdict for d in turn.decisions.decisions
    ]
    np.testing.assert_allclose(beside.path.vertices, turn.path.vertices, rtol=0, atol=1e-15)
    for key in ("linearised", "monte_carlo"):
        a, b = beside.uncertainty[key], turn.uncertainty[key]
        np.testing.assert_allclose(a.vertex_cov, b.vertex_cov, rtol=1e-12, atol=0)
        np.testing.assert_allclose(a.offset_sd, b.offset_sd, rtol=1e-12, atol=0)
    assert set(beside.timings) == set(turn.timings) >= {"decisions", "path", "uncertainty"}
    assert beside.bayes_characteristics == turn.bayes_characteristics


def test_a_failure_beside_the_sampler_is_raised_by_the_job(study, monkeypatch):
    def broken(*_a, **_k):
        raise RuntimeError("a bug in the decisions")

    monkeypatch.setattr(_main, "decide_study", broken)
    with pytest.raises(RuntimeError, match="a bug in the decisions"):
        run_job(study, OPTIONS)


def test_a_decision_that_cannot_be_made_is_unavailable_and_the_job_goes_on(study, monkeypatch):
    def refused(*_a, **_k):
        raise AnalysisError("no decision for this part")

    monkeypatch.setattr(_main, "decide_study", refused)
    res = run_job(study, OPTIONS)
    assert res.unavailable["decisions"] == "no decision for this part"
    assert res.decisions is None and res.bayes is not None
    assert set(res.gains.values()) == {study.compensation.gain}  # the study's gain drives
    assert res.path is not None and res.uncertainty["monte_carlo"] is not None
