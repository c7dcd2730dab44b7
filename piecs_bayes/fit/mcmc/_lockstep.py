r"""Bayesian fits of many parts: independent ensembles stepped in lockstep.

[`sample_posteriors`][] samples one log posterior for `P` parts (`x0` of shape
`(P, dim)`, every leaf of `args` with a leading axis of length `P`) and returns one
[`Posterior`][] per part. Every part gets `n_ensembles` ensembles of its own, as
[`sample_posterior`][] does, and all ensembles advance together: each half-step of the
red-blue scheme proposes a move for half of the walkers of every ensemble from the other
half of the same ensemble, and one jitted, `vmap`-ed call evaluates all proposals
(`backend="jax"`: the whole chain one JAX loop; `"numpy"`). Each ensemble is exactly an
emcee ensemble (same moves, same acceptance rule; only the random numbers differ), the
parts are independent Markov chains, and the diagnostics and convergence verdict per
part are [`sample_posterior`][]'s. Validated against emcee on the same posteriors.

Why parts never share an ensemble: docs/models/sampling.md.
"""

from __future__ import annotations

import functools
import sys
import time
import warnings
from collections.abc import Callable
from typing import Any, Literal

import jax
import jax.numpy as jnp
import numpy as np

from ... import _config
from ...errors import AnalysisError, InputError
from ._core import (
    ConvergenceError,
    ConvergenceWarning,
    cov_from_hessian,
    diagnose,
    kept_trace,
    neg_hessians,
    sqrt_psd,
    start_cov,
)
from ._diagnostics import problems as _problems
from ._moves import DE_FRACTION, DE_SIGMA, STRETCH_A, de_gamma0
from ._options import SamplerOptions
from ._posterior import Posterior, make_posterior

#: The sampler's name in `Posterior.sampler` and posterior.nc (with the backend).
LOCKSTEP = "piecs_bayes lockstep ensembles"


@functools.lru_cache(maxsize=64)
def _parts_walkers(log_prob):
    """`log_prob(theta, args)` jitted and vmapped over parts (theta and args) and
    walkers (theta only), cached per function (its traces kept across processes where
    `log_prob` has a `trace_key`)."""
    over_walkers = jax.vmap(log_prob, in_axes=(0, None))
    fn = jax.jit(jax.vmap(over_walkers, in_axes=(0, 0)))
    return kept_trace("parts_walkers", log_prob, fn) or fn


def _evaluate(vec, q, args, n_parts, n_ens):
    """Log posterior of proposals `q` `(P*K, m, d)` -> `(P*K, m)`, NaN -> -inf."""
    e, m, d = q.shape
    flat = q.reshape(n_parts, n_ens * m, d)
    lp = np.asarray(vec(flat, args), dtype=float).reshape(e, m)  # NumPy in: no eager transfer
    return np.where(np.isnan(lp), -np.inf, lp)


def _half_step(rng, coords, lp, s_idx, c_idx, moves, ndim, lp_fn):
    """One red-blue half-step for all ensembles at once: walkers `s_idx` `(E, h)`
    move using their ensemble's walkers `c_idx` `(E, h)`. Updates in place;
    returns the accepted mask `(E, h)`."""
    e, h = s_idx.shape
    rows = np.arange(e)[:, None]
    s = coords[rows, s_idx]  # (E, h, d)
    c = coords[rows, c_idx]
    # stretch: q = c_j + z (s - c_j), log factor (d - 1) log z
    a = STRETCH_A
    z = ((a - 1.0) * rng.random((e, h)) + 1.0) ** 2 / a
    j = rng.integers(0, h, size=(e, h))
    cj = c[rows, j]
    q_st = cj - (cj - s) * z[..., None]
    f_st = (ndim - 1.0) * np.log(z)
    if moves == "de":
        # differential evolution: q = s + gamma (c_k - c_l), k != l, factor 0
        k = rng.integers(0, h, size=(e, h))
        l_ = rng.integers(0, h - 1, size=(e, h))
        l_ = l_ + (l_ >= k)
        gamma = de_gamma0(ndim) * (1.0 + DE_SIGMA * rng.standard_normal((e, h, 1)))
        q_de = s + gamma * (c[rows, l_] - c[rows, k])
        use_de = rng.random(e) < DE_FRACTION  # one move per ensemble and step
        q = np.where(use_de[:, None, None], q_de, q_st)
        f = np.where(use_de[:, None], 0.0, f_st)
    else:
        q, f = q_st, f_st
    lp_new = lp_fn(q)
    lp_old = lp[rows, s_idx]
    accept = (f + lp_new - lp_old) > np.log(rng.random((e, h)))
    coords[rows, s_idx] = np.where(accept[..., None], q, s)
    lp[rows, s_idx] = np.where(accept, lp_new, lp_old)
    return accept


