"""The compiled solves of [`fit_profiles`][]: one jitted `vmap` per group (residual
function, settings), batches padded to a fixed size, dispatched asynchronously
and fetched as one packed array, and `solver="auto"`'s Levenberg-Marquardt
retries of what the batch kernel did not solve."""

from __future__ import annotations

import functools
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from ..geometry import Profile
from ._batch_kernel import kernel_solver, svd_batch
from ._features import feature_residuals, geometry_args
from .lsq import LsqArrays, SolverOptions, Status, solve_arrays

#: points (problems x bucket) per compiled call at most: buckets over 256 points
#: get fewer problems per call (4,096 points: 16), so that a small study of densely
#: probed parts is not padded to 256 problems and a call's arrays stay ~10 MB.
#: Like `BATCH` (`BatchOptions`' default), it depends on the bucket only: one compilation per group.
BATCH_POINTS = 1 << 16
#: fields of `LsqArrays` kept per problem (all of them: `profile_fit` rebuilds results)
_FIELDS = LsqArrays._fields


class Settings(NamedTuple):
    """What every solve of one batch fit shares: the loss, the solver choice
    (`fit_profiles`' `solver`), the tolerances, and the ball radius, loss scale
    and sigma as arrays."""

    loss: str
    solver: str
    rtol: float
    atol: float
    max_steps: int
    ball_radius: jax.Array
    scale: jax.Array
    sigma: jax.Array


def _engine_one(kind, free, loss, solver, rtol, atol, max_steps):
    """One problem solved as `fit_feature` solves it: `solve_arrays` from zero with
    the feature's residual function and the settings."""
    fn = feature_residuals(kind, free)
    p = len(free)
    options = SolverOptions(method=solver, rtol=rtol, atol=atol, max_steps=max_steps)

    def one(points, geom, ball_radius, weights, scale, sigma):
        return solve_arrays(
            fn,
            jnp.zeros(p),
            (points, geom, ball_radius),
            weights,
            loss=loss,
            scale=scale,
            sigma=sigma,
            solver=options,
        )

    return one


@functools.lru_cache(maxsize=64)
def _engine_group_solver(kind, free, loss, solver, rtol, atol, max_steps):
    """Jitted `vmap` of `solve_arrays` for one residual function and settings."""
    one = _engine_one(kind, free, loss, solver, rtol, atol, max_steps)

    def solve(points, geom, ball_radius, weights, scale, sigma):
        # in slices small enough for jaxlib's LAPACK kernels (QR, SVD) to run
        # inline: split over XLA's intra-op threads they can deadlock
        return jax.lax.map(
            lambda a: one(*a[:2], ball_radius, a[2], scale, sigma),
            (points, geom, weights),
            batch_size=svd_batch(points.shape[0], points.shape[1], len(free)),
        )

    return jax.jit(solve)


@functools.lru_cache(maxsize=64)
def _lm_retry_solver(kind, free, loss, rtol, atol, max_steps):
    """`_engine_one` with LM, jitted: a call dispatches in ~0.1 ms, where the engine's
    own entry (`solve_arrays`' eager preparation, `equinox.filter_jit`) takes ~1 ms."""
    return jax.jit(_engine_one(kind, free, loss, "lm", rtol, atol, max_steps))


def group_solver(st: Settings, kind: str, free: tuple[int, ...], n_pad: int):
    """The compiled solve of a group: the batch kernel for `"auto"`/`"fast"` (every
    bucket, 8 to 4,096 points and more), or the engine solver `st.solver`. (Before,
    buckets over 32 points went to Levenberg-Marquardt: with 64 points the kernel
    hung in XLA's CPU runtime, a deadlock of jaxlib's batched SVD that the kernel
    now avoids, `docs/xla_batched_svd_deadlock.md`.)"""
    del n_pad  # the kernel's compilations are per shape
    if st.solver in ("auto", "fast"):
        return kernel_solver(feature_residuals(kind, free), len(free), st.loss, st.rtol, st.atol)
    return _engine_group_solver(kind, free, st.loss, st.solver, st.rtol, st.atol, st.max_steps)


