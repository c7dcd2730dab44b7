"""Uncertainty of the adjusted tool path, two ways that agree where linearisation holds.

- **Linearised (GUM, JCGM 100)**: the whole chain *probe points and error
  sources -> feature fits -> mirrored deviations -> adjusted vertices and path*
  is one JAX function; its Jacobian (through the fits by the implicit function
  theorem) times the input covariance gives every output's covariance, and the
  split of the input covariance by source gives the uncertainty budget.
- **Monte Carlo (JCGM 101)**: posterior draws of the deviations (Bayesian fit,
  nuisance parameters included) pushed through the same path function.

The path is described by its vertices and by its **normal offset** from the
nominal contour at grid points along every feature (positive outward): the
bands are pointwise and simultaneous bands of that offset.
"""

from __future__ import annotations

import functools
import hashlib
import math
from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from .. import _config
from ..compensate import adjusted_geometry
from ..errors import InputError
from ..fit import (
    CALIBRATION_SOURCE,
    SOURCE_EFFECTS,
    coverage_factor,
    effective_dof,
    is_calibration_source,
    probe_residuals,
)
from ..fit.lsq import normal_variance_factor
from ..geometry import Line, MachineTransform, Profile
from ..io import rows_to_dataframe
from . import _toolpath_rows
from ._bands import Bands, bands_from_samples, bands_linear
from ._propagate import uncertainty_budget

LINEARISED_SOURCES = SOURCE_EFFECTS


@dataclass(frozen=True, eq=False)
class PathGrid:
    """Grid points along the nominal contour: feature index, fraction, point, outward normal."""

    feature: np.ndarray
    t: np.ndarray
    points: np.ndarray
    normals: np.ndarray

    def __len__(self) -> int:
        return len(self.t)


@functools.lru_cache(maxsize=32)
def path_grid(profile: Profile, per_feature: int = 21) -> PathGrid:
    """``per_feature`` points on every feature (ends included)."""
    fi, ts, pts, nrm = [], [], [], []
    for i, f in enumerate(profile.features):
        t = np.linspace(0.0, 1.0, per_feature)
        p, n = f.drawn_at(t)  # in NumPy: no eager JAX programs compiled per shape
        fi.append(np.full(per_feature, i))
        ts.append(t)
        pts.append(p)
        nrm.append(n)
    return PathGrid(np.concatenate(fi), np.concatenate(ts), np.vstack(pts), np.vstack(nrm))


def path_function(profile: Profile, grid: PathGrid, gain=1.0):
    """``f(devs) -> (vertices (n+1, 2), offsets (m,))`` for deviations ``devs`` (a
    tuple, one vector per feature, profile order): the adjusted path's vertices
    and its normal offset from nominal at the grid points."""
    gains = [gain.get(f.id, 1.0) if isinstance(gain, dict) else gain for f in profile.features]
    feats = profile.features
    idx = [np.flatnonzero(grid.feature == i) for i in range(len(feats))]

    def f(devs):
        dev_c = tuple(-g * jnp.asarray(d) for g, d in zip(gains, devs, strict=True))
        verts, centres, radii = adjusted_geometry(profile, dev_c)
        offs = []
        for i, feat in enumerate(feats):
            g = jnp.asarray(grid.points[idx[i]])
            if isinstance(feat, Line):
                d = feat.signed_distance(g, dev_c[i])
            else:
                v = g - centres[i]
                d = feat.sense * (jnp.sqrt(jnp.sum(v * v, axis=-1)) - radii[i])
            offs.append(-d)
        return verts, jnp.concatenate(offs)

    return f


