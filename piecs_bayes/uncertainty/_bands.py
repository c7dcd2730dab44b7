r"""Pointwise and simultaneous confidence bands along a curve.

For a curve $g(z)$ estimated at grid points with standard uncertainties $u(z_i)$, a band
is $\hat g(z_i) \pm c_i\, u(z_i)$, returned as [`Bands`][]: **pointwise** ($c_i$ the
$p$ quantile of the standardised error at each point alone: it covers each point with
probability $p$, the whole curve much less often) and **simultaneous** (max-t: one $c$,
the $p$ quantile of the largest standardised error, so the band holds the whole curve
with probability $p$). [`bands_from_samples`][] takes Monte Carlo draws of the curve
values (JCGM 101; empirical quantiles); [`bands_linear`][] a linearised mean and
covariance (GUM), simulating the max-$|z|$ quantile (`method="mc"` or `"qmc"`, Student-t
with `dof`, a Type A share with `cov_estimated`) or bounding it by Scheffé's
(`"scheffe"`, conservative). For a tool path the curve values are the signed offsets
normal to the path at the grid points; these functions only see numbers along a curve.

The two bands and the two routes: docs/uncertainty.md, section 7.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

from .. import _config
from ..errors import InputError

stats = _config.LazyModule("scipy.stats")  # on first use: a fast start
qmc = _config.LazyModule("scipy.stats.qmc")


def _frozen(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, repr=False, eq=False)
class Bands:
    """Pointwise and simultaneous bands of probability `p` along a curve.

    `center` and `sd` are the estimate and standard uncertainty at each point;
    the bands are `center -/+ crit_pointwise * sd` (`crit_pointwise` has one
    value per point) and `center -/+ crit_simultaneous * sd`.
    `crit_simultaneous_se` is the Monte Carlo standard error of the simulated
    critical value (0 when it is not simulated); `method` says how it was made.
    """

    center: np.ndarray
    sd: np.ndarray
    pointwise_lower: np.ndarray
    pointwise_upper: np.ndarray
    simultaneous_lower: np.ndarray
    simultaneous_upper: np.ndarray
    crit_pointwise: np.ndarray
    crit_simultaneous: float
    crit_simultaneous_se: float
    p: float
    method: str
    n_draws: int

    def contains(self, curve, kind: Literal["pointwise", "simultaneous"] = "simultaneous"):
        """Boolean per point: is `curve` inside the band?"""
        c = np.asarray(curve, dtype=float)
        if kind == "pointwise":
            return (c >= self.pointwise_lower) & (c <= self.pointwise_upper)
        if kind == "simultaneous":
            return (c >= self.simultaneous_lower) & (c <= self.simultaneous_upper)
        raise InputError(f"kind: got {kind!r}, expected 'pointwise' or 'simultaneous'")

    def covers(self, curve, kind: Literal["pointwise", "simultaneous"] = "simultaneous") -> bool:
        """Does the band hold the whole `curve`?"""
        return bool(np.all(self.contains(curve, kind)))

    def __repr__(self) -> str:
        cp = self.crit_pointwise
        pw = f"{cp[0]:.3f}" if np.ptp(cp) == 0 else f"{cp.min():.3f}..{cp.max():.3f}"
        return (
            f"Bands(p={self.p:g}, {self.center.size} points, method={self.method!r}, "
            f"critical values: pointwise {pw}, simultaneous {self.crit_simultaneous:.3f}"
            f" (se {self.crit_simultaneous_se:.3f}), n_draws={self.n_draws})"
        )


def _quantile_with_se(x: np.ndarray, p: float) -> tuple[float, float]:
    """p quantile of draws `x` and its standard error from order-statistic ranks."""
    m = x.size
    xs = np.sort(x)
    q = float(np.quantile(xs, p))
    half = 1.959964 * math.sqrt(m * p * (1.0 - p))
    lo = xs[max(int(math.floor(m * p - half)), 0)]
    hi = xs[min(int(math.ceil(m * p + half)), m - 1)]
    return q, float(hi - lo) / (2.0 * 1.959964)


def _make(center, sd, cp, cs, se, p, method, n):
    return Bands(
        center=_frozen(center), sd=_frozen(sd),
        pointwise_lower=_frozen(center - cp * sd), pointwise_upper=_frozen(center + cp * sd),
        simultaneous_lower=_frozen(center - cs * sd), simultaneous_upper=_frozen(center + cs * sd),
        crit_pointwise=_frozen(np.broadcast_to(cp, center.shape)), crit_simultaneous=float(cs),
        crit_simultaneous_se=float(se), p=float(p), method=method, n_draws=int(n),
    )  # fmt: skip


def _check_p(p):
    if not 0.0 < p < 1.0:
        raise InputError(f"p: got {p!r}, expected 0 < p < 1", value=p)


def bands_from_samples(samples, *, center=None, p: float = 0.95) -> Bands:
    """Bands from Monte Carlo draws of the curve values.

    **Arguments:**

    - `samples`: draws of the curve at the grid points, shape `(M, n)`.
    - `center`: the curve estimate, shape `(n,)`; default the mean of the draws
      (pass the point estimate to centre the band on it).
    - `p`: coverage probability.

    **Returns:** `Bands` with `sd` the draws' standard deviation per point,
    `crit_pointwise[i]` the `p` quantile of $|g_s(z_i) - \\hat g(z_i)|/u(z_i)$ and
    `crit_simultaneous` that of $\\max_i$ of it. Points with zero spread are
    held exactly and do not enter the maximum.
    """
    _check_p(p)
    s = np.asarray(samples, dtype=float)
    if s.ndim != 2 or s.shape[0] < 20:
        raise InputError(f"samples: got shape {s.shape}, expected (M >= 20, n)")
    c = s.mean(axis=0) if center is None else np.asarray(center, dtype=float)
    if c.shape != s.shape[1:]:
        raise InputError(f"center: got shape {c.shape}, expected {s.shape[1:]}")
    sd = s.std(axis=0, ddof=1)
    safe = np.where(sd > 0.0, sd, 1.0)
    t = np.where(sd > 0.0, np.abs(s - c) / safe, 0.0)
    cp = np.quantile(t, p, axis=0)
    cs, se = _quantile_with_se(t.max(axis=1), p)
    return _make(c, sd, cp, cs, se, p, "samples", s.shape[0])


def _factor(cov: np.ndarray, sd: np.ndarray) -> np.ndarray:
    """Rank-r factor L of the correlation matrix: R = L L^T, L of shape (n, r)."""
    safe = np.where(sd > 0.0, sd, 1.0)
    r = cov / np.outer(safe, safe)
    w, v = np.linalg.eigh(0.5 * (r + r.T))
    keep = w > 1e-10 * max(w.max(), 0.0)
    return v[:, keep] * np.sqrt(w[keep])


@functools.lru_cache(maxsize=16)
def _base_draws(method: str, r: int, n_sim: int, seed: int, dof: float | None):
    """Standard-normal draws (n, r) and, with `dof`, sqrt(chi2_dof / dof) per draw.

    They depend only on these arguments, so repeated bands (one per part, per
    simulated fit) reuse them; the arrays are read-only."""
    if method == "qmc":
        k = max(int(math.ceil(math.log2(n_sim))), 4)
        u = qmc.Sobol(d=r + (dof is not None), scramble=True, seed=seed).random_base2(k)
        u = np.clip(u, 1e-16, 1.0 - 1e-16)
        xi = stats.norm.ppf(u[:, :r])
        scale = None if dof is None else np.sqrt(stats.chi2.ppf(u[:, r], dof) / dof)
    else:
        rng = np.random.default_rng(seed)
        xi = rng.standard_normal((n_sim, r))
        scale = None if dof is None else np.sqrt(rng.chisquare(dof, n_sim) / dof)
    xi.flags.writeable = False
    if scale is not None:
        scale.flags.writeable = False
    return xi, scale


def bands_linear(
    mean,
    cov=None,
    *,
    factor=None,
    p: float = 0.95,
    dof: float | None = None,
    cov_estimated=None,
    method: Literal["mc", "qmc", "scheffe"] = "qmc",
    n_sim: int = 100_000,
    seed: int = 0,
) -> Bands:
    """Bands from a linearised mean and covariance of the curve values.

    **Arguments:**

    - `mean`: curve estimate at the grid points, shape `(n,)`.
    - `cov`: its covariance, shape `(n, n)` (typically $G U_\\theta G^\\top$, of
      low rank $r$ = number of parameters); or, instead,
    - `factor`: $L$ with $U = L L^\\top$, shape `(n, r)`, e.g. $G\\,\\mathrm{chol}(U_\\theta)$:
      skips the eigen-decomposition of $U$ (faster when $r \\ll n$).
    - `p`: coverage probability.
    - `dof`: degrees of freedom when the scale was estimated (Student-t
      pointwise, multivariate-t simultaneous); `None` for a known scale.
    - `cov_estimated`: with `cov` and `dof`, the part of `cov` whose scale was
      estimated with `dof` (Type A, e.g. the probe repeatability's share); the
      rest is known (Type B). The simulated error is then
      $L_A\\xi_A\\sqrt{\\nu/\\chi^2_\\nu} + L_B\\xi_B$ and the pointwise
      factors are $t_p(\\nu_i)$ with Welch-Satterthwaite's $\\nu_i$ per point;
      without it the whole covariance is treated as estimated (conservative).
    - `method`: `"qmc"` (scrambled Sobol, default), `"mc"` (pseudo-random) or
      `"scheffe"` (the conservative $\\sqrt{\\chi^2_{r,p}}$ bound).
    - `n_sim`, `seed`: simulated draws (rounded up to a power of two for `"qmc"`).

    **Returns:** `Bands`.
    """
    _check_p(p)
    if method not in ("mc", "qmc", "scheffe"):
        raise InputError(f"method: got {method!r}, expected 'qmc', 'mc' or 'scheffe'")
    m = np.asarray(mean, dtype=float)
    if (cov is None) == (factor is None):
        raise InputError("bands_linear: give exactly one of cov= and factor=")
    if factor is not None:
        lfull = np.asarray(factor, dtype=float)
        if lfull.ndim == 1:
            lfull = lfull[:, None]
        if m.ndim != 1 or lfull.ndim != 2 or lfull.shape[0] != m.size:
            raise InputError(
                f"mean/factor: got shapes {m.shape}, {lfull.shape}, expected (n,), (n, r)"
            )
        if not np.all(np.isfinite(lfull)):
            raise InputError("factor: expected finite values")
        c = None
        d = np.sum(lfull**2, axis=1)
    else:
        c = np.asarray(cov, dtype=float)
        if m.ndim != 1 or c.shape != (m.size, m.size):
            raise InputError(f"mean/cov: got shapes {m.shape}, {c.shape}, expected (n,), (n, n)")
        d = np.diag(c)
        if not np.all(np.isfinite(c)) or np.any(d < 0.0):
            raise InputError("cov: expected finite values and a non-negative diagonal")
    if dof is not None and not dof > 0:
        raise InputError(f"dof: got {dof!r}, expected > 0", value=dof)
    sd = np.sqrt(d)
    if cov_estimated is not None:
        if c is None or dof is None:
            raise InputError("bands_linear: cov_estimated needs cov= and dof=")
        return _bands_mixed(m, c, np.asarray(cov_estimated, float), sd, p, float(dof),
                            method, int(n_sim), int(seed))  # fmt: skip
    cp = stats.norm.ppf(0.5 + p / 2) if dof is None else stats.t.ppf(0.5 + p / 2, dof)
    if c is None:
        lf = lfull / np.where(sd > 0.0, sd, 1.0)[:, None]
        lf = lf[:, np.any(lf != 0.0, axis=0)]
        r = int(np.linalg.matrix_rank(lf)) if method == "scheffe" else lf.shape[1]
    else:
        lf = _factor(c, sd)
        r = lf.shape[1]
    if r == 0:
        return _make(m, sd, cp, 0.0, 0.0, p, f"linear-{method}", 0)
    if method == "scheffe":
        cs = math.sqrt(stats.chi2.ppf(p, r) if dof is None else r * stats.f.ppf(p, r, dof))
        return _make(m, sd, cp, cs, 0.0, p, "linear-scheffe", 0)
    if n_sim < 100:
        raise InputError(f"n_sim: got {n_sim!r}, expected >= 100", value=n_sim)
    k = lf.shape[1]
    # dof to two significant digits: bands of many parts (each with its own estimated
    # sigma) share the cached draws; a 5 % change of dof moves the quantile by < 0.1 %
    xi, scale = _base_draws(method, k, int(n_sim), int(seed), _dof_key(dof))
    mx = np.empty(xi.shape[0])
    for i in range(0, xi.shape[0], 8192):  # bound memory: (chunk, n)
        mx[i : i + 8192] = _abs_max(xi[i : i + 8192] @ lf.T)
    if scale is not None:
        mx = mx / scale
    cs, se = _quantile_with_se(mx, p)
    return _make(m, sd, cp, cs, se, p, f"linear-{method}", xi.shape[0])


def _abs_max(z: np.ndarray) -> np.ndarray:
    """`np.abs(z).max(axis=1)` without the temporary of `abs`."""
    return np.maximum(z.max(axis=1), -z.min(axis=1))


def _dof_key(dof) -> float | None:
    return None if dof is None else float(f"{float(dof):.2g}")


def _cov_factor(c: np.ndarray, scale: float) -> np.ndarray:
    """Rank-r factor of a covariance: C = L L^T, L of shape (n, r); eigenvalues below
    1e-12 `scale` (the largest of the whole covariance) are rounding, not a share."""
    w, v = np.linalg.eigh(0.5 * (c + c.T))
    keep = w > 1e-12 * scale
    return v[:, keep] * np.sqrt(w[keep])


def _bands_mixed(m, c, ca, sd, p, dof, method, n_sim, seed) -> Bands:
    """`bands_linear` for a covariance with an estimated (Type A, `dof`) part `ca`."""
    if ca.shape != c.shape or not np.all(np.isfinite(ca)):
        raise InputError(f"cov_estimated: got shape {ca.shape}, expected {c.shape}, finite")
    safe = np.where(sd > 0.0, sd, 1.0)[:, None]
    top = max(float(np.linalg.eigvalsh(0.5 * (c + c.T)).max()), 0.0)
    la = _cov_factor(ca, top) / safe
    lb = _cov_factor(c - ca, top) / safe
    da = np.clip(np.diag(ca), 0.0, None)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = np.where(da > 0, dof * (np.diag(c) / np.where(da > 0, da, 1.0)) ** 2, np.inf)
    q = 0.5 + p / 2
    cp = np.where(np.isfinite(nu), stats.t.ppf(q, np.where(np.isfinite(nu), nu, 1.0)), 0.0)
    cp = np.where(np.isfinite(nu), cp, stats.norm.ppf(q))
    ka, kb = la.shape[1], lb.shape[1]
    if ka + kb == 0:
        return _make(m, sd, cp, 0.0, 0.0, p, f"linear-{method}", 0)
    if method == "scheffe":
        r = int(np.linalg.matrix_rank(np.hstack([la, lb])))
        cs = math.sqrt(r * stats.f.ppf(p, r, dof))
        return _make(m, sd, cp, cs, 0.0, p, "linear-scheffe", 0)
    if n_sim < 100:
        raise InputError(f"n_sim: got {n_sim!r}, expected >= 100", value=n_sim)
    xi, scale = _base_draws(method, ka + kb, n_sim, seed, _dof_key(dof))
    mx = np.empty(xi.shape[0])
    lab = np.hstack([la, lb]).T
    for i in range(0, xi.shape[0], 8192):
        x = xi[i : i + 8192]
        # the Type A draws scaled before the product: one (chunk, k) x (k, n) product
        xs = np.concatenate([x[:, :ka] / scale[i : i + 8192, None], x[:, ka:]], axis=1)
        mx[i : i + 8192] = _abs_max(xs @ lab)
    cs, se = _quantile_with_se(mx, p)
    return _make(m, sd, cp, cs, se, p, f"linear-{method}", xi.shape[0])
