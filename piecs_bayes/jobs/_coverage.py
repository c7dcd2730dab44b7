r"""Calibration of the stated uncertainty: do 95 % intervals cover the truth 95 % of the time?

[`coverage_check`][] simulates `n_parts` probed parts of one profile with known true
deviations (each part with its own probe noise and its own draw of the machine error
sources), fits them all in one batch (`fit_profiles`, the settings a study would use),
propagates each part to the adjusted tool path (linearised, GUM; with `bayes=True` also
Monte Carlo from the posterior, all parts sampled in lockstep), and counts how often the
`p` intervals hold the truth: every feature parameter's
(`ToolpathUncertainty.deviation_interval`), every vertex coordinate's
(`vertex_interval`) and the whole path inside the simultaneous band (one event per
part). It returns a [`CoverageResult`][]. A rate has a binomial standard deviation of
$\sqrt{p(1-p)/n}$ (0.7 % at n = 1,000, p = 0.95); hits within one part are correlated.

The rates measured: docs/uncertainty.md, section 4.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from numbers import Integral, Real

import numpy as np

from ..errors import InputError
from ..geometry import MachineTransform, Profile
from ..uncertainty import (
    LinearisedOptions,
    linearised_toolpath,
    monte_carlo_toolpath,
    path_function,
    path_grid,
)
from ._probe_radius import calibrated_points, radius_components


@dataclass(frozen=True)
class CoverageResult:
    """Coverage rates per route (``"linearised"``, ``"monte_carlo"``) and kind
    (``"parameters"``, ``"vertices"``, ``"band"``), the per-feature parameter rates,
    the number of parts and the settings."""

    rates: dict
    per_feature: dict
    n_parts: int
    p: float
    settings: dict = field(default_factory=dict)
    sigma_dof: tuple[float, float] = (math.nan, math.nan)

    def table(self) -> str:
        """A text table of the rates (percent) with the binomial sd of one rate."""
        sd = 100.0 * math.sqrt(self.p * (1.0 - self.p) / self.n_parts)
        lines = [
            f"coverage of {100 * self.p:g} % intervals over {self.n_parts} parts "
            f"(binomial sd {sd:.2f} %); {self.settings}",
            f"{'route':<12} {'parameters':>10} {'vertices':>9} {'band':>7}",
        ]
        for route, r in self.rates.items():
            lines.append(
                f"{route:<12} {100 * r['parameters']:9.2f}% {100 * r['vertices']:8.2f}% "
                f"{100 * r['band']:6.2f}%"
            )
        for route, feats in self.per_feature.items():
            lines.append(
                f"  {route}: " + ", ".join(f"{fid} {100 * v:.1f}%" for fid, v in feats.items())
            )
        return "\n".join(lines)


def _hits(u, truth_dev, true_v, true_o, fixed):
    """Per-parameter hits by feature, vertex hits, whole-band hit of one part."""
    dev_hits = {}
    for fid, (lo, hi) in u.deviation_interval.items():
        free = ~fixed[fid]
        t = truth_dev[fid]
        dev_hits[fid] = ((lo <= t) & (t <= hi))[free]
    lo, hi = u.vertex_interval
    vsd = u.vertex_sd
    ok = vsd > 1e-7  # a coordinate the data cannot move (e.g. on the axis) has no interval
    vert = ((lo <= true_v) & (true_v <= hi))[ok]
    b = u.bands
    band = bool(np.all((true_o >= b.simultaneous_lower) & (true_o <= b.simultaneous_upper)))
    return dev_hits, vert, band


@dataclass(frozen=True)
class CoverageOptions:
    """The settings of a [`coverage_check`][]: how the parts are probed, fitted,
    propagated and counted.

    - `n_parts`: simulated parts; `seed`: their noise, machine errors and chains.
    - `points`, `noise_sd`, `ball_radius`, `transform`, `margin`: the probing
      (`simulate_parts`); the declared repeatability is `noise_sd`.
    - `source_sd`: per-part machine errors actually drawn (normal) and declared to
      the propagation with the same sds (`SIMULATED_SOURCES`).
    - `known_sigma`, `declared_dof`, `method`, `loss`: the fit settings (a study's
      `[fit] known_sigma`, `[probe] repeatability_dof`, `[fit] method`, `loss`).
    - `p`: the level of the intervals and bands counted.
    - `bayes`: also sample every part's posterior (lockstep ensembles, one ensemble
      per part; the probe sigma estimated with the declared prior unless known) and
      count the Monte Carlo intervals and bands: `bayes_steps` steps of
      `bayes_walkers` walkers (default: the sampler's).
    - `bayes_chunk`: parts sampled together (memory: the lockstep sampler holds their
      whole chains, parts x walkers x steps x parameters x 8 bytes, until it thins).
    - `band_sims`: quasi-random draws for each linearised band's critical value
      (2^15 scrambled Sobol points: its standard error ~0.005, ~0.1 % of coverage).
    - `probe`: a lobing probe (`io.ProbeCalibration`, its r(theta) the truth) that
      records every part. With `calibrated`, the parts are fitted with `probe` as
      their calibration (points corrected to r0, its covariance a source) and each
      part's real probe differs from it by a draw of that covariance (so that the
      count includes the calibration's own error); without, they are fitted with
      one radius, `ball_radius`, as if nobody had calibrated.
    """

    n_parts: int = 1000
    points: int | Mapping = 8
    noise_sd: float = 0.0015
    ball_radius: float = 1.0
    transform: MachineTransform = MachineTransform()
    margin: float = 0.1
    source_sd: Mapping[str, float] | None = None
    known_sigma: bool = False
    declared_dof: float = 8.0
    method: str = "robust"
    loss: str = "huber"
    p: float = 0.95
    bayes: bool = False
    bayes_steps: int = 1500
    bayes_walkers: int | None = None
    bayes_chunk: int = 100
    band_sims: int = 2**15
    seed: int = 0
    probe: object = None
    calibrated: bool = False

    def __post_init__(self):
        for name, least in (("n_parts", 1), ("bayes_steps", 1), ("bayes_chunk", 1),
                            ("band_sims", 1), ("seed", 0)):  # fmt: skip
            _integer(name, getattr(self, name), least)
        if self.bayes_walkers is not None:
            _integer("bayes_walkers", self.bayes_walkers, 2)
        if not isinstance(self.points, Mapping):
            _integer("points", self.points, 1)
        for name, ok, expected in (
            ("noise_sd", lambda v: v > 0.0, "a finite number > 0"),
            ("ball_radius", lambda v: v > 0.0, "a finite number > 0"),
            ("margin", lambda v: 0.0 <= v < 0.5, "a number in [0, 0.5)"),
            ("declared_dof", lambda v: v > 0.0, "a finite number > 0"),
            ("p", lambda v: 0.0 < v < 1.0, "a number in (0, 1)"),
        ):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, Real) or not math.isfinite(v) or not ok(v):
                _refuse(name, expected, v)
        for name in ("known_sigma", "bayes", "calibrated"):
            if not isinstance(getattr(self, name), bool):
                _refuse(name, "true or false", getattr(self, name))
        if self.method not in ("lsq", "robust"):
            _refuse("method", "'lsq' or 'robust'", self.method)


def _refuse(name: str, expected: str, value) -> None:
    raise InputError(f"coverage option {name!r}: expected {expected}, got {value!r}", value=value)


def _integer(name: str, value, least: int) -> None:
    if isinstance(value, bool) or not isinstance(value, Integral) or value < least:
        _refuse(name, f"an integer >= {least}", value)


def coverage_check(
    profile: Profile, truth: dict, options: CoverageOptions = CoverageOptions()
) -> CoverageResult:
    """Simulate `options.n_parts` parts, fit and propagate them at the given settings,
    count coverage.

    **Arguments:**

    - `profile`: the nominal profile of every part.
    - `truth`: the true deviation per feature id (every part).
    - `options`: a [`CoverageOptions`][]: the probing, the fit, the routes and the count.

    **Returns:** a [`CoverageResult`][].
    """
    from ..fit import FitOptions, fit_profiles, to_part_frame
    from ..fit.lsq import TUNING
    from ..simulate import SimulatedProbing, simulate_parts

    o = options
    n_parts, points, noise_sd, ball_radius, transform = (
        o.n_parts, o.points, o.noise_sd, o.ball_radius, o.transform
    )  # fmt: skip
    known_sigma, declared_dof, method, loss, margin, p = (
        o.known_sigma, o.declared_dof, o.method, o.loss, o.margin, o.p
    )  # fmt: skip
    band_sims, seed, probe, calibrated = o.band_sims, o.seed, o.probe, o.calibrated
    source_sd = dict(o.source_sd or {})
    probing = SimulatedProbing(
        ball_radius=ball_radius, transform=transform, points=points, noise_sd=noise_sd,
        margin=margin,
    )  # fmt: skip
    sim = simulate_parts(
        profile, truth, n_parts, probing=probing, source_sd=source_sd, rng=seed, probe=probe,
        probe_error=calibrated,
    )  # fmt: skip
    radius = None
    if probe is not None and calibrated:
        radius = radius_components(probe)
        sim = {**sim, "points": calibrated_points(
            profile, sim["feature"], sim["points"], transform, probe, parts=sim["part"]
        )}  # fmt: skip
        ball_radius = probe.r0
    prop_sd = {**source_sd, **(radius.source_sd if radius else {})}
    bf = fit_profiles(
        profile, sim["part"], sim["feature"], to_part_frame(transform, sim["points"]),
        ball_radius=ball_radius, options=FitOptions(
            method=method, loss=loss, scale=TUNING.get(loss, 1.0) * noise_sd,
            sigma=noise_sd if known_sigma else None, declared=noise_sd, declared_dof=declared_dof,
        ),
    )  # fmt: skip
    grid = path_grid(profile)
    feats = profile.features
    truth_dev = {f.id: np.asarray(truth.get(f.id, np.zeros(f.nparams)), float) for f in feats}
    true_v, true_o = map(np.asarray, path_function(profile, grid)(tuple(truth_dev.values())))
    fixed = {f.id: np.zeros(f.nparams, dtype=bool) for f in feats}
    keep = ~bf.outlier_mask
    values = {f.id: bf.values(f.id) for f in feats}
    n_pts = len(sim["part"]) // n_parts
    routes = {"linearised": []}
    options = LinearisedOptions(
        ball_radius=ball_radius, transform=transform, source_sd=prop_sd, grid=grid, p=p,
        band_sims=band_sims, loss=loss if method == "robust" else "linear", radius=radius,
    )  # fmt: skip
    for i in range(n_parts):
        rows = slice(i * n_pts, (i + 1) * n_pts)
        k = keep[rows]
        u = linearised_toolpath(
            profile, sim["feature"][rows], sim["points"][rows],
            {fid: v[i] for fid, v in values.items()}, options=options, inlier=k,
            sigma=float(bf.sigma[i]), dof=float(bf.sigma_dof[i]),
        )  # fmt: skip
        routes["linearised"].append(_hits(u, truth_dev, true_v, true_o, fixed))
    if o.bayes:
        routes["monte_carlo"] = _monte_carlo_hits(
            profile, sim, bf, (truth_dev, true_v, true_o, fixed), grid, o,
            source_sd=prop_sd, ball_radius=ball_radius, radius=radius,
        )  # fmt: skip
    rates, per_feature = _rates(routes, feats)
    settings = {
        "known_sigma": known_sigma, "repeatability_dof": declared_dof, "method": method,
        "loss": loss, "points": points, "noise_sd": noise_sd, "sources": source_sd,
        "probe": None if probe is None else ("calibrated" if calibrated else "uncalibrated"),
    }  # fmt: skip
    dofs = np.asarray(bf.sigma_dof)
    return CoverageResult(
        rates, per_feature, n_parts, p, settings, (float(dofs.min()), float(dofs.max()))
    )


def _rates(routes: dict, feats) -> tuple[dict, dict]:
    """Coverage rates per route and kind, and per feature, from the hits of each part."""
    rates, per_feature = {}, {}
    for route, hits in routes.items():
        dev = np.concatenate([np.concatenate(list(h[0].values())) for h in hits])
        rates[route] = {
            "parameters": float(np.mean(dev)),
            "vertices": float(np.mean(np.concatenate([h[1] for h in hits]))),
            "band": float(np.mean([h[2] for h in hits])),
        }
        per_feature[route] = {
            f.id: float(np.mean(np.concatenate([h[0][f.id] for h in hits]))) for f in feats
        }
    return rates, per_feature


def _monte_carlo_hits(
    profile, sim, bf, target, grid, options: CoverageOptions, *, source_sd, ball_radius, radius
) -> list:
    """Every part's posterior (lockstep ensembles, one per part; the probe sigma
    estimated with the declared prior unless known) and the hits of its Monte Carlo
    intervals and bands (`target`: the truth as `_hits` takes it), sampled in chunks
    of `options.bayes_chunk` parts; `source_sd`, `ball_radius`, `radius`: those the
    parts were fitted with."""
    from ..fit import BAYES_SAMPLING, BayesOptions, fit_profiles_bayes

    o = options
    noise_sd, transform, seed, bayes_chunk = o.noise_sd, o.transform, o.seed, o.bayes_chunk
    bayes_steps, bayes_walkers = o.bayes_steps, o.bayes_walkers
    known_sigma, declared_dof = o.known_sigma, o.declared_dof
    keep = ~bf.outlier_mask
    values = {f.id: bf.values(f.id) for f in profile.features}
    sources = {n: {"dist": "normal", "mean": 0.0, "sd": sd} for n, sd in source_sd.items()}
    if not known_sigma:
        sources["repeatability"] = {
            "dist": "scaled_inv_chi2", "nu": max(declared_dof, 1e-3), "scale": noise_sd,
        }  # fmt: skip
    model = BayesOptions(sources=sources, ball_radius=ball_radius, sigma=noise_sd,
                         transform=transform, radius=radius)  # fmt: skip
    n_parts = len(bf.parts)
    starts = {bf.parts[i]: {fid: v[i] for fid, v in values.items()} for i in range(n_parts)}
    hits = []
    # chunks of parts: the lockstep sampler keeps every part's whole chain
    # (parts x walkers x steps x parameters) until it thins
    for lo in range(0, n_parts, bayes_chunk):
        sel = np.isin(sim["part"], bf.parts[lo : lo + bayes_chunk])
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # short chains on purpose: coverage is the check
            posts = fit_profiles_bayes(
                profile, sim["part"][sel], sim["feature"][sel], sim["points"][sel],
                starts=starts, options=model, sampling=replace(
                    BAYES_SAMPLING, nsteps=bayes_steps, n_ensembles=1, nwalkers=bayes_walkers,
                    progress=False, on_fail="ignore", seed=seed + 1 + lo,
                ), inlier=keep[sel],
            )  # fmt: skip
        for post in posts.values():
            u = monte_carlo_toolpath(profile, post.deviation_samples, grid=grid, p=o.p)
            hits.append(_hits(u, *target))
    return hits