@dataclass(frozen=True, eq=False)
class ToolpathUncertainty:
    """Uncertainty of the adjusted tool path.

    ``vertex_cov`` ``(n+1, 2, 2)`` per vertex (x, z); ``offset``/``offset_sd``
    the normal offset of the adjusted path from nominal and its standard
    uncertainty at the grid points; ``bands`` pointwise and simultaneous 95 %
    bands of the offset; ``budget`` (linearised only) the variance contributed
    by each source to each vertex coordinate (``vertex_budget`` ``{source: (n+1, 2)}``)
    and to each grid offset (``offset_budget``); ``deviation_cov`` per feature.

    ``dof``: degrees of freedom of the probe sigma (linearised; ``inf`` when it is
    known). Each quantity's effective dof is Welch-Satterthwaite's from its
    repeatability share (``deviation_dof``, ``vertex_dof``, ``offset_dof``), and
    its `p` interval is $y \\pm t_p(\\nu_\\mathrm{eff})\\,u$ (``deviation_interval``,
    ``vertex_interval``). The Monte Carlo route's intervals are the draws'
    equal-tailed quantiles (JCGM 101), sigma's uncertainty integrated out.
    """

    method: str
    grid: PathGrid
    vertices: np.ndarray
    vertex_cov: np.ndarray
    offset: np.ndarray
    offset_sd: np.ndarray
    bands: Bands
    deviations: dict
    deviation_cov: dict
    vertex_budget: dict | None = None
    offset_budget: dict | None = None
    deviation_budget: dict | None = None
    dof: float = math.inf
    p: float = 0.95
    quantile_intervals: dict | None = None  # Monte Carlo: {"deviation": {...}, "vertex": (lo, hi)}

    @property
    def vertex_sd(self) -> np.ndarray:
        return np.sqrt(np.stack([self.vertex_cov[:, 0, 0], self.vertex_cov[:, 1, 1]], axis=1))

    def _ws(self, total_var, budget_rep) -> np.ndarray:
        if budget_rep is None or math.isinf(self.dof):
            return np.full(np.shape(total_var), math.inf)
        return effective_dof(np.sqrt(total_var), np.sqrt(np.clip(budget_rep, 0.0, None)), self.dof)

    @property
    def deviation_dof(self) -> dict:
        """Effective degrees of freedom per feature parameter (``inf``: normal)."""
        rep = None if self.deviation_budget is None else self.deviation_budget["repeatability"]
        out, i = {}, 0
        for fid, c in self.deviation_cov.items():
            k = c.shape[0]
            out[fid] = self._ws(np.diag(c), None if rep is None else rep[i : i + k])
            i += k
        return out

    @property
    def vertex_dof(self) -> np.ndarray:
        rep = None if self.vertex_budget is None else self.vertex_budget["repeatability"]
        return self._ws(self.vertex_sd**2, rep)

    @property
    def offset_dof(self) -> np.ndarray:
        rep = None if self.offset_budget is None else self.offset_budget["repeatability"]
        return self._ws(self.offset_sd**2, rep)

    @property
    def deviation_interval(self) -> dict:
        """``{feature: (lower, upper)}`` `p` intervals of every deviation parameter."""
        if self.quantile_intervals is not None:
            return self.quantile_intervals["deviation"]
        dofs = self.deviation_dof
        out = {}
        for fid, c in self.deviation_cov.items():
            half = coverage_factor(dofs[fid], self.p) * np.sqrt(np.clip(np.diag(c), 0.0, None))
            out[fid] = (self.deviations[fid] - half, self.deviations[fid] + half)
        return out

    @property
    def vertex_interval(self) -> tuple[np.ndarray, np.ndarray]:
        """`p` intervals of the vertex coordinates, ``(lower, upper)`` each ``(n+1, 2)``."""
        if self.quantile_intervals is not None:
            return self.quantile_intervals["vertex"]
        half = coverage_factor(self.vertex_dof, self.p) * self.vertex_sd
        return self.vertices - half, self.vertices + half

    def rows(self) -> list[dict]:
        """One row per vertex: position, standard uncertainties, correlation
        (toolpath_bounds.csv; mm, X as a radius)."""
        return _toolpath_rows.vertex_rows(self)

    def band_rows(self, profile: Profile) -> list[dict]:
        """One row per grid point: offset from nominal, its u and bands (toolpath_band.csv)."""
        return _toolpath_rows.band_rows(self, profile)

    def budget_rows(self, profile: Profile) -> list[dict]:
        """Per output and source, the variance share and u (uncertainty_budget.csv)."""
        return _toolpath_rows.budget_rows(self, profile)

    def to_dataframe(self, table: str = "vertices", *, profile: Profile | None = None):
        """A `pandas.DataFrame` of `table`: "vertices" (`rows()`), "band" or "budget"
        (these two name the features: give the `profile`)."""
        if table == "vertices":
            return rows_to_dataframe(self.rows())
        if table not in ("band", "budget"):
            raise ValueError(f"unknown table {table!r}; expected vertices, band or budget")
        if profile is None:
            raise ValueError(f"table {table!r} names the features: give profile=study.profile")
        return rows_to_dataframe(getattr(self, f"{table}_rows")(profile))

    def __repr__(self) -> str:
        sd = self.vertex_sd
        return (
            f"ToolpathUncertainty({self.method}, {len(self.vertices)} vertices, "
            f"max u(vertex) = {sd.max() * 1000:.2f} um, "
            f"simultaneous k = {self.bands.crit_simultaneous:.2f}, max band half-width "
            f"{np.max(self.bands.crit_simultaneous * self.offset_sd) * 1000:.2f} um)"
        )


