r"""A lean solver for batches of small feature fits (`solver="fast"`/`"auto"` of `fit_profiles`).

[`kernel_solver`][] returns a jitted solve with the signature and result ([`LsqArrays`][])
of the batch engine's group solver. It minimises **the same staged objectives** as
[`solve_arrays`][] (same stages, scale re-estimation and losses) by Newton steps with the
$p \le 3$ normal equations in closed form, then computes the result's statistics **with
`_solve_core`'s formulas**: ~6 steps and ~15 µs per problem against ~125 steps and
~300 µs for LM under `vmap`. `tests/fit/test_batch.py` checks every field against the
per-part loop; if `_solve_core`'s statistics change, change them here too. Named losses
only (not a callable), residual functions with a fixed, small number of parameters, any
point-count bucket. The statistics' SVDs run in slices of [`svd_batch`][] problems, so
that jaxlib's batched LAPACK kernels stay on their calling thread (they deadlocked when
split over XLA's intra-op threads: docs/xla_batched_svd_deadlock.md).

The kernel: docs/models/batch_fits.md.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .lsq import FinalLoss, Status, analyse, losses, stages, statistics

#: Gauss-Newton iterations per stage before giving up (MAX_STEPS_REACHED -> engine)
MAX_ITER = 60
#: step halvings tried when a full step raises the objective
HALVINGS = 8
#: problems of at most this many (padded) points try every halving of a step at
#: once instead of in a loop (the loop's overhead exceeds 9 small evaluations)
HALVE_AT_ONCE = 64
#: curvature floor, a fraction of the IRLS weight rho'(z): where the exact robust
#: curvature vanishes (Huber beyond the scale) the step stays bounded (0: Newton,
#: 1: IRLS). 0.01 gave the fewest iterations and no failure on 28,000 fleet fits.
CURVATURE_FLOOR = 0.01
#: jaxlib's LAPACK kernels split a batch over XLA's intra-op threads, and block
#: one of them waiting, when it costs at least 2e5 flops by their model, 10 m n^2
#: for an m x n SVD (`GetLapackBatchChunkSize`); smaller batches run inline.
SVD_PARALLEL_FLOPS, SVD_FLOPS = 200_000, 10


def _runs(ids, cs):
    """The stage schedule as runs of one loss: `[(loss index, tuning constants)]`."""
    out = []
    for idx, c in zip(ids.tolist(), cs.tolist(), strict=True):
        if out and out[-1][0] == idx:
            out[-1][1].append(c)
        else:
            out.append((int(idx), [c]))
    return [(idx, np.asarray(c, dtype=float)) for idx, c in out]


def _spd_solve(a, b):
    """Solve `a x = b` for a small symmetric positive definite `a` (Cholesky, unrolled)."""
    p = a.shape[0]
    low = [[None] * p for _ in range(p)]
    for i in range(p):
        for j in range(i + 1):
            s = a[i, j] - sum(low[i][k] * low[j][k] for k in range(j))
            if i == j:
                low[i][i] = jnp.sqrt(jnp.maximum(s, 0.0))
            else:
                low[i][j] = s / low[j][j]
    y = []
    for i in range(p):
        y.append((b[i] - sum(low[i][k] * y[k] for k in range(i))) / low[i][i])
    x = [None] * p
    for i in reversed(range(p)):
        x[i] = (y[i] - sum(low[k][i] * x[k] for k in range(i + 1, p))) / low[i][i]
    return jnp.stack(x)


@functools.lru_cache(maxsize=64)
def kernel_solver(fn, p: int, loss: str, rtol: float, atol: float):
    """Jitted `vmap` over problems of the lean staged solve, then the statistics in
    slices of `svd_batch` problems; the same signature and result (`LsqArrays`) as
    the batch engine's group solver: `solve(points, geom, ball_radius, weights,
    scale, sigma)`, the first, second and fourth batched."""
    robust = losses.loss_id(loss) != 0
    ids, cs = stages(loss) if robust else (np.zeros(1, np.int32), np.ones(1))
    final = FinalLoss(idx=int(ids[-1]), tuning=float(cs[-1]), custom=None, robust=robust)
    one = functools.partial(_solve_one, fn, p, robust, tuple(_runs(ids, cs)), rtol, atol)
    stats = functools.partial(_statistics_one, fn, final, atol)

    def solve(points, geom, ball_radius, w, scale, sigma):
        y, code, steps, s_final = jax.vmap(one, in_axes=(0, 0, None, 0, None))(
            points, geom, ball_radius, w, scale
        )
        return jax.lax.map(
            lambda a: stats(*a, ball_radius, sigma),
            (points, geom, w, y, code, steps, s_final),
            batch_size=svd_batch(points.shape[0], points.shape[1], p),
        )

    return jax.jit(solve)


def svd_batch(batch: int, n: int, p: int) -> int:
    """Problems per call of the statistics' batched SVDs: few enough that jaxlib's
    LAPACK kernel runs them on its calling thread (`docs/xla_batched_svd_deadlock.md`)."""
    return int(max(1, min(batch, (SVD_PARALLEL_FLOPS - 1) // (SVD_FLOPS * n * p * p))))


def _solve_one(fn, p, robust, runs, rtol, atol, points, geom, ball_radius, w, scale):
    """One problem: the stages (`runs`) from zero; the solution, its status code,
    the Newton steps and the final scale."""
    args = (points, geom, ball_radius)
    mask = w > 0
    wsqrt = jnp.sqrt(jnp.where(mask, w, 0.0))

    def weighted(y):
        return jnp.where(mask, wsqrt * fn(y, args), 0.0)

    carry = (jnp.zeros(p), jnp.asarray(True), jnp.asarray(0))
    for idx, cs_run in runs:
        carry, s_run = _run(weighted, mask, scale, carry, idx, cs_run, rtol, atol)
    y, ok, steps = carry
    s_final = s_run if robust else jnp.asarray(jnp.nan)
    code = jnp.where(ok, int(Status.SUCCESSFUL), int(Status.MAX_STEPS_REACHED))
    return y, code, steps, s_final


def _statistics_one(fn, final: FinalLoss, atol,
                    points, geom, w, y, code, steps, s_final, ball_radius, sigma):  # fmt: skip
    """The statistics of `_solve_core` at the solution `y`: the same functions."""
    args = (points, geom, ball_radius)
    mask = w > 0
    wsqrt = jnp.sqrt(jnp.where(mask, w, 0.0))
    info = analyse(fn, args, y, mask, wsqrt, s_final, final)
    return statistics(info, y, code, steps, s_final, mask, w, sigma, final, atol)


def _run(weighted, mask, scale, carry, idx, cs_run, rtol, atol):
    """Stages of one loss (a static index: one branch of the loss switch is traced,
    not all of them) over the tuning constants `cs_run`, from `carry` =
    `(y, ok, steps)`; returns the new carry and the last stage's scale.

    With a given scale a repeated stage is the same problem, started at its minimum
    (the engine's repeat moves ~1 ulp): the loop stops before it, so a given scale
    runs one stage of the loss, not `len(cs_run)` empty ones (~0.1 ms a group)."""
    n = len(cs_run)
    cs = jnp.asarray(cs_run)
    given = ~jnp.isnan(scale)

    def body(state):
        k, (y, ok_before, steps), _ = state
        if idx == 0:
            s = jnp.asarray(1.0)
        else:  # a cond, not a where: the MAD (two sorts) only when estimated
            s = jax.lax.cond(
                given,
                lambda: jnp.asarray(scale, dtype=float),
                lambda: cs[k] * losses.mad_sigma(weighted(y), mask),
            )
        y, it, ok = _newton(weighted, y, jnp.asarray(s, dtype=float), idx, rtol, atol)
        return k + 1, (y, ok, steps + it), jnp.asarray(s, float)

    def cond(state):
        k = state[0]
        return (k < n) & ((k == 0) | ~given)

    start = (jnp.asarray(0), carry, jnp.asarray(1.0 if idx == 0 else np.nan))
    _, carry, s = jax.lax.while_loop(cond, body, start)
    return carry, s


def _newton(weighted, y, s, idx, rtol, atol):
    """Newton steps on the stage's objective $\\tfrac12\\sum s^2\\rho(z)$ with
    the curvature $J^T \\mathrm{diag}(\\max(\\rho' + 2z\\rho'', 0)) J$ (Gauss-Newton
    for the linear loss; for Huber exact on the active set, so it ends in a
    few steps where Gauss-Newton on the wrapped residuals crawls), halved
    until the objective does not rise; until the step is negligible or no
    step lowers the objective (the final stationarity check judges it).
    Returns the solution, the steps taken and whether it ended cleanly."""

    def body(state):
        y, it, _, _ = state
        y_new, small, good, finite = _newton_step(weighted, y, s, idx, rtol, atol)
        return y_new, it + 1, small | ~good, finite

    def cond(state):
        _, it, done, _ = state
        return (it < MAX_ITER) & ~done

    y, it, done, finite = jax.lax.while_loop(
        cond, body, (y, jnp.asarray(0), jnp.asarray(False), jnp.asarray(True))
    )
    return y, it, done & finite


def _newton_step(weighted, y, s, idx, rtol, atol):
    """One Newton step from `y`, halved (at most `HALVINGS` times) until the
    objective does not rise beyond rounding: the new point, whether the step was
    negligible, whether it was taken, and whether the new point is finite."""
    eps = jnp.finfo(float).eps
    d2 = jnp.vectorize(jax.grad(lambda z: losses.rho_prime(idx, z)))

    def cost(yy):
        e = weighted(yy)
        return 0.5 * jnp.sum(e * e * losses.rho_over_z(idx, (e / s) ** 2))

    e = weighted(y)
    je = jax.jacfwd(weighted)(y)
    z = (e / s) ** 2
    rp = losses.rho_prime(idx, z)
    curv = jnp.maximum(rp + 2.0 * z * d2(z), CURVATURE_FLOOR * rp)
    a = je.T @ (curv[:, None] * je)
    d = jnp.sqrt(jnp.diagonal(a))
    d = jnp.where(d > 0, d, 1.0)
    step = _spd_solve(a / jnp.outer(d, d), -(je.T @ (rp * e)) / d) / d
    c0 = 0.5 * jnp.sum(e * e * losses.rho_over_z(idx, z))
    limit = c0 * (1.0 + 16.0 * eps)

    if e.shape[0] <= HALVE_AT_ONCE:
        # the full step and every halving at once: on the CPU an iteration of a
        # nested loop costs more than these few small residual evaluations; the first
        # that does not raise the objective, the one halving in turn finds (the same
        # powers of two: the same bits)
        fs = 0.5 ** jnp.arange(HALVINGS + 1.0)
        cs = jax.vmap(lambda f: cost(y + f * step))(fs)
        k = jnp.argmax(jnp.isfinite(cs) & (cs <= limit))
        f, c = fs[k], cs[k]
    else:  # many points: evaluations dominate, halve only while needed

        def halve(hs):
            f, c, k = hs
            return f * 0.5, cost(y + 0.5 * f * step), k + 1

        def worse(hs):
            _, c, k = hs
            return ~(jnp.isfinite(c) & (c <= limit)) & (k < HALVINGS)

        start = (jnp.asarray(1.0), cost(y + step), jnp.asarray(0))
        f, c, _ = jax.lax.while_loop(worse, halve, start)
    good = jnp.isfinite(c) & (c <= limit) & jnp.all(jnp.isfinite(step))
    y_new = jnp.where(good, y + f * step, y)
    small = jnp.all(jnp.abs(step) <= rtol * jnp.abs(y) + atol)
    finite = jnp.all(jnp.isfinite(y_new))
    return y_new, small, good, finite