#: kept steps per jitted block of the JAX backend (the progress bar moves per block)
_BLOCK = 250


@functools.lru_cache(maxsize=32)
def _jax_chain(log_prob, n_parts: int, k_ens: int, w: int, ndim: int, moves: str, thin: int):
    """The jitted runner of the lockstep ensembles, cached per model.

    `advance(carry, n_skip, n_keep, args)` runs `n_skip` steps, then `n_keep * thin`
    steps keeping the state after every `thin`-th, and returns the carry and the
    kept `(n_keep, E, W, d)` walkers and log posteriors (in a buffer of `_BLOCK`
    rows; `n_keep <= _BLOCK`). The loop runs over half-steps (the red-blue scheme:
    a new random split of every ensemble on each even half-step), so that the log
    posterior is compiled once: one program for burn-in and every block.
    """
    vec = jax.vmap(jax.vmap(log_prob, in_axes=(0, None)), in_axes=(0, 0))
    n_e, h = n_parts * k_ens, w // 2
    rows = np.arange(n_e)[:, None]  # a constant of the trace

    def lp_fn(q, args):
        out = vec(q.reshape(n_parts, k_ens * h, ndim), args).reshape(n_e, h)
        return jnp.where(jnp.isnan(out), -jnp.inf, out)

    def half(key, coords, lp, s_idx, c_idx, args):
        ks = jax.random.split(key, 7)
        s, c = coords[rows, s_idx], coords[rows, c_idx]
        z = ((STRETCH_A - 1.0) * jax.random.uniform(ks[0], (n_e, h)) + 1.0) ** 2 / STRETCH_A
        j = jax.random.randint(ks[1], (n_e, h), 0, h)
        cj = c[rows, j]
        q = cj - (cj - s) * z[..., None]
        f = (ndim - 1.0) * jnp.log(z)
        if moves == "de":
            k = jax.random.randint(ks[2], (n_e, h), 0, h)
            l_ = jax.random.randint(ks[3], (n_e, h), 0, h - 1)
            l_ = l_ + (l_ >= k)
            gamma = de_gamma0(ndim) * (1.0 + DE_SIGMA * jax.random.normal(ks[4], (n_e, h, 1)))
            q_de = s + gamma * (c[rows, l_] - c[rows, k])
            use_de = jax.random.uniform(ks[5], (n_e,)) < DE_FRACTION
            q = jnp.where(use_de[:, None, None], q_de, q)
            f = jnp.where(use_de[:, None], 0.0, f)
        lp_new = lp_fn(q, args)
        lp_old = lp[rows, s_idx]
        acc = (f + lp_new - lp_old) > jnp.log(jax.random.uniform(ks[6], (n_e, h)))
        coords = coords.at[rows, s_idx].set(jnp.where(acc[..., None], q, s))
        lp = lp.at[rows, s_idx].set(jnp.where(acc, lp_new, lp_old))
        return coords, lp, acc

    def half_step(i, state, n_skip, args):
        key, coords, lp, n_acc, perm, kept, kept_lp = state
        key, k0, k1 = jax.random.split(key, 3)
        first = i % 2 == 0  # first half of a step: a new split (emcee's random split)
        new = jnp.argsort(jax.random.uniform(k0, (n_e, w)), axis=1).astype(perm.dtype)
        perm = jnp.where(first, new, perm)
        s_idx = jnp.where(first, perm[:, :h], perm[:, h:])
        c_idx = jnp.where(first, perm[:, h:], perm[:, :h])
        coords, lp, acc = half(k1, coords, lp, s_idx, c_idx, args)
        n_acc = n_acc.at[rows, s_idx].add(acc)
        j = i // 2 - n_skip + 1  # steps done after the skipped ones
        slot = jnp.where(~first & (j > 0) & (j % thin == 0), j // thin - 1, _BLOCK)
        kept = jax.lax.dynamic_update_index_in_dim(kept, coords, slot, 0)  # row _BLOCK: discarded
        kept_lp = jax.lax.dynamic_update_index_in_dim(kept_lp, lp, slot, 0)
        return key, coords, lp, n_acc, perm, kept, kept_lp

    @jax.jit
    def advance(carry, n_skip, n_keep, args):
        key, coords, lp, n_acc = carry
        state = (
            key, coords, lp, n_acc, jnp.zeros((n_e, w), dtype=jnp.int32),
            jnp.zeros((_BLOCK + 1, n_e, w, ndim), coords.dtype),
            jnp.zeros((_BLOCK + 1, n_e, w), lp.dtype),
        )  # fmt: skip
        n_half = 2 * (n_skip + n_keep * thin)
        state = jax.lax.fori_loop(0, n_half, lambda i, s: half_step(i, s, n_skip, args), state)
        return state[:4], state[5][:_BLOCK], state[6][:_BLOCK]

    return advance


@functools.lru_cache(maxsize=32)
def _kept_chain(log_prob, n_parts: int, k_ens: int, w: int, ndim: int, moves: str, thin: int):
    """`_jax_chain`'s runner through a trace kept across processes (None when
    `log_prob` has no `trace_key`), one per model: later runs reuse its program."""
    advance = _jax_chain(log_prob, n_parts, k_ens, w, ndim, moves, thin)
    return kept_trace("lockstep_advance", log_prob, advance, n_parts, k_ens, w, ndim, moves,
                      thin, _BLOCK, compiler_options=_config.LONG_RUNNING)  # fmt: skip


def threefry_key(seed: int):
    """`jax.random.PRNGKey(seed)` made in NumPy where JAX's generator is the default
    threefry (the same two words: high and low 32 bits of the seed), without the two
    programs JAX compiles for it; JAX's own key otherwise."""
    if jax.config.jax_default_prng_impl != "threefry2x32":
        return jax.random.PRNGKey(seed)
    return np.array([(seed >> 32) & 0xFFFFFFFF, seed & 0xFFFFFFFF], dtype=np.uint32)


def _prepare_jax(log_prob, args, coords, lp, n_parts, k_ens, moves, burn, thin, n_keep, seed):
    """The JAX backend, compiled (so that the run's wall time excludes compilation):
    a function `run(bar)` that returns the kept walkers `(n_keep, E, W, d)`, their
    log posteriors, the accepted moves per walker and the number of steps run."""
    n_e, w, ndim = coords.shape
    advance = _jax_chain(log_prob, n_parts, k_ens, w, ndim, moves, thin)
    # transferred, not made by eager JAX operations (each compiled per shape)
    carry = _config.on_device((threefry_key(seed), coords, lp, np.zeros((n_e, w))))
    kept = _kept_chain(log_prob, n_parts, k_ens, w, ndim, moves, thin)
    n0 = np.asarray(0, np.int64)
    compiled = None if kept is None else kept.compiled(carry, n0, n0, args)
    if compiled is None:
        # n_skip, n_keep: traced; thousands of steps: the faster code, not the faster compile
        advance = advance.lower(carry, 0, 0, args).compile(_config.LONG_RUNNING)
    else:  # the trace kept across processes (~0.5 s to trace and lower): counts as arrays

        def advance(carry, n_skip, n_keep, args):
            n_skip, n_keep = np.asarray(n_skip, np.int64), np.asarray(n_keep, np.int64)
            return compiled(carry, n_skip, n_keep, args)

    def run(bar):
        nonlocal carry
        done = 0
        while done < burn:  # in blocks, for the progress bar
            n = min(burn - done, _BLOCK * thin)
            carry = advance(carry, n, 0, args)[0]
            done += n
            # wait for each block (not only for the bar): no queue of dispatched
            # blocks outlives a Ctrl-C or SIGTERM raised between them
            jax.block_until_ready(carry)
            if bar is not None:
                bar.update(done - bar.n)
        chains, lps = [], []
        for lo in range(0, n_keep, _BLOCK):
            m = min(_BLOCK, n_keep - lo)
            carry, c, lp_b = advance(carry, 0, m, args)
            chains.append(np.asarray(c)[:m])  # sliced in NumPy: no program per slice
            lps.append(np.asarray(lp_b)[:m])
            if bar is not None:
                bar.update(min(bar.total, burn + (lo + m) * thin) - bar.n)
        kept_lp = np.concatenate(lps)
        kept_lp = np.where(np.isnan(kept_lp), -np.inf, kept_lp)
        return np.concatenate(chains), kept_lp, np.asarray(carry[3]), burn + n_keep * thin

    return run


def sample_posteriors(
    log_prob: Callable,
    x0,
    *,
    names,
    args: Any,
    cov0=None,
    options: SamplerOptions = SamplerOptions(),
    backend: Literal["jax", "numpy"] = "jax",
) -> list[Posterior]:
    """Sample the posteriors of many parts of one model together (see module doc).

    **Arguments:**

    - `log_prob`: `log_prob(theta, args) -> scalar`, JAX-traceable, as for
      [`sample_posterior`][]; the same function (one compilation) for every part.
    - `x0`: `(P, dim)` start (the least-squares optimum) of each part.
    - `args`: pytree whose every leaf has a leading axis of length `P`: part
      `p`'s data is `tree_map(lambda a: a[p], args)`.
    - `cov0`: start-ball covariance per part, `(P, dim, dim)` or `(P, dim)`
      variances; `None`: the inverse Hessian of `-log_prob` at each `x0`.
    - `options`: the [`SamplerOptions`][] as [`sample_posterior`][] takes them (its
      `sampler` is not read: this is the lockstep sampler); `on_fail` applies per
      part (one warning lists every failing part); `progress`: one tqdm progress bar
      for all ensembles, a callable also gets a line before the diagnostics.
    - `backend`: `"jax"` (default): the whole chain is one jitted loop (moves,
      acceptance and the log posterior, compiled once per model; run in blocks of
      `_BLOCK` kept steps for the progress bar), no Python per step; `"numpy"`: the
      moves in NumPy around one jitted log-posterior call per half-step (emcee's
      structure). Same algorithm, other random numbers. With `thin > 1` the JAX
      backend keeps every `thin`-th state after `burn` (and may run up to
      `thin - 1` steps more).

    `Posterior.wall_time` is the run's wall time (compilation excluded) divided by
    the number of parts; `Posterior.sampler` is `LOCKSTEP` with the backend.

    **Returns:** one [`Posterior`][piecs_bayes.fit.Posterior] per part, in order.
    """
    x0, names, opts = _checked_run(x0, names, args, options, backend)
    n_parts, ndim = x0.shape
    cov0 = None if cov0 is None else np.asarray(cov0, dtype=float)
    args = _config.on_device(args)
    vec = _parts_walkers(log_prob)
    k_ens, w = opts.n_ensembles, opts.nwalkers
    nsteps, burn, thin, moves = opts.nsteps, opts.burn, opts.run_thin, opts.moves

    def lp_fn(q):
        return _evaluate(vec, q, args, n_parts, k_ens)

    rng = np.random.default_rng(np.random.SeedSequence(opts.seed))
    coords, lp = _starts(rng, lp_fn, log_prob, x0, args, cov0, k_ens, w, opts.init_scale)
    n_keep = (nsteps - burn + thin - 1) // thin
    if backend == "jax":
        run = _prepare_jax(log_prob, args, coords, lp, n_parts, k_ens, moves, burn, thin,
                           n_keep, int(rng.integers(2**31)))  # fmt: skip
    else:
        run = functools.partial(_run_numpy, rng, coords, lp, lp_fn, moves, nsteps, burn, thin,
                                n_keep)  # fmt: skip
    bar = _bar(opts.progress, nsteps, n_parts, k_ens)
    t0 = time.perf_counter()
    kept, kept_lp, n_acc, steps_run = run(bar)
    wall = time.perf_counter() - t0
    if bar is not None:
        bar.close()
    if callable(opts.progress):
        opts.progress("posterior diagnostics: autocorrelation times, ESS and R-hat per parameter")

    out, failed = [], []
    for p in range(n_parts):
        sl = slice(p * k_ens, (p + 1) * k_ens)
        post = _part_posterior(
            names, kept[:, sl].transpose(1, 0, 2, 3), kept_lp[:, sl].transpose(1, 0, 2),
            (n_acc[sl] / steps_run).reshape(-1), opts, wall_time=wall / n_parts,
            sampler=f"{LOCKSTEP} ({backend})",
        )  # fmt: skip
        out.append(post)
        if post.problems:
            failed.append((p, list(post.problems)))
    if failed and opts.on_fail != "ignore":
        msg = f"MCMC runs of {len(failed)} of {n_parts} parts have not converged:\n" + "\n".join(
            f"  part {p}: " + "; ".join(pr) for p, pr in failed
        )
        if opts.on_fail == "raise":
            raise ConvergenceError(msg, posterior=out)
        warnings.warn(msg, ConvergenceWarning, stacklevel=2)
    return out


def _checked_run(x0, names, args, options: SamplerOptions, backend):
    """`sample_posteriors`' checked settings: `x0` as a `(P, dim)` array, `names` as
    a tuple, and the options for its dimension (`SamplerOptions.for_dim`)."""
    x0 = np.asarray(x0, dtype=float)
    if x0.ndim != 2 or not np.all(np.isfinite(x0)):
        raise InputError(f"x0: expected a finite (parts, dim) array, got shape {x0.shape}")
    n_parts, ndim = x0.shape
    names = tuple(str(n) for n in names)
    if len(names) != ndim:
        raise InputError(f"names: got {len(names)} names for {ndim} parameters", value=names)
    for leaf in jax.tree_util.tree_leaves(args):
        if np.shape(leaf)[:1] != (n_parts,):
            raise InputError(
                f"args: every leaf needs a leading axis of {n_parts} parts, got shape "
                f"{np.shape(leaf)}"
            )
    opts = options.for_dim(ndim)
    if opts.nwalkers < 2 * ndim or opts.nwalkers % 2:
        raise InputError(f"nwalkers: got {opts.nwalkers}, expected an even number >= 2 * dim")
    if backend not in ("jax", "numpy"):
        raise InputError(f"backend: got {backend!r}, expected 'jax' or 'numpy'")
    return x0, names, opts


def _bar(progress, nsteps: int, n_parts: int, k_ens: int):
    """The tqdm progress bar of a run (`None` without `progress`): like emcee's, a
    line every 10 s when stderr is not a terminal (a log file, CI)."""
    if not progress:
        return None
    from tqdm.auto import tqdm

    desc = f"lockstep ensembles ({n_parts} parts x {k_ens})" if n_parts > 1 else (
        f"lockstep sampler ({k_ens} ensembles)"
    )  # fmt: skip
    return tqdm(total=nsteps, desc=desc, mininterval=0.1 if sys.stderr.isatty() else 10.0)


def _starts(rng, lp_fn, log_prob, x0, args, cov0, k_ens, w, init_scale):
    """Per part, `k_ens` independent balls of `w` walkers around its `x0`; walkers
    whose log posterior is not finite are redrawn. Returns the walkers
    `(P*K, w, d)` and their log posteriors."""
    n_parts, ndim = x0.shape
    n_e = n_parts * k_ens

    if cov0 is None:  # every part's Hessian in one call
        hs = np.asarray(neg_hessians(log_prob)(x0, args))  # NumPy in: no program to convert it
        roots = [sqrt_psd(cov_from_hessian(h)) * init_scale for h in hs]
    else:
        roots = [sqrt_psd(start_cov(log_prob, x0[p], None, cov0[p], ndim)) * init_scale
                 for p in range(n_parts)]  # fmt: skip

    def root_of(p):
        return roots[p]

    coords = np.empty((n_e, w, ndim))
    for p in range(n_parts):
        root = root_of(p)
        noise = rng.standard_normal((k_ens, w, ndim))
        coords[p * k_ens : (p + 1) * k_ens] = x0[p] + noise @ root.T
    lp = lp_fn(coords)
    for _ in range(100):
        bad = ~np.isfinite(lp)
        if not bad.any():
            break
        ens = np.nonzero(bad)[0] // k_ens
        # redraw around the part's x0 with its own ball
        for p in np.unique(ens):
            root = root_of(p)
            sel = bad & (np.arange(n_e)[:, None] // k_ens == p)
            coords[sel] = x0[p] + rng.standard_normal((int(sel.sum()), ndim)) @ root.T
        lp = np.where(bad, lp_fn(coords), lp)
    if not np.all(np.isfinite(lp)):
        parts_bad = sorted(set((np.nonzero(~np.isfinite(lp))[0] // k_ens).tolist()))
        raise AnalysisError(
            f"could not start walkers with a finite log_prob for part(s) {parts_bad} "
            "(after 100 redraws); check x0 and the prior supports, or lower init_scale"
        )
    return coords, lp


def _run_numpy(rng, coords, lp, lp_fn, moves, nsteps, burn, thin, n_keep, bar):
    """The NumPy backend: red-blue half-steps of all ensembles, one jitted log
    posterior call per half-step. Returns the kept walkers `(n_keep, E, W, d)`,
    their log posteriors, the accepted moves per walker and the steps run."""
    n_e, w, ndim = coords.shape
    h = w // 2
    kept = np.empty((n_keep, n_e, w, ndim))
    kept_lp = np.empty((n_keep, n_e, w))
    n_acc = np.zeros((n_e, w))
    slot = 0
    for step in range(nsteps):
        perm = np.argsort(rng.random((n_e, w)), axis=1)  # emcee's random split
        first, second = perm[:, :h], perm[:, h:]
        rows = np.arange(n_e)[:, None]
        acc = _half_step(rng, coords, lp, first, second, moves, ndim, lp_fn)
        n_acc[rows, first] += acc
        acc = _half_step(rng, coords, lp, second, first, moves, ndim, lp_fn)
        n_acc[rows, second] += acc
        if step >= burn and (step - burn) % thin == 0:
            kept[slot], kept_lp[slot] = coords, lp
            slot += 1
        if bar is not None and (step % 50 == 49 or step == nsteps - 1):
            bar.update(step + 1 - bar.n)
    return kept, kept_lp, n_acc, nsteps


def _part_posterior(names, kept, kept_lp, acceptance, opts: SamplerOptions, *, wall_time,
                    sampler) -> Posterior:  # fmt: skip
    """One part's [`Posterior`][] from its ensembles' kept draws `(K, S, W, d)` and
    log posteriors `(K, S, W)` (thinned further and diagnosed as
    `sample_posterior` does)."""
    nsteps = opts.nsteps
    kp, lp_p, thin_p, tau, tau_max, reliable, ess, rhat = diagnose(
        kept, kept_lp, opts.run_thin, opts.thin, opts.tau_factor
    )  # kp: (K, S, W, d)
    # a chain too short (or stuck) for an estimate: tau unknown, never trusted
    unknown = ~np.isfinite(tau_max)
    tau = np.where(np.isfinite(tau), tau, float(nsteps))
    tau_max = np.where(unknown, float(nsteps), tau_max)
    reliable = reliable & ~unknown
    ess = np.where(np.isfinite(ess), ess, 0.0)
    problems = _problems(names, (tau_max, reliable, ess, rhat), kp.shape[1], opts, thin=thin_p)
    return make_posterior(
        names, (kp, lp_p, acceptance), (tau, reliable, ess, rhat), problems, opts, thin=thin_p,
        wall_time=wall_time, sampler=sampler,
    )  # fmt: skip
