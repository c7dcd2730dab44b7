"""The Bayesian sampler's traces kept across processes (issue 39): the start ball's
Hessian, the log posterior over walkers and the lock-step runner of a profile model are
traced once and read back by a later process (`mcmc._core.kept_trace`, named by the
model's `trace_key`), and the draws are those of the run that traced them."""

from __future__ import annotations

import functools
from collections import Counter
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring

from piecs_bayes import _config
from piecs_bayes.fit import _bayes_profile
from piecs_bayes.fit.mcmc import _core, _lockstep
from piecs_bayes.io import load_study
from piecs_bayes.jobs import bayes_study, fit_study, load_probe_data

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"
TRACED: Counter = Counter()


def _on_duration(event, duration_secs, fun_name="?", **_):
    if event == "/jax/core/compile/jaxpr_trace_duration":
        TRACED[fun_name] += 1


monitoring.register_event_duration_secs_listener(_on_duration)


@functools.cache
def _demo():
    study = load_study(DEMO)
    probe = load_probe_data(study)
    return study, probe, fit_study(study, probe, method="robust")


def _new_process():
    """What a new process starts from: no model, jitted function or kept trace in
    memory (the files on disk stay)."""
    for cached in (_bayes_profile._model, _core._neg_hessian, _core.neg_hessians,
                   _lockstep._parts_walkers, _lockstep._jax_chain, _lockstep._kept_chain):  # fmt: skip
        cached.cache_clear()


def _posterior():
    study, probe, fit = _demo()
    return bayes_study(
        study, fit, probe, nsteps=300, n_ensembles=2, seed=5, progress=False, on_fail="ignore"
    ).posterior


def test_a_later_process_reads_the_traces_and_draws_the_same(tmp_path, monkeypatch):
    pytest.importorskip("flatbuffers")  # jax.export's serialisation needs it
    monkeypatch.delenv("PIECS_BAYES_NO_CACHE", raising=False)
    monkeypatch.setattr(_config, "_cache_dir", lambda: tmp_path / "piecs_bayes" / "jax")
    _new_process()
    first = _posterior()
    kept = sorted(p.name.split("-")[0] for p in (tmp_path / "piecs_bayes" / "export").glob("*"))
    assert {"neg_hessians", "parts_walkers", "lockstep_advance"} <= set(kept), kept

    _new_process()
    TRACED.clear()
    again = _posterior()
    # read back, not traced again: neither the runner nor the log posterior
    assert TRACED["advance"] == 0 and TRACED["log_prob"] == 0, TRACED
    np.testing.assert_allclose(again.samples, first.samples, rtol=1e-12, atol=0.0)
    np.testing.assert_allclose(again.log_prob, first.log_prob, rtol=1e-12, atol=0.0)
    _new_process()  # later tests trace their own


def test_the_kept_hessian_is_the_hessian(tmp_path, monkeypatch):
    pytest.importorskip("flatbuffers")
    monkeypatch.delenv("PIECS_BAYES_NO_CACHE", raising=False)
    monkeypatch.setattr(_config, "_cache_dir", lambda: tmp_path / "piecs_bayes" / "jax")

    def log_prob(theta, args):
        points, scale = args
        return -jnp.sum(jnp.cos(theta[0] * points) ** 2 / scale) - theta[1] ** 4

    log_prob.trace_key = ("unit test", 1)
    x0 = np.array([[0.3, -0.2], [1.1, 0.5]])
    args = (np.array([[0.1, 0.2, 0.3], [0.4, 0.5, 0.6]]), np.array([2.0, 3.0]))
    # jitted: one program, not one per operation of the Hessian
    want = jax.jit(jax.vmap(jax.hessian(lambda t, a: -log_prob(t, a))))(x0, args)
    kept = _core.neg_hessians(log_prob)
    assert isinstance(kept, _config.KeptTrace)
    np.testing.assert_allclose(kept(x0, args), want, rtol=1e-13)
    assert len(list((tmp_path / "piecs_bayes" / "export").glob("neg_hessians-*.bin"))) == 1
    _core.neg_hessians.cache_clear()  # as a new process: read back
    np.testing.assert_allclose(_core.neg_hessians(log_prob)(x0, args), want, rtol=1e-13)
    # a Python number among the arguments (weakly typed): the function itself runs it
    one = _core._neg_hessian(log_prob)(x0[0], (args[0][0], 2.0))
    np.testing.assert_allclose(one, want[0], rtol=1e-13)


def test_a_log_posterior_without_a_key_is_traced_as_before():
    def log_prob(theta, args):
        return -0.5 * jnp.sum((theta - args) ** 2)

    fn = _core.neg_hessians(log_prob)
    assert not isinstance(fn, _config.KeptTrace)
    h = np.asarray(fn(np.zeros((3, 2)), np.ones((3, 2))))
    np.testing.assert_allclose(h, np.broadcast_to(np.eye(2), (3, 2, 2)))
    assert _core.kept_trace("x", log_prob, jax.jit(log_prob)) is None