def _split(profile, flat):
    out, i = [], 0
    for f in profile.features:
        out.append(flat[i : i + f.nparams])
        i += f.nparams
    return tuple(out)


def _gain_key(gain):
    return tuple(sorted(gain.items())) if isinstance(gain, dict) else float(gain)


def _grid_key(grid: PathGrid) -> str:
    """The grid's arrays as a digest (a key of kept traces: an array's repr elides)."""
    h = hashlib.sha256()
    for a in (grid.feature, grid.t, grid.points, grid.normals):
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.tobytes())
    return h.hexdigest()


def _kept(name: str, fn, *key):
    """`fn` through a trace kept across processes (`_config.KeptTrace`): tracing the
    path and residual Jacobians is most of a warm `demo`'s tool-path step."""
    return _config.KeptTrace(name, key, fn)


@functools.lru_cache(maxsize=64)
def _path_jacobian_jit(profile: Profile, grid: PathGrid, gain_key):
    gain = dict(gain_key) if isinstance(gain_key, tuple) else gain_key
    path_f = path_function(profile, grid, gain)

    def path_flat(devs_flat):
        verts, offs = path_f(_split(profile, devs_flat))
        return jnp.concatenate([verts.ravel(), offs])

    return jax.jit(lambda d: (path_flat(d), jax.jacfwd(path_flat)(d)))


@functools.lru_cache(maxsize=64)
def _path_jacobian(profile: Profile, grid: PathGrid, gain_key):
    """Jitted ``devs_flat -> (path values, d path / d devs)``, cached per structure."""
    fn = _path_jacobian_jit(profile, grid, gain_key)
    return _kept("path_jacobian", fn, profile, _grid_key(grid), gain_key)


@functools.lru_cache(maxsize=16)
def _batched_path_jacobian(profile: Profile, grid: PathGrid, gain_key):
    fn = jax.jit(jax.vmap(_path_jacobian_jit(profile, grid, gain_key)))
    return _kept("path_jacobians", fn, profile, _grid_key(grid), gain_key)


def path_jacobian_function(profile: Profile, grid: PathGrid, gain=1.0, *, batched=False):
    """The jitted map ``flat deviations -> (path values, their Jacobian)`` of the
    adjusted path (vertices then grid offsets), compiled once per profile, grid and
    gain; ``batched``: vmapped over rows of deviations (one part per row)."""
    key = _gain_key(gain)
    if batched:
        return _batched_path_jacobian(profile, grid, key)
    return _path_jacobian(profile, grid, key)


#: draws per call of the compiled path function: every number of draws is evaluated
#: in blocks of this size (the last one padded), so one compilation serves every part,
#: whatever its posterior's number of kept draws
PATH_BLOCK = 1024


@functools.lru_cache(maxsize=64)
def _batched_path(profile: Profile, grid: PathGrid, gain_key):
    """The path function over draws, `(vertices, offsets)` of each: jitted, vmapped and
    called on blocks of `PATH_BLOCK` draws (cached per structure)."""
    gain = dict(gain_key) if isinstance(gain_key, tuple) else gain_key
    block = jax.jit(jax.vmap(path_function(profile, grid, gain)))
    block = _kept("path_block", block, profile, _grid_key(grid), gain_key)

    def over_draws(stacked):
        m = len(stacked[0])
        pad = -m % PATH_BLOCK
        full = [
            np.concatenate([np.asarray(a), np.repeat(np.asarray(a)[-1:], pad, 0)]) for a in stacked
        ]
        outs = [block(tuple(a[i : i + PATH_BLOCK] for a in full))
                for i in range(0, m + pad, PATH_BLOCK)]  # fmt: skip
        return tuple(np.concatenate([np.asarray(o[k]) for o in outs])[:m] for k in range(2))

    return over_draws


