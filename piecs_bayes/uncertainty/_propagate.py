"""Propagation of uncertainty: linearised (GUM, JCGM 100) and Monte Carlo (JCGM 101).

- `propagate_linear(fn, x, cov)`: $y = f(x)$, $U_y = J U_x J^\\top$ with the
  Jacobian $J = \\partial f/\\partial x$ from JAX forward-mode autodiff (exact,
  no finite differences). Valid when $f$ is close to linear over a few
  standard uncertainties of $x$.
- `propagate_mc(fn, samples)`: push draws of $x$ (from the posterior, or from
  the input distributions) through $f$; JCGM 101's answer where linearisation
  fails (the mass-calibration example 9.3 is the classic case).
- `coverage_interval`: JCGM 101 7.7, probabilistically symmetric or shortest.
- `adaptive_monte_carlo`: JCGM 101 7.9, blocks of $M$ trials until the
  numerical tolerance of `ndig` significant digits of $u(y)$ is met.
- `uncertainty_budget`: share of the output variance from each declared source.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Literal

import jax
import numpy as np

from ..errors import AnalysisError, InputError


def _check_cov(x: np.ndarray, cov, what: str = "cov") -> np.ndarray:
    n = x.size
    c = np.asarray(cov, dtype=float)
    if c.ndim == 0 and n == 1:
        c = c.reshape(1, 1)
    elif c.ndim == 1:
        if c.shape != (n,):
            raise InputError(f"{what}: got shape {c.shape}, expected ({n},) or ({n}, {n})")
        c = np.diag(c)
    if c.shape != (n, n):
        raise InputError(f"{what}: got shape {c.shape}, expected ({n}, {n}) for x of size {n}")
    if not np.all(np.isfinite(c)):
        raise InputError(f"{what}: expected finite values, got {c}")
    d = np.diag(c)
    if np.any(d < 0.0):
        i = int(np.argmin(d))
        raise InputError(
            f"{what}: diagonal element {i} is {float(d[i])!r}, expected >= 0", value=float(d[i])
        )
    if not np.allclose(c, c.T, rtol=1e-10, atol=1e-300):
        raise InputError(f"{what}: expected a symmetric matrix")
    return c


def propagate_linear(fn, x, cov):
    """GUM (JCGM 100) law of propagation: $y = f(x)$, $U_y = J U_x J^\\top$.

    **Arguments:**

    - `fn`: JAX-traceable $f$ mapping a vector `x` (shape `(n,)`) to an array `y`.
    - `x`: estimate of the inputs, shape `(n,)` (a scalar is treated as `(1,)`).
    - `cov`: covariance $U_x$, shape `(n, n)`, or variances `(n,)`; checked for
      shape, finiteness, symmetry and a non-negative diagonal before anything
      is computed.

    **Returns:** `(y, ycov, jac)`: `y` as `fn` returns it (NumPy), `ycov` of shape
    `(m, m)` for `m = y.size` (flattened), and `jac` of shape `(m, n)`.
    """
    x = np.atleast_1d(np.asarray(x, dtype=float))
    if x.ndim != 1:
        raise InputError(f"x: got shape {x.shape}, expected a vector (n,)")
    c = _check_cov(x, cov)
    y, jac = map(np.asarray, _value_and_jacobian(fn)(x))
    jac = jac.reshape(y.size, x.size)
    ycov = jac @ c @ jac.T
    return y, 0.5 * (ycov + ycov.T), jac


# jitted vmapped versions of the functions seen, so repeated calls do not recompile
_VMAPPED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()
# jitted (value, Jacobian) of the functions seen (`propagate_linear`)
_LINEARISED: weakref.WeakKeyDictionary = weakref.WeakKeyDictionary()


def _value_and_jacobian(fn):
    """`x -> (fn(x), jacfwd(fn)(x))` jitted, once per function: one compiled program
    per input shape, not one per JAX operation that `fn` and its derivative dispatch
    eagerly (nor one per shape for moving `x` to the device)."""
    try:
        vj = _LINEARISED.get(fn)
    except TypeError:  # not weak-referenceable: no caching
        vj = None
    if vj is None:
        f = _weakly(fn)
        vj = jax.jit(lambda x: (f(x), jax.jacfwd(f)(x)))
        try:
            _LINEARISED[fn] = vj
        except TypeError:
            pass
    return vj


def _weakly(fn):
    """`fn`, called through a weak reference where it takes one: a cached program
    that held `fn` itself would keep its own key alive in the weak caches."""
    try:
        ref = weakref.ref(fn)
    except TypeError:
        return fn
    return lambda x: ref()(x)


def _vectorise(fn, vectorized: bool, batch_size: int):
    """A function of the whole `(M, n)` sample array (jitted and vmapped once)."""
    if vectorized:
        return lambda s: np.asarray(fn(s))
    try:
        vf = _VMAPPED.get(fn)
    except TypeError:  # not weak-referenceable: no caching
        vf = None
    if vf is None:
        vf = jax.jit(jax.vmap(_weakly(fn)))
        try:
            _VMAPPED[fn] = vf
        except TypeError:
            pass

    def apply(s):
        s = np.asarray(s)  # sliced in NumPy and passed as NumPy: no program per slice
        out = [np.asarray(vf(s[i : i + batch_size]))
               for i in range(0, s.shape[0], batch_size)]  # fmt: skip
        return np.concatenate(out, axis=0)

    return apply


def propagate_mc(fn, samples, *, vectorized: bool = False, batch_size: int = 100_000):
    """Monte Carlo propagation (JCGM 101): push input draws through `fn`.

    **Arguments:**

    - `fn`: $f$ of one input vector (JAX-traceable; jitted and vmapped here), or,
      with `vectorized=True`, any function of the whole `(M, n)` array.
    - `samples`: input draws, shape `(M, n)` (or `(M,)` for one input).
    - `batch_size`: rows per vmapped call, bounding memory.

    **Returns:** `(ymean, ycov, ysamples)`: the mean of the output draws, their
    covariance `(m, m)` over the flattened output (`ddof=1`), and the draws,
    shape `(M, *y.shape)`. Coverage intervals: `coverage_interval(ysamples)`.
    """
    s = np.asarray(samples, dtype=float)
    if s.ndim == 1:
        s = s[:, None]
    if s.ndim != 2 or s.shape[0] < 2:
        raise InputError(f"samples: got shape {s.shape}, expected (M >= 2, n)")
    ys = _vectorise(fn, vectorized, batch_size)(s)
    flat = ys.reshape(ys.shape[0], -1)
    return ys.mean(axis=0), np.atleast_2d(np.cov(flat, rowvar=False)), ys


def coverage_interval(
    samples, p: float = 0.95, kind: Literal["symmetric", "shortest"] = "symmetric"
):
    """Coverage interval from Monte Carlo draws, JCGM 101 7.7.

    With the $M$ draws sorted, $q = pM$ rounded (integer part of $pM + 1/2$),
    the interval is $[y_{(r)}, y_{(r+q)}]$ (1-based): the probabilistically
    symmetric one has $r = (M-q)/2$, rounded up when not an integer (the
    integer part of $(M-q+1)/2$); the shortest has the $r$ minimising
    $y_{(r+q)} - y_{(r)}$.

    **Arguments:**

    - `samples`: draws, shape `(M,)` or `(M, ...)` (intervals per column).
    - `p`: coverage probability.
    - `kind`: `"symmetric"` or `"shortest"`.

    **Returns:** `(low, high)`, scalars or arrays of the trailing shape.
    """
    if not 0.0 < p < 1.0:
        raise InputError(f"p: got {p!r}, expected 0 < p < 1", value=p)
    if kind not in ("symmetric", "shortest"):
        raise InputError(f"kind: got {kind!r}, expected 'symmetric' or 'shortest'", value=kind)
    y = np.sort(np.asarray(samples, dtype=float), axis=0)
    m = y.shape[0]
    q = int(p * m) if float(p * m).is_integer() else int(math.floor(p * m + 0.5))
    if q >= m:
        raise InputError(f"{m} draws are too few for a {p:g} coverage interval")
    if kind == "symmetric":
        r = (m - q) // 2 if (m - q) % 2 == 0 else (m - q + 1) // 2
        return y[r - 1], y[r - 1 + q]
    widths = y[q:] - y[: m - q]  # r = 1 .. M - q
    r = np.argmin(widths, axis=0)
    lo = np.take_along_axis(y, r[None, ...], axis=0)[0]
    hi = np.take_along_axis(y, (r + q)[None, ...], axis=0)[0]
    return (lo[()], hi[()])


@dataclass(frozen=True)
class AdaptiveMCResult:
    """Result of `adaptive_monte_carlo` (JCGM 101 7.9).

    `y`, `u`, `low`, `high`: estimate, standard uncertainty and coverage
    interval from all `n_trials = n_blocks * block_size` trials; `tolerance`:
    the numerical tolerance $\\delta$ met (per output); `samples`: the output draws.
    """

    y: np.ndarray
    u: np.ndarray
    low: np.ndarray
    high: np.ndarray
    tolerance: np.ndarray
    n_blocks: int
    block_size: int
    p: float
    kind: str
    samples: np.ndarray

    @property
    def n_trials(self) -> int:
        return self.n_blocks * self.block_size

    def __repr__(self) -> str:
        def fmt(a):
            a = np.atleast_1d(a)
            return "[" + ", ".join(f"{v:.6g}" for v in a) + "]" if a.size > 1 else f"{a[0]:.6g}"

        return (
            f"AdaptiveMCResult(y={fmt(self.y)}, u={fmt(self.u)}, {self.p:g} {self.kind} "
            f"interval [{fmt(self.low)}, {fmt(self.high)}], tolerance {fmt(self.tolerance)}, "
            f"M={self.n_trials} in {self.n_blocks} blocks)"
        )


def _tolerance(u: np.ndarray, ndig: int) -> np.ndarray:
    """JCGM 101 7.9.2: write u = c x 10^l with c an ndig-digit integer; delta = 10^l / 2."""
    u = np.abs(np.asarray(u, dtype=float))
    with np.errstate(divide="ignore"):
        ell = np.floor(np.log10(np.where(u > 0, u, np.nan))) - (ndig - 1)
    # rounding may add a digit (e.g. 0.0996 -> 0.10 with ndig=2): JCGM uses the rounded c
    c = np.round(u / 10.0**ell)
    ell = np.where(c >= 10**ndig, ell + 1, ell)
    return 0.5 * 10.0**ell


def adaptive_monte_carlo(
    fn,
    draw,
    *,
    ndig: int = 2,
    p: float = 0.95,
    kind: Literal["symmetric", "shortest"] = "symmetric",
    block_size: int | None = None,
    max_trials: int = 10_000_000,
    seed: int = 0,
    vectorized: bool = False,
):
    """Adaptive Monte Carlo procedure of JCGM 101 7.9.4.

    Blocks of $M$ trials are run; after each block $h \\ge 2$ the standard
    deviations of the block means of $y$, $u(y)$, $y_\\text{low}$ and
    $y_\\text{high}$ are $s = \\sqrt{\\sum_r (z_r - \\bar z)^2 / (h(h-1))}$; the
    procedure stops when all of $2s$ are at most the tolerance $\\delta$ of
    `ndig` significant digits of $u(y)$ (from all $hM$ trials).

    **Arguments:**

    - `fn`: measurement function of one input vector (JAX; or any function of
      the `(M, n)` array with `vectorized=True`); scalar or vector output (the
      tolerance must hold for every component).
    - `draw`: `draw(rng, M) -> (M, n)` draws of the inputs from a
      `numpy.random.Generator`.
    - `ndig`: significant decimal digits wanted in $u(y)$.
    - `p`, `kind`: coverage probability and interval kind.
    - `block_size`: $M$; default $\\max(\\lceil 100/(1-p) \\rceil, 10^4)$.
    - `max_trials`: stop with `AnalysisError` if the tolerance is not met by then.
    - `seed`: seed of the generator.

    **Returns:** an `AdaptiveMCResult`.
    """
    if ndig < 1:
        raise InputError(f"ndig: got {ndig!r}, expected >= 1", value=ndig)
    m = block_size or max(int(math.ceil(100.0 / (1.0 - p))), 10_000)
    rng = np.random.default_rng(seed)
    apply = _vectorise(fn, vectorized, 100_000)
    blocks, stats_ = [], []
    n_all, shift, s1, s2 = 0, None, 0.0, 0.0  # running moments of all trials
    while True:
        xs = np.asarray(draw(rng, m), dtype=float)
        ys = apply(xs[:, None] if xs.ndim == 1 else xs)
        out_shape = ys.shape[1:]
        ys = ys.reshape(m, -1)
        lo, hi = coverage_interval(ys, p, kind)
        blocks.append(ys)
        stats_.append(np.stack([ys.mean(0), ys.std(0, ddof=1), lo, hi]))
        shift = ys.mean(0) if shift is None else shift
        n_all, s1, s2 = n_all + m, s1 + (ys - shift).sum(0), s2 + ((ys - shift) ** 2).sum(0)
        h = len(blocks)
        if h < 2:
            continue
        z = np.stack(stats_)  # (h, 4, m_out)
        s = z.std(axis=0, ddof=1) / math.sqrt(h)
        u = np.sqrt((s2 - s1 * s1 / n_all) / (n_all - 1))
        delta = _tolerance(u, ndig)
        if np.all(2.0 * s <= delta[None, :]):
            break
        if (h + 1) * m > max_trials:
            raise AnalysisError(
                f"adaptive Monte Carlo: tolerance {delta} for {ndig} digits not met after "
                f"{h * m} trials (2 s = {2.0 * s.max(axis=0)}); raise max_trials or lower ndig"
            )
    allys = np.concatenate(blocks)
    u = allys.std(axis=0, ddof=1)
    lo, hi = coverage_interval(allys, p, kind)

    def shaped(a):
        return np.asarray(a).reshape(out_shape)

    return AdaptiveMCResult(
        y=shaped(allys.mean(axis=0)), u=shaped(u), low=shaped(lo), high=shaped(hi),
        tolerance=shaped(delta), n_blocks=h, block_size=m, p=p, kind=kind,
        samples=allys.reshape(-1, *out_shape),
    )  # fmt: skip


def _source_cov(name, spec, n, cov):
    """One source's covariance contribution to U_x, as an (n, n) matrix."""
    if isinstance(spec, tuple):
        if len(spec) != 2:
            raise InputError(f"source {name!r}: expected (indices, block), got {spec!r}")
        idx = np.atleast_1d(np.asarray(spec[0]))
        block = np.asarray(spec[1], dtype=float)
        k = idx.size
        if block.ndim == 0 and k == 1:
            block = block.reshape(1, 1)
        elif block.ndim == 1:
            block = np.diag(block)
        if block.shape != (k, k):
            raise InputError(f"source {name!r}: block shape {block.shape}, expected ({k}, {k})")
    else:
        a = np.asarray(spec)
        if a.ndim == 2:
            if a.shape != (n, n):
                raise InputError(
                    f"source {name!r}: covariance shape {a.shape}, expected ({n}, {n})"
                )
            return _check_cov(np.zeros(n), a, f"source {name!r}"), None
        idx = np.atleast_1d(a)
        if cov is None:
            raise InputError(f"source {name!r}: indices given but no cov= to take the block from")
        block = cov[np.ix_(idx, idx)]
    if not np.issubdtype(idx.dtype, np.integer) or np.any((idx < 0) | (idx >= n)):
        raise InputError(f"source {name!r}: indices {idx.tolist()} must be integers in [0, {n})")
    if len(set(idx.tolist())) != idx.size:
        raise InputError(f"source {name!r}: repeated indices {idx.tolist()}")
    full = np.zeros((n, n))
    full[np.ix_(idx, idx)] = _check_cov(np.zeros(idx.size), block, f"source {name!r}")
    return full, idx


