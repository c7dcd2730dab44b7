"""Calibration of the stated uncertainty: do 95 % intervals cover the truth 95 % of the time?

`coverage_check` simulates many probed parts of one profile with known true
deviations (each part with its own probe noise and its own draw of the machine
error sources), fits them all in one batch (`fit_profiles`, the settings a study
would use), propagates each part to the adjusted tool path (linearised, GUM;
and, with `bayes=True`, Monte Carlo from the posterior, all parts sampled in
lockstep), and counts how often the intervals hold the truth:

- every feature parameter's `p` interval (`ToolpathUncertainty.deviation_interval`);
- every vertex coordinate's `p` interval (`vertex_interval`);
- the whole path inside the simultaneous band (one event per part).

With `n` parts a rate has a binomial standard deviation of
$\\sqrt{p(1-p)/n}$ (0.7 % at n = 1,000 and p = 0.95); per-parameter and
per-vertex hits of one part are correlated, so their pooled rate scatters more
than the count suggests.
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

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


def coverage_check(
    profile: Profile,
    truth: dict,
    *,
    n_parts: int = 1000,
    points: int | dict = 8,
    noise_sd: float = 0.0015,
    ball_radius: float = 1.0,
    transform: MachineTransform = MachineTransform(),
    source_sd: dict | None = None,
    known_sigma: bool = False,
    declared_dof: float = 8.0,
    method: str = "robust",
    loss: str = "huber",
    margin: float = 0.1,
    p: float = 0.95,
    bayes: bool = False,
    bayes_steps: int = 1500,
    bayes_walkers: int | None = None,
    band_sims: int = 2**15,
    bayes_chunk: int = 100,
    seed: int = 0,
    probe=None,
    calibrated: bool = False,
) -> CoverageResult:
    """Simulate `n_parts`, fit and propagate them at the given settings, count coverage.

    **Arguments:**

    - `truth`: the true deviation per feature id (every part).
    - `points`, `noise_sd`, `ball_radius`, `transform`, `margin`: the probing
      (`simulate_parts`); the declared repeatability is `noise_sd`.
    - `source_sd`: per-part machine errors actually drawn (normal) and declared to
      the propagation with the same sds (`SIMULATED_SOURCES`).
    - `known_sigma`, `declared_dof`, `method`, `loss`: the fit settings (a study's
      `[fit] known_sigma`, `[probe] repeatability_dof`, `[fit] method`, `loss`).
    - `bayes`: also sample every part's posterior (lockstep ensembles, one ensemble
      per part; the probe sigma estimated with the declared prior unless known) and
      count the Monte Carlo intervals and bands.
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

    **Returns:** a [`CoverageResult`][].
    """
    from ..fit import TUNING, fit_profiles, to_part_frame
    from ..simulate import SimulatedProbing, simulate_parts

    source_sd = dict(source_sd or {})
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
            profile, sim["feature"], sim["points"], transform, probe
        )}  # fmt: skip
        ball_radius = probe.r0
    prop_sd = {**source_sd, **(radius.source_sd if radius else {})}
    bf = fit_profiles(
        profile, sim["part"], sim["feature"], to_part_frame(transform, sim["points"]),
        ball_radius=ball_radius, method=method, loss=loss,
        scale=TUNING.get(loss, 1.0) * noise_sd, sigma=noise_sd if known_sigma else None,
        declared=noise_sd, declared_dof=declared_dof,
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
    if bayes:
        routes["monte_carlo"] = _monte_carlo_hits(
            profile, sim, bf, keep, values, truth_dev, true_v, true_o, fixed, grid,
            source_sd=prop_sd, known_sigma=known_sigma, declared_dof=declared_dof,
            noise_sd=noise_sd, ball_radius=ball_radius, transform=transform, p=p,
            bayes_steps=bayes_steps, bayes_walkers=bayes_walkers, bayes_chunk=bayes_chunk,
            seed=seed, radius=radius,
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
    profile, sim, bf, keep, values, truth_dev, true_v, true_o, fixed, grid, *, source_sd,
    known_sigma, declared_dof, noise_sd, ball_radius, transform, p, bayes_steps, bayes_walkers,
    bayes_chunk, seed, radius=None,
) -> list:  # fmt: skip
    """Every part's posterior (lockstep ensembles, one per part; the probe sigma
    estimated with the declared prior unless known) and the hits of its Monte Carlo
    intervals and bands, sampled in chunks of `bayes_chunk` parts."""
    from ..fit import fit_profiles_bayes

    sources = {n: {"dist": "normal", "mean": 0.0, "sd": sd} for n, sd in source_sd.items()}
    if not known_sigma:
        sources["repeatability"] = {
            "dist": "scaled_inv_chi2", "nu": max(declared_dof, 1e-3), "scale": noise_sd,
        }  # fmt: skip
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
                starts=starts, sources=sources, ball_radius=ball_radius,
                transform=transform, sigma=noise_sd, nsteps=bayes_steps, n_ensembles=1,
                nwalkers=bayes_walkers, progress=False, on_fail="ignore", seed=seed + 1 + lo,
                radius=radius, inlier=keep[sel],
            )  # fmt: skip
        for post in posts.values():
            u = monte_carlo_toolpath(profile, post.deviation_samples, grid=grid, p=p)
            hits.append(_hits(u, truth_dev, true_v, true_o, fixed))
    return hits