@functools.lru_cache(maxsize=64)
def _residual_jacobians(
    profile: Profile,
    feature_ids: tuple,
    names: tuple,
    ball_radius: float,
    transform: MachineTransform,
    with_approach: bool,
    radius=None,
):
    """Jitted Jacobians of all residuals with respect to the deviations and to the
    inputs (points, then source deltas), cached per point pattern so that many
    parts of one study compile once."""
    ids = np.asarray(feature_ids)
    feats = profile.features
    index = [np.flatnonzero(ids == f.id) for f in feats]
    n_pts = 2 * len(ids)
    base = transform.as_array()

    measured = [(f, idx) for f, idx in zip(feats, index, strict=True) if idx.size]
    offsets = {f.id: i for i, f in enumerate(feats)}

    def residuals(devs_flat, x, appr):
        devs = _split(profile, devs_flat)
        return probe_residuals(
            measured,
            [devs[offsets[f.id]] for f, _ in measured],
            x[:n_pts].reshape(-1, 2),
            dict(zip(names, x[n_pts:], strict=True)),
            transform=base,
            ball_radius=ball_radius,
            approach=appr if with_approach else None,
            radius=radius,
        )

    fn = jax.jit(
        lambda d, x, a: (
            jax.jacfwd(residuals, argnums=0)(d, x, a),
            jax.jacfwd(residuals, argnums=1)(d, x, a),
        )
    )
    return _kept("residual_jacobians", fn, profile, feature_ids, names, ball_radius,
                 transform, with_approach, radius)  # fmt: skip


@dataclass(frozen=True)
class LinearisedOptions:
    """The measurement model and the outputs of [`linearised_toolpath`][].

    - `ball_radius`, `transform`: the probe's ball radius (mm) and the part-to-machine
      transform the points were fitted with.
    - `source_sd`: standard uncertainty of each other source (names in
      ``LINEARISED_SOURCES``, or a probe calibration's components), e.g. the sd
      of the study's priors.
    - `radius`: a probe calibration's `fit.RadiusComponents` (its components in
      `source_sd`, from `RadiusComponents.source_sd`): one systematic source,
      correlated over the points through the coefficients; the budget shows it as
      one line, ``"probe calibration"``.
    - `loss`: the fit's loss. A robust (M-)estimator is less efficient than least
      squares at the normal: the repeatability variance is multiplied by its
      asymptotic factor $\\kappa = E[\\psi^2]/E[\\psi']^2$ (Huber: 1.053). Without it the
      intervals of a robust fit with a known sigma covered 94.3 % instead of 95 %.
    - `gain`: compensation gain(s); `grid`: where the offset is evaluated (default
      `path_grid(profile)`); `p`: the coverage probability of intervals and bands.
    - `band_sims`: quasi-random draws for the simultaneous band's critical value.
    """

    ball_radius: float
    transform: MachineTransform = MachineTransform()
    source_sd: dict | None = None
    radius: object = None
    loss: str = "linear"
    gain: float | dict = 1.0
    grid: PathGrid | None = None
    p: float = 0.95
    band_sims: int = 100_000

    def __post_init__(self):
        radius = self.radius
        for name in self.source_sd or {}:
            if is_calibration_source(name) and radius is not None and name in radius.names:
                continue
            if name not in LINEARISED_SOURCES:
                raise InputError(
                    f"unknown uncertainty source {name!r}; "
                    f"expected one of {', '.join(LINEARISED_SOURCES)}"
                )


