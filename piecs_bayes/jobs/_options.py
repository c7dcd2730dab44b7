"""One translation of a study into the settings of the numerical layers.

Every job (one part, a batch of parts, a capability study on Dask, the main job)
takes its fit, sampler, decision and offset settings from here, so a study means
the same thing wherever it is used.
"""

from __future__ import annotations

from dataclasses import replace
from typing import TYPE_CHECKING

from ..errors import InputError
from ..fit import BAYES_SAMPLING, CALIBRATION_SOURCE, BayesOptions, FitOptions
from ..fit.lsq import TUNING
from ..fit.mcmc import SamplerOptions, prior_from_spec
from ..io import Study, parse_fix
from ._probe_radius import radius_components

if TYPE_CHECKING:  # imported where read: `fit` needs neither (22 ms of its start)
    from ..compensate import OffsetSettings
    from ..decide import DecisionSettings


def robust_scale(study: Study) -> float:
    """Loss scale of robust fits: the study's ``fit.scale`` (a standard deviation,
    mm), else the probe's known repeatability, times the loss's tuning constant.

    A MAD from the handful of points on one feature can collapse towards zero
    and flag good points (seen on a 7-point fillet: 0.15 um against 1.5 um of
    noise), so the known repeatability is the better robust scale.
    """
    sd = study.fit.scale if study.fit.scale is not None else study.probe.repeatability
    return TUNING.get(study.fit.loss, 1.0) * sd


def fit_options(study: Study, method: str) -> FitOptions:
    """The [`FitOptions`][piecs_bayes.fit.FitOptions] of `fit.fit_profile` /
    `fit.fit_profiles` for ``method`` (``"lsq"`` or ``"robust"``): the loss and its
    scale, the probe sigma rule (known, or declared with its weight), fixed
    parameters, minimum points (the ball radius is the study's `probe.ball_radius`)."""
    return FitOptions(
        method=method,
        loss=study.fit.loss,
        scale=robust_scale(study),
        sigma=study.probe.repeatability if study.fit.known_sigma else None,
        declared=study.probe.repeatability,
        declared_dof=study.probe.repeatability_dof,
        fix=parse_fix(study.fit.fix),
        min_points={"line": study.fit.min_points_line, "arc": study.fit.min_points_arc},
    )


def bayes_sources(study: Study) -> dict:
    """The study's uncertainty sources as the Bayesian fit takes them.

    Unless the study declares the probe sigma known (``known_sigma = true``) or gives
    ``repeatability`` its own prior under ``[uncertainty]``, the sigma is a parameter
    with the declared repeatability as a scaled-inverse-chi-square prior worth
    ``[probe] repeatability_dof`` degrees of freedom (the same rule as the
    least-squares fits, docs/uncertainty.md); a weight of 0 is nearly Jeffreys' 1/sigma.
    """
    sources = {k: dict(v) for k, v in study.sources.items()}
    if not study.fit.known_sigma and "repeatability" not in sources:
        sources["repeatability"] = {
            "dist": "scaled_inv_chi2",
            "nu": max(float(study.probe.repeatability_dof), 1e-3),
            "scale": float(study.probe.repeatability),
        }
    if study.fit.known_sigma:
        sources.pop("repeatability", None)
    for name, sd in calibration_sds(study).items():
        sources[name] = {"dist": "normal", "mean": 0.0, "sd": sd}
    return sources


def calibration_sds(study: Study) -> dict[str, float]:
    """The probe calibration's independent components and their standard deviations
    (``probe_cal_<j>``: `fit.RadiusComponents`); empty without a calibration."""
    radius = radius_components(study.probe.calibration)
    return {} if radius is None else radius.source_sd


def bayes_options(study: Study) -> BayesOptions:
    """The [`BayesOptions`][piecs_bayes.fit.BayesOptions] of `fit.fit_profile_bayes` /
    `fit.fit_profiles_bayes`: the study's sources (`bayes_sources`), its probe
    calibration, ball radius, transform and repeatability, and its likelihood."""
    return BayesOptions(
        sources=bayes_sources(study),
        radius=radius_components(study.probe.calibration),
        ball_radius=study.probe.ball_radius,
        transform=study.transform,
        sigma=study.probe.repeatability,
        likelihood=study.fit.likelihood,
        nu=study.fit.nu,
        file=str(study.path),
    )


def sampler_options(
    study: Study,
    *,
    nsteps=None,
    n_ensembles=None,
    seed=0,
    progress=True,
    on_fail="warn",
    sampler="lockstep",
) -> SamplerOptions:
    """The [`SamplerOptions`][piecs_bayes.fit.SamplerOptions] of the Bayesian fit
    (`fit.BAYES_SAMPLING`) with the study's steps, walkers and ensembles and the
    caller's overrides."""
    return replace(
        BAYES_SAMPLING,
        nsteps=nsteps or study.fit.bayes_steps,
        nwalkers=study.fit.bayes_walkers,
        n_ensembles=n_ensembles or study.fit.bayes_ensembles,
        seed=seed,
        progress=progress,
        on_fail=on_fail,
        sampler=sampler,
    )


def source_sds(study: Study) -> dict:
    """Standard deviations of the study's systematic sources (mm or 1 or rad), as
    `uncertainty.u_systematic` takes them; a probe calibration as its
    `fit.RadiusComponents` under ``"probe calibration"``."""
    out = {}
    for name, spec in study.sources.items():
        if name in ("repeatability", "thermal"):
            continue
        out[name] = float(prior_from_spec(name, dict(spec), file=str(study.path)).sd)
    if "ball_radius" not in out and study.probe.ball_radius_u > 0:
        out["ball_radius"] = float(study.probe.ball_radius_u)
    radius = radius_components(study.probe.calibration)
    if radius is not None:
        out[CALIBRATION_SOURCE] = radius
    return out


def decision_settings(study: Study) -> DecisionSettings:
    """[`DecisionSettings`][piecs_bayes.compensate.DecisionSettings] from the study's
    `[decision]` table; `max_correction` defaults to `compensation.max_correction`."""
    from ..decide import settings_from_spec

    spec = {k: v for k, v in study.decision.items() if k not in ("characteristic", "run_index")}
    spec.setdefault("max_correction", study.compensation.max_correction)
    return settings_from_spec(spec, file=str(study.path))


def offset_settings(study: Study) -> OffsetSettings:
    """[`OffsetSettings`][piecs_bayes.compensate.OffsetSettings] from `[offsets]`."""
    from ..compensate import OffsetSettings

    keys = ("null_band", "feedback_gain", "upper_limit", "k_significance", "decimals")
    spec = {k: study.offsets[k] for k in keys if k in study.offsets}
    try:
        return OffsetSettings(**spec)
    except InputError as e:
        raise InputError(f"offsets: {e.reason}", file=str(study.path), value=e.value) from None