def uncertainty_budget(jac, sources: dict, *, cov=None, relative: bool = False):
    """Share of each output's variance that comes from each uncertainty source.

    The input covariance is the sum of the sources' contributions,
    $U_x = \\sum_s U_s$, which is what independent sources give; then
    $\\operatorname{diag}(J U_x J^\\top) = \\sum_s \\operatorname{diag}(J U_s J^\\top)$
    exactly, so the shares add up to the total variance with no cross terms.
    Correlations *within* a source (e.g. one scale error moving every probe
    point) are kept in its block; correlated inputs must belong to one source.
    Correlation *between* sources cannot be split uniquely: with `cov` given,
    a non-zero `cov[i, j]` linking two sources' indices raises `InputError`
    (merge them into one source). Inputs not in any source contribute nothing.

    **Arguments:**

    - `jac`: Jacobian $J$, shape `(m, n)` (from `propagate_linear`).
    - `sources`: `{name: spec}` with `spec` either `(indices, block)` (a tuple;
      `block` the `(k, k)` covariance, `(k,)` variances or a scalar for one
      index), a list/array of input indices whose block is taken from `cov`, or
      an `(n, n)` covariance contribution (for a source acting on many inputs).
    - `cov`: full input covariance, needed for index-only specs; used to check
      that sources are uncorrelated.
    - `relative`: return fractions of the total variance (summing to 1)
      instead of variances.

    **Returns:** `{name: array (m,)}` of variance contributions $u_s^2(y_i)$ (or
    fractions), plus `"total"`: their sum, $u^2(y_i)$.
    """
    j = np.atleast_2d(np.asarray(jac, dtype=float))
    n = j.shape[1]
    c = None if cov is None else _check_cov(np.zeros(n), cov)
    out, owner = {}, {}
    for name, spec in sources.items():
        if name == "total":
            raise InputError("source name 'total' is reserved")
        us, idx = _source_cov(name, spec, n, c)
        if idx is not None:
            for i in idx.tolist():
                if i in owner:
                    raise InputError(
                        f"input {i} belongs to sources {owner[i]!r} and {name!r}; "
                        "each input belongs to one source"
                    )
                owner[i] = name
        out[name] = np.einsum("ij,jk,ik->i", j, us, j)
    if c is not None and owner:
        idx = np.array(sorted(owner))
        lab = np.array([owner[i] for i in idx], dtype=object)
        sub = c[np.ix_(idx, idx)]
        d = np.sqrt(np.diag(sub))
        bad = (lab[:, None] != lab[None, :]) & (np.abs(sub) > 1e-12 * np.outer(d, d))
        if bad.any():
            a, b = (int(v) for v in np.argwhere(bad)[0])
            raise InputError(
                f"sources {lab[a]!r} and {lab[b]!r} are correlated "
                f"(cov[{idx[a]}, {idx[b]}] = {sub[a, b]:.3g}); merge them into one source",
                value=sub[a, b],
            )
    total = sum(out.values()) if out else np.zeros(j.shape[0])
    if relative:
        with np.errstate(invalid="ignore", divide="ignore"):
            out = {k: np.where(total > 0, v / total, 0.0) for k, v in out.items()}
    out["total"] = total
    return out