def linearised_toolpath(
    profile: Profile,
    feature_ids,
    machine_points,
    deviations: dict,
    *,
    options: LinearisedOptions,
    sigma: float,
    dof: float = math.inf,
    approach=None,
    inlier=None,
) -> ToolpathUncertainty:
    """GUM propagation from probe points and error sources to the adjusted path.

    The sensitivities of the fitted deviations to every input come from the
    implicit function theorem at the least-squares solution,
    $\\partial d/\\partial x = -(J_d^T J_d)^{-1} J_d^T J_x$ with $J_d$, $J_x$ the
    Jacobians (JAX autodiff) of the residuals with respect to the deviations and
    to the inputs; the path's sensitivities follow by the chain rule.

    **Arguments:**

    - `feature_ids`, `machine_points`: the inlier triggers (outliers removed),
      ball centres in machine coordinates (radius X, mm).
    - `deviations`: the fitted deviations per feature id (the solution).
    - `options`: the probe, the sources, the loss, the gain and the bands (a
      [`LinearisedOptions`][]).
    - `sigma`: probe repeatability: each coordinate of each point has variance
      ``sigma**2`` (the "repeatability" source); `dof`: its degrees of freedom
      (``ProfileFit.sigma``; ``inf`` when known): intervals and bands use
      Student-t quantiles with Welch-Satterthwaite effective dof.
    - `approach`: the approach direction of each point (for the pretravel and a
      probe calibration).
    - `inlier`: with every trigger given, which of them the fit kept (bool per
      point): the same result as the inliers alone (an outlier's residual row and
      its coordinates drop out), with one compiled Jacobian for every part of one
      point pattern (parts whose outliers differ do not compile again).

    **Returns:** a :class:`ToolpathUncertainty` with the budget.
    """
    o = options
    ball_radius, transform, radius, gain, p = o.ball_radius, o.transform, o.radius, o.gain, o.p
    source_sd = dict(o.source_sd or {})
    feature_ids = np.asarray(feature_ids).astype(str)
    pts = np.asarray(machine_points, dtype=float)
    grid = o.grid or path_grid(profile)
    names = tuple(source_sd)
    feats = profile.features
    dev0 = np.concatenate(
        [np.asarray(deviations.get(f.id, np.zeros(f.nparams)), dtype=float) for f in feats]
    )
    d_dx = _deviation_sensitivities(
        profile, feature_ids, pts, names, dev0, ball_radius, transform, approach, inlier, radius
    )
    y_path, j_path = map(np.asarray, _path_jacobian(profile, grid, _gain_key(gain))(dev0))
    jac = np.vstack([d_dx, j_path @ d_dx])
    n_pts = pts.size
    y = np.concatenate([np.asarray(dev0), y_path])
    var_rep = sigma**2 * normal_variance_factor(o.loss)
    var_x = np.concatenate([np.full(n_pts, var_rep), np.array([source_sd[n] ** 2 for n in names])])
    cov_y = (jac * var_x) @ jac.T
    n_dev = dev0.size
    n_v = 2 * (len(profile) + 1)
    sl_dev, sl_v, sl_o = slice(0, n_dev), slice(n_dev, n_dev + n_v), slice(n_dev + n_v, None)
    sources = {"repeatability": (np.arange(n_pts), np.full(n_pts, var_rep))}
    for k, name in enumerate(names):
        key = CALIBRATION_SOURCE if is_calibration_source(name) else name
        idx, var = sources.get(key, (np.zeros(0, dtype=int), np.zeros(0)))
        sources[key] = (np.append(idx, n_pts + k), np.append(var, source_sd[name] ** 2))
    budget = uncertainty_budget(jac, sources)
    vertices = y[sl_v].reshape(-1, 2)
    cv = cov_y[sl_v, sl_v]
    vcov = np.array([cv[2 * j : 2 * j + 2, 2 * j : 2 * j + 2] for j in range(len(vertices))])
    offset = y[sl_o]
    ocov = cov_y[sl_o, sl_o]
    if math.isfinite(dof):
        # the repeatability's share is scaled by the estimated sigma (t, `dof`); the
        # declared sources are known (Type B)
        j_rep = jac[sl_o, :n_pts]
        cov_a = (j_rep * var_rep) @ j_rep.T
        bands = bands_linear(offset, ocov, p=p, dof=dof, cov_estimated=cov_a, n_sim=o.band_sims)
    else:
        bands = bands_linear(offset, ocov, p=p, n_sim=o.band_sims)
    dev_val, dev_cov = _per_feature(feats, y[sl_dev], cov_y[sl_dev, sl_dev])
    return ToolpathUncertainty(
        method="linearised (GUM)",
        grid=grid,
        vertices=vertices,
        vertex_cov=vcov,
        offset=offset,
        offset_sd=np.sqrt(np.clip(np.diag(ocov), 0.0, None)),
        bands=bands,
        deviations=dev_val,
        deviation_cov=dev_cov,
        vertex_budget={k: v[sl_v].reshape(-1, 2) for k, v in budget.items()},
        offset_budget={k: v[sl_o] for k, v in budget.items()},
        deviation_budget={k: v[sl_dev] for k, v in budget.items()},
        dof=float(dof),
        p=p,
    )


