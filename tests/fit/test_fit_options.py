"""The lathe fits' option objects (`fit._options`): each default is the one its entry
points had as keywords, each bad value is refused with the entry point's message."""

from __future__ import annotations

import inspect
import math

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.fit import (
    BAYES_SAMPLING,
    CALIBRATION_SAMPLING,
    CHUNK_PARTS,
    DECLARED_DOF,
    BatchOptions,
    BayesOptions,
    CalibrationOptions,
    FitOptions,
    RadiusComponents,
    fit_feature,
    fit_probe_calibration,
    fit_profile,
    fit_profile_bayes,
    fit_profile_joint,
    fit_profiles,
    fit_profiles_bayes,
)
from piecs_bayes.fit.mcmc import SamplerOptions
from piecs_bayes.geometry import MachineTransform
from piecs_bayes.simulate import demo_profile


def test_fit_options_defaults_are_the_keywords_they_replace():
    o = FitOptions()
    assert (o.method, o.loss, o.scale, o.sigma, o.declared) == ("lsq", "huber", None, None, None)
    assert o.declared_dof == DECLARED_DOF == 8.0
    assert o.fix == {} and o.min_points == {"line": 3, "arc": 4}
    # fit_profiles' default; fit_profile's was "lm" (its callers that relied on it say so)
    assert o.solver == "auto"
    assert (o.rtol, o.atol, o.max_steps) == (1e-10, 1e-12, 1000)
    assert o.solve_loss == "linear" and FitOptions(method="robust").solve_loss == "huber"
    assert o.reference_sigma == 1.0
    assert FitOptions(declared=0.002).reference_sigma == 0.002
    assert FitOptions(sigma=0.003, declared=0.002).reference_sigma == 0.003
    for fn in (fit_feature, fit_profile, fit_profiles, fit_profile_joint):
        assert inspect.signature(fn).parameters["options"].default == FitOptions()


def test_fit_options_normalise_fix_and_min_points():
    o = FitOptions(fix=["dia_24.offset", "fillet.radius", "fillet.center_x"], min_points={"arc": 5})
    assert o.fix == {"dia_24": ("offset",), "fillet": ("radius", "center_x")}
    assert FitOptions(fix={"dia_24": ["offset"]}).fix == {"dia_24": ("offset",)}
    assert o.min_points == {"line": 3, "arc": 5}


def test_fit_options_refuse_what_the_entry_points_refused():
    with pytest.raises(ValueError, match=r"^unknown method 'bayes'; expected 'lsq' or 'robust'$"):
        FitOptions(method="bayes")
    msg = r"unknown solver 'newton'; expected 'auto', 'fast', 'lm', 'gauss_newton' or 'dogleg'"
    with pytest.raises(InputError, match=msg):
        FitOptions(solver="newton")
    # the one-part fit takes two of them, with its own message
    pts, ids = np.zeros((3, 2)), ["dia_24"] * 3
    with pytest.raises(InputError, match=r"unknown solver 'fast'; expected 'lm' or 'auto'"):
        fit_profile(demo_profile(), ids, pts, ball_radius=1.0, options=FitOptions(solver="fast"))


def test_batch_options():
    b = BatchOptions()
    assert (b.chunk_size, b.batch_size, b.progress) == (CHUNK_PARTS, 256, False)
    assert CHUNK_PARTS == 1024
    assert inspect.signature(fit_profiles).parameters["batch"].default == b
    with pytest.raises(InputError, match=r"chunk_size and batch_size must be >= 1, got 0, 256"):
        BatchOptions(chunk_size=0)
    with pytest.raises(InputError, match=r"chunk_size and batch_size must be >= 1, got 1024, 0"):
        BatchOptions(batch_size=0)


def test_bayes_sampling_is_the_profile_fits_defaults():
    """The Bayesian fits kept their keywords' defaults: 3,000 steps, the DE mixture, the
    lockstep sampler; the rest the engine's. The calibration: the same, no bar."""
    engine = SamplerOptions()
    want = {"nsteps": 3000, "moves": "de", "sampler": "lockstep"}
    for name, value in vars(BAYES_SAMPLING).items():
        assert value == want.get(name, getattr(engine, name)), name
    assert (BAYES_SAMPLING.nwalkers, BAYES_SAMPLING.n_ensembles, BAYES_SAMPLING.seed) == (
        None,
        4,
        0,
    )
    assert BAYES_SAMPLING.progress is True and BAYES_SAMPLING.on_fail == "warn"
    for fn in (fit_profile_bayes, fit_profiles_bayes):
        assert inspect.signature(fn).parameters["sampling"].default is BAYES_SAMPLING
    assert CALIBRATION_SAMPLING.progress is False
    assert vars(CALIBRATION_SAMPLING) == {**vars(BAYES_SAMPLING), "progress": False}
    assert inspect.signature(fit_probe_calibration).parameters["sampling"].default is (
        CALIBRATION_SAMPLING
    )


def test_bayes_options():
    o = BayesOptions(sources={}, ball_radius=1.0, sigma=0.0015)
    assert o.transform == MachineTransform() and o.likelihood == "gaussian" and o.nu == 4.0
    assert o.radius is None and o.file is None
    # fit_profiles_bayes took transform=None for the identity
    assert BayesOptions(sources={}, ball_radius=1.0, sigma=0.0015, transform=None).transform == (
        MachineTransform()
    )
    with pytest.raises(InputError, match=r"unknown likelihood 'cauchy'; expected 'gaussian' or"):
        BayesOptions(sources={}, ball_radius=1.0, sigma=0.0015, likelihood="cauchy")
    cal = {"probe_cal_1": {"dist": "normal", "mean": 0.0, "sd": 1e-4}}
    with pytest.raises(InputError, match=r"study.toml: source 'probe_cal_1' needs the probe cal"):
        BayesOptions(sources=cal, ball_radius=1.0, sigma=0.0015, file="study.toml")
    radius = RadiusComponents(orders=(2,), vectors=((1.0,), (0.0,), (0.0,)), sds=(1e-4,))
    ok = BayesOptions(sources=cal, ball_radius=1.0, sigma=0.0015, radius=radius)
    assert ok.radius is radius


def test_calibration_options():
    o = CalibrationOptions()
    assert (o.orders, o.sigma_dof, o.sigma_known, o.method, o.loss) == (
        "auto",
        DECLARED_DOF,
        False,
        "lsq",
        "huber",
    )
    assert inspect.signature(fit_probe_calibration).parameters["options"].default == o
    with pytest.raises(InputError, match=r"^method 'robust'; expected 'lsq' or 'bayes'$"):
        CalibrationOptions(method="robust")
    assert math.isfinite(o.sigma_dof)