def batch_rows(bsize: int, n_pad: int) -> int:
    """Problems per compiled call for the bucket `n_pad`: `bsize`, at most
    `BATCH_POINTS` points (at least one problem)."""
    return max(1, min(int(bsize), BATCH_POINTS // int(n_pad)))


def dispatch(solve, rows, data, bsize, st: Settings):
    """Start the solve of `rows` padded to `bsize` problems (asynchronous). `data`:
    `(pp, ff, counts, starts, order, centres, geoms, n_pad)`, the problems' part
    and feature, the points per (part, feature), where they start in `order`, the
    point order, the points, the geometry table and the group's bucket."""
    take = np.concatenate([rows, np.repeat(rows[:1], bsize - rows.size)])
    pts, geom, w = _problems(take, data)
    # NumPy into the jitted solve (it transfers them): an eager jnp.asarray compiles a
    # program per shape
    geom = tuple(np.asarray(leaf) for leaf in geom)
    args = (np.asarray(pts), geom, st.ball_radius, np.asarray(w), st.scale, st.sigma)
    run, layouts = _packed(solve)
    packed = run(*args)
    return packed, _unpacker(solve, layouts, _hashable(jax.tree_util.tree_map(jnp.shape, args)))


def _problems(rows, data):
    """The problems `rows` as solved: points padded to the group's bucket by repeating
    the first (as `fit_feature` pads them) with weight zero, `(m, n_pad, 2)`; their
    nominal geometry (leaves `(m, ...)`); the weights `(m, n_pad)`."""
    pp, ff, counts, starts, order, centres, geoms, n_pad = data
    cnt = counts[pp[rows], ff[rows]]
    start = starts[pp[rows], ff[rows]]
    j = np.arange(n_pad)
    idx = start[:, None] + np.where(j[None, :] < cnt[:, None], j[None, :], 0)
    w = (j[None, :] < cnt[:, None]).astype(float)
    return centres[order[idx]], tuple(leaf[ff[rows]] for leaf in geoms), w


@functools.lru_cache(maxsize=128)
def _packed(solve):
    """`solve` with its 17 result arrays packed into one `(B, K)` float64 array: one
    transfer per batch instead of 17 (integer codes and flags are exact in float64);
    and the layouts its traces saw, argument shapes -> the result (`_unpacker`)."""
    layouts: dict = {}

    def run(*args):
        out = solve(*args)
        shapes = _hashable(jax.tree_util.tree_map(jnp.shape, args))
        layouts[shapes] = jax.tree_util.tree_map(
            lambda a: jax.ShapeDtypeStruct(a.shape, a.dtype), out
        )
        b = out.params_flat.shape[0]
        return jnp.concatenate(
            [jnp.reshape(getattr(out, n), (b, -1)).astype(float) for n in _FIELDS], axis=1
        )

    return jax.jit(run), layouts


@functools.lru_cache(maxsize=128)
def _layout(solve, shapes):
    return jax.eval_shape(solve, *jax.tree_util.tree_map(
        lambda s: jax.ShapeDtypeStruct(s, jnp.float64), shapes,
        is_leaf=lambda x: isinstance(x, tuple) and all(isinstance(i, int) for i in x),
    ))  # fmt: skip


def _unpacker(solve, layouts: dict, shapes):
    """Field name -> (column slice, per-problem shape, dtype) of `_packed(solve)` on
    arguments of `shapes`: the layout its trace saw (`eval_shape` traced the solver a
    second time, ~0.8 s a group, in every process), or, where the packed call was
    not traced here, `eval_shape`'s."""
    out = layouts.get(shapes) or _layout(solve, shapes)
    cols, k = {}, 0
    for n in _FIELDS:
        a = getattr(out, n)
        size = int(np.prod(a.shape[1:], dtype=int))
        cols[n] = (slice(k, k + size), a.shape[1:], a.dtype)
        k += size
    return cols


def _hashable(tree):
    return tuple(_hashable(x) for x in tree) if isinstance(tree, tuple | list) else tree


def fetch(dev, m: int) -> dict:
    """The first `m` problems' results as writable NumPy arrays."""
    packed, cols = dev
    arr = np.asarray(jax.device_get(packed))[:m]
    return {
        n: arr[:, sl].reshape((m, *shape)).astype(dtype) for n, (sl, shape, dtype) in cols.items()
    }


def retry_lm(out: dict, rows, data, kind, free, st: Settings) -> None:
    """`solver="auto"`: problems that Gauss-Newton did not solve are solved again
    with Levenberg-Marquardt, in place, one by one as the loop (`fit_feature`) solves
    them: the same residual function, padded points, start and settings, so their
    status, and a failure's message, are the loop's. One problem at a time compiles
    the loop's solve (~1-2 s), not a batched one (8-15 s, for a few retried problems:
    the 3-point faces of `tests/jobs/test_coverage.py` that a robust fit leaves
    DEGENERATE); each then costs ~1 ms."""
    bad = np.flatnonzero(out["status_code"] != int(Status.SUCCESSFUL))
    if bad.size == 0:
        return
    solve = _lm_retry_solver(kind, free, st.loss, st.rtol, st.atol, st.max_steps)
    pts, geom, w = _problems(rows[bad], data)
    for i, b in enumerate(bad):
        geom_i = tuple(leaf[i] for leaf in geom)
        res = jax.device_get(solve(pts[i], geom_i, st.ball_radius, w[i], st.scale, st.sigma))
        for name in out:
            out[name][b] = getattr(res, name)


@functools.lru_cache(maxsize=64)
def geometry_table(profile: Profile) -> tuple[np.ndarray, ...]:
    """The features' nominal geometry (`geometry_args`) stacked, `(F, ...)` per leaf;
    cached per profile (building it takes ~100 eager JAX operations)."""
    geoms = [geometry_args(f) for f in profile.features]
    return tuple(np.stack([np.asarray(g[k]) for g in geoms]) for k in range(len(geoms[0])))
