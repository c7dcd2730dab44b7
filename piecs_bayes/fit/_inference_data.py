r"""The ArviZ `InferenceData` of a Bayesian profile fit: what `posterior.nc` holds.

[`BayesProfileFit.to_arviz`][piecs_bayes.fit.BayesProfileFit.to_arviz] builds it from
the fit's draws and the data it was given ([`BayesData`][]): groups `posterior` (one
variable per deviation parameter over `line_feature` or `arc_feature`, one per source,
`frame_rotation` for the source `rotation`, `sigma`), `sample_stats` (`lp`),
`observed_data` and `log_likelihood` (`ball_centre`, per probe point, with its feature
and file line), `prior` (draws of the sources' priors). `chain` is one independent
ensemble and `draw` its walkers' thinned trajectories, so `az.rhat`, `az.ess` and
`az.summary` give the numbers the package reports. Every variable has a `units`
attribute; the run's and the priors' settings are in the attrs. The log likelihood is
float64 rounded to 24 significant bits (`LOG_LIKELIHOOD_BITS`, [`keep_bits`][]), so
the file compresses; [`write_netcdf`][] writes it.

The layout and why: docs/models/bayes_fit.md, "posterior.nc".
"""

from __future__ import annotations

import functools
import json
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .. import __version__
from ..geometry import machine_to_part
from .mcmc import import_arviz

#: Draws per source in the `prior` group (one chain).
PRIOR_DRAWS = 2000
#: Explicit mantissa bits kept of the stored log likelihood (float32's 23).
LOG_LIKELIHOOD_BITS = 23
#: Sources stored under another name (the lines' deviation has a `rotation` too).
_SOURCE_VARIABLE = {"rotation": "frame_rotation"}
_CHUNK = 8192  # draws per vmapped call of the pointwise log likelihood


@dataclass(frozen=True, eq=False)
class BayesData:
    """What a Bayesian profile fit was given, kept for its `InferenceData`.

    - `feature_ids`, `machine_points` (`(n, 2)`, machine frame, X as radius, mm),
      `approach` (`(n, 2)` or None), `lines` (file line of each point, or None):
      the triggers used, in the order handed to the fit.
    - `sources`: the prior specs `{source: spec}`; `ball_radius`, `transform`,
      `sigma` (mm; the known probe sigma unless `repeatability` is a source),
      `nu` (Student-t degrees of freedom), `file` (the study file, for messages).
    - `sampler`, `moves`: how the draws were made.
    - `radius`: the probe calibration's `RadiusComponents` (None without one).
    """

    feature_ids: np.ndarray
    machine_points: np.ndarray
    approach: np.ndarray | None
    lines: np.ndarray | None
    sources: dict
    ball_radius: float
    transform: object
    sigma: float
    nu: float
    file: str | None
    sampler: str
    moves: str
    radius: object = None


def parameter_locations(layout, units) -> list[tuple[str, str, str | None, str | None, int, str]]:
    """Where each parameter of a profile fit sits in its `InferenceData`:
    `(name, variable, dim, coordinate, column, unit)` per parameter, in the order
    of `layout.names` (column = its index there); `dim`/`coordinate` None for a
    scalar source."""
    out, dim_of = [], {}
    for f, sl in layout.features:
        dim = f"{f.kind}_feature"
        for j, p in enumerate(f.param_names):
            var = p if dim_of.setdefault(p, dim) == dim else f"{f.kind}_{p}"  # kinds sharing p
            col = sl.start + j
            out.append((f"{f.id}.{p}", var, dim, f.id, col, units[col]))
    for name, k in layout.nuisance:
        out.append((name, _SOURCE_VARIABLE.get(name, name), None, None, k, units[k]))
    if layout.sigma_index is not None:
        k = layout.sigma_index
        out.append(("sigma", "sigma", None, None, k, units[k]))
    return out


@functools.lru_cache(maxsize=32)
def _over_draws(pointwise):
    return jax.jit(jax.vmap(pointwise, in_axes=(0, None)))


def pointwise_over_draws(pointwise, draws: np.ndarray, args) -> np.ndarray:
    """`pointwise(theta, args) -> (n,)` for every row of `draws` `(m, d)`: one
    jitted `jax.vmap` over draws, in chunks of fixed size (one compilation)."""
    fn = _over_draws(pointwise)
    m = draws.shape[0]
    chunk = min(_CHUNK, m)
    pad = -m % chunk
    padded = np.concatenate([draws, np.repeat(draws[:1], pad, axis=0)]) if pad else draws
    out = [
        np.asarray(fn(jnp.asarray(padded[i : i + chunk]), args))
        for i in range(0, padded.shape[0], chunk)
    ]
    return np.concatenate(out)[:m]


def _posterior_group(az, posterior, locations, attrs):
    chains = posterior.arviz_chains  # (K, W*S, d)
    variables: dict[str, list] = {}
    for _, var, dim, coord, col, unit in locations:
        variables.setdefault(var, []).append((dim, coord, col, unit))
    data, dims, coords, var_attrs = {}, {}, {}, {}
    for var, entries in variables.items():
        dim = entries[0][0]
        cols = [c for _, _, c, _ in entries]
        if dim is None:
            data[var] = chains[:, :, cols[0]]
        else:
            data[var] = chains[:, :, cols]
            dims[var] = [dim]
            coords[dim] = [c for _, c, _, _ in entries]
        var_attrs[var] = {"units": entries[0][3], "long_name": _long_name(var, dim)}
    ds = az.dict_to_dataset(data, coords=coords, dims=dims, attrs=attrs)
    for var, a in var_attrs.items():
        ds[var].attrs.update(a)
    return ds