def _deviation_sensitivities(
    profile, feature_ids, pts, names, dev0, ball_radius, transform, approach, inlier=None,
    radius=None,
) -> np.ndarray:  # fmt: skip
    """d(deviations)/d(inputs) at the solution by the implicit function theorem:
    $-(J_d^T J_d)^{-1} J_d^T J_x$ over the measured features (rows of unmeasured
    features stay 0); inputs are the point coordinates, then the sources `names`.
    With `inlier`, the residual rows of the other points are left out."""
    feats = profile.features
    # NumPy into the jitted Jacobians: an eager jnp.asarray compiles a program per shape
    x0 = np.concatenate([np.asarray(pts, dtype=float).ravel(), np.zeros(len(names))])
    jac_fn = _residual_jacobians(
        profile,
        tuple(feature_ids.tolist()),
        names,
        float(ball_radius),
        transform,
        approach is not None,
        radius,
    )
    j_d, j_x = map(
        np.asarray, jac_fn(dev0, x0, None if approach is None else np.asarray(approach, float))
    )
    index = [np.flatnonzero(feature_ids == f.id) for f in feats]
    if inlier is not None:  # residual rows come feature by feature, in profile order
        keep = np.asarray(inlier, dtype=bool)
        rows = np.concatenate([keep[idx] for idx in index if idx.size])
        j_d, j_x = j_d[rows], j_x[rows]
        index = [idx[keep[idx]] for idx in index]
    measured = np.concatenate(
        [np.full(f.nparams, idx.size > 0) for f, idx in zip(feats, index, strict=True)]
    )
    d_dx = np.zeros((dev0.size, x0.size))
    jm = j_d[:, measured]
    d_dx[measured] = -np.linalg.solve(jm.T @ jm, jm.T @ j_x)
    return d_dx


def _per_feature(feats, values, cov) -> tuple[dict, dict]:
    """Split the stacked deviations and their covariance by feature id."""
    dev_val, dev_cov, i = {}, {}, 0
    for f in feats:
        dev_cov[f.id] = cov[i : i + f.nparams, i : i + f.nparams]
        dev_val[f.id] = values[i : i + f.nparams]
        i += f.nparams
    return dev_val, dev_cov


def monte_carlo_toolpath(
    profile: Profile,
    deviation_samples: dict,
    *,
    gain=1.0,
    grid: PathGrid | None = None,
    p: float = 0.95,
    max_draws: int = 20_000,
    seed: int = 0,
) -> ToolpathUncertainty:
    """JCGM 101 propagation of posterior deviation draws to the adjusted path.

    **Arguments:**

    - `deviation_samples`: ``{feature_id: (M, nparams)}`` draws (features
      absent are as drawn); e.g. ``BayesProfileFit.deviation_samples``.
    - `max_draws`: thin to at most this many draws (seeded).
    """
    grid = grid or path_grid(profile)
    m = len(next(iter(deviation_samples.values())))
    rng = np.random.default_rng(seed)
    take = np.sort(rng.choice(m, max_draws, replace=False)) if m > max_draws else np.arange(m)
    stacked = tuple(
        np.asarray(deviation_samples[f.id], float)[take]
        if f.id in deviation_samples
        else np.zeros((len(take), f.nparams))
        for f in profile.features
    )
    batched = _batched_path(profile, grid, _gain_key(gain))
    verts, offs = batched(stacked)
    vcov = np.array([np.cov(verts[:, j, :], rowvar=False) for j in range(verts.shape[1])])
    means = {
        f.id: np.asarray(s).mean(axis=0) for f, s in zip(profile.features, stacked, strict=True)
    }
    # the path at the mean: the same compiled call as the draws (no eager operations)
    center_v, center_o = (
        np.asarray(a)[0] for a in batched(tuple(means[f.id][None] for f in profile.features))
    )
    bands = bands_from_samples(offs, center=np.asarray(center_o), p=p)
    q = [0.5 - p / 2, 0.5 + p / 2]
    vq = np.quantile(verts, q, axis=0)
    intervals = {
        "deviation": {
            f.id: tuple(np.quantile(np.asarray(s), q, axis=0))
            for f, s in zip(profile.features, stacked, strict=True)
        },
        "vertex": (vq[0], vq[1]),
    }
    return ToolpathUncertainty(
        method="Monte Carlo (JCGM 101)",
        grid=grid,
        vertices=np.asarray(center_v),
        vertex_cov=vcov,
        offset=np.asarray(center_o),
        offset_sd=offs.std(axis=0, ddof=1),
        bands=bands,
        deviations=means,
        deviation_cov={
            f.id: np.atleast_2d(np.cov(np.asarray(s), rowvar=False))
            for f, s in zip(profile.features, stacked, strict=True)
        },
        p=p,
        quantile_intervals=intervals,
    )