def _long_name(var: str, dim: str | None) -> str:
    if dim is not None:
        return f"deviation parameter {var} of each {dim.removesuffix('_feature')} feature"
    if var == "sigma":
        return "probe sigma (repeatability; the Student-t scale with that likelihood)"
    return f"error source {var}"


def _points_group(az, name, values, dims, coords, point_coords, units, long_name):
    """A group of one per-point variable; `dims` its own (sampled when `values`
    has the chain and draw axes in front)."""
    sampled = values.ndim == len(dims) + 2
    ds = az.dict_to_dataset(
        {name: values}, coords=coords, dims={name: dims}, default_dims=None if sampled else []
    )
    ds = ds.assign_coords({k: ("point", v) for k, v in point_coords.items()})
    ds[name].attrs.update({"units": units, "long_name": long_name})
    return ds


def inference_data(fit, data: BayesData, log_lik: np.ndarray, priors: dict):
    """The `InferenceData` of `fit` (a `BayesProfileFit`) given its `data`, the
    pointwise log likelihood `log_lik` `(chain, draw, n)` (NaN for points outside
    the measured features) and the sources' `priors` (see module doc)."""
    az = import_arviz()
    post = fit.posterior
    locations = parameter_locations(fit.layout, fit.units)
    attrs = _attrs(fit, data)
    used = ~np.all(np.isnan(log_lik), axis=(0, 1))
    n = int(used.sum())
    part_points = np.asarray(machine_to_part(jnp.asarray(data.machine_points), data.transform))
    point_coords = {"feature": np.asarray(data.feature_ids).astype(str)[used]}
    if data.lines is not None:
        point_coords["line"] = np.asarray(data.lines, dtype=np.int64)[used]
    coords = {"point": np.arange(n), "axis": ["x", "z"]}
    observed = _points_group(
        az, "ball_centre", part_points[used], ["point", "axis"], coords, point_coords, "mm",
        "probe-ball centre, part frame (the study's transform), X as radius",
    )  # fmt: skip
    loglik = _points_group(
        az, "ball_centre", keep_bits(log_lik[:, :, used], LOG_LIKELIHOOD_BITS), ["point"],
        {"point": coords["point"]}, point_coords, "1",
        f"log likelihood ({fit.likelihood}) of each point's residual (density per mm)",
    )  # fmt: skip
    stats = az.dict_to_dataset({"lp": post.arviz_log_prob})
    stats["lp"].attrs.update({"units": "1", "long_name": "log posterior (up to a constant)"})
    return az.InferenceData(
        attrs=attrs,
        posterior=_posterior_group(az, post, locations, attrs),
        sample_stats=stats,
        observed_data=observed,
        log_likelihood=loglik,
        prior=_prior_group(az, fit.layout, locations, priors),
    )


def keep_bits(x, bits: int) -> np.ndarray:
    """float64 `x` rounded to nearest with `bits` explicit mantissa bits (of 52): the
    same numbers to a relative $2^{-(\\mathrm{bits}+1)}$, and the cleared bits cost
    nothing once shuffled and compressed. inf and NaN stay what they are."""
    b = np.ascontiguousarray(x, dtype=np.float64).view(np.uint64)
    drop = 52 - int(bits)
    half, mask = np.uint64(1 << (drop - 1)), ~np.uint64((1 << drop) - 1)
    return ((b + half) & mask).view(np.float64)


def write_netcdf(idata, path) -> str:
    """`idata.to_netcdf(path)` (same groups, read by `arviz.from_netcdf`) with
    byte-shuffled zlib compression at level 1: random float draws compress about
    10 % better, and faster, than with zlib alone (ArviZ's default); level 4 would
    make the demo's file 1.3 % smaller in 30 % more time (0.95 s against 0.75 s)."""
    import xarray as xr

    path, mode = str(path), "w"
    if idata.attrs:
        xr.Dataset(attrs=idata.attrs).to_netcdf(path, mode=mode, engine="h5netcdf")
        mode = "a"
    for group in idata.groups():
        ds = idata[group]
        enc = {v: {"zlib": True, "shuffle": True, "complevel": 1} for v, x in ds.variables.items()
               if x.dtype.kind in "fiu"}  # fmt: skip
        ds.to_netcdf(path, mode=mode, group=group, engine="h5netcdf", encoding=enc)
        mode = "a"
    return path


def _prior_group(az, layout, locations, priors):
    rng = np.random.default_rng(0)
    src = {name: name for name, _ in layout.nuisance}
    if layout.sigma_index is not None:
        src["sigma"] = "repeatability"
    data, units = {}, {}
    for name, var, dim, _, _, unit in locations:
        if dim is None:
            data[var] = priors[src[name]].sample(rng, PRIOR_DRAWS)[None, :]
            units[var] = unit
    ds = az.dict_to_dataset(
        data, attrs={"deviation_prior": "flat (improper) on every feature deviation: not drawn"}
    )
    for var, unit in units.items():
        ds[var].attrs.update({"units": unit, "long_name": _long_name(var, None)})
    return ds


def _attrs(fit, data: BayesData) -> dict:
    post = fit.posterior
    attrs = post.run_attrs()
    attrs.update(
        {
            "piecs_bayes_version": __version__,
            "sampler": data.sampler,
            "moves": data.moves,
            "nwalkers": post.nwalkers,
            "part": fit.part or "",
            "likelihood": fit.likelihood,
            "ball_radius_mm": data.ball_radius,
            "declared_sigma_mm": data.sigma,
            "prior_sources": json.dumps(data.sources, sort_keys=True),
            "deviation_prior": "flat (improper) on every feature deviation",
        }
    )
    if fit.likelihood == "student_t":
        attrs["nu"] = data.nu
    return attrs
