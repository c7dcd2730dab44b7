r"""Robust losses for least squares, in SciPy's convention.

A loss is a function $\rho(z)$ of the squared scaled residual $z = (e/s)^2$, with
$\rho(z) \approx z$ near zero, so that the objective is
$\tfrac12 \sum_i s^2 \rho\big((e_i/s)^2\big)$, exactly as
`scipy.optimize.least_squares(loss=..., f_scale=s)`; $e_i = \sqrt{w_i}\,r_i$ is the
weighted residual and $s$ the *scale*. Named losses (`LOSS_NAMES`): `"linear"`,
`"huber"`, `"soft_l1"`, `"cauchy"`, `"tukey"`, or a callable `rho(z)` with
$\rho(0)=0$, $\rho'(0)=1$. `TUNING` holds each loss's tuning constant (about 95 %
efficiency at the normal), [`mad_sigma`][] the robust standard deviation
$1.4826\,\mathrm{MAD}$ that, times the constant, is the default scale, and
[`normal_variance_factor`][] the loss's variance factor at the normal,
[`fixed_weight_factor`][] what the fixed-weight sandwich misses of it.

Which loss when: docs/models/least_squares.md, "Losses".
"""

from __future__ import annotations

import functools
from collections.abc import Callable

import jax
import jax.numpy as jnp

LOSS_NAMES = ("linear", "huber", "soft_l1", "cauchy", "tukey")
TUNING = {"linear": 1.0, "huber": 1.345, "soft_l1": 1.345, "cauchy": 2.385, "tukey": 4.685}
CUSTOM = len(LOSS_NAMES)  # index of a user-supplied loss
MAD_FACTOR = 1.4826


def loss_id(loss: str | Callable) -> int:
    """Index of a loss in the internal switch (a callable gets the last slot).

    Raises `ValueError` for an unknown name.
    """
    if callable(loss):
        return CUSTOM
    if isinstance(loss, str) and loss in LOSS_NAMES:
        return LOSS_NAMES.index(loss)
    raise ValueError(f"unknown loss {loss!r}; expected one of {LOSS_NAMES} or a callable rho(z)")


# Each ratio rho(z)/z is written so that it and its derivatives stay finite at
# z = 0 (the wrapped residual is e * sqrt(rho(z)/z)).


def _linear_ratio(z):
    return jnp.ones_like(z)


def _huber_ratio(z):
    zs = jnp.where(z <= 1.0, 1.0, z)
    return jnp.where(z <= 1.0, 1.0, (2.0 * jnp.sqrt(zs) - 1.0) / zs)


def _soft_l1_ratio(z):
    return 2.0 / (jnp.sqrt(1.0 + z) + 1.0)


def _cauchy_ratio(z):
    small = z < 1e-6
    zs = jnp.where(small, 1.0, z)
    return jnp.where(small, 1.0 - 0.5 * z + z * z / 3.0, jnp.log1p(zs) / zs)


def _tukey_ratio(z):
    inside = z <= 1.0
    zs = jnp.where(inside, 1.0, z)
    return jnp.where(inside, 1.0 - z + z * z / 3.0, 1.0 / (3.0 * zs))


def _linear_weight(z):
    return jnp.ones_like(z)


def _huber_weight(z):
    zs = jnp.where(z <= 1.0, 1.0, z)
    return jnp.where(z <= 1.0, 1.0, 1.0 / jnp.sqrt(zs))


def _soft_l1_weight(z):
    return 1.0 / jnp.sqrt(1.0 + z)


def _cauchy_weight(z):
    return 1.0 / (1.0 + z)


def _tukey_weight(z):
    return jnp.where(z <= 1.0, (1.0 - jnp.minimum(z, 1.0)) ** 2, 0.0)


_RATIOS = (_linear_ratio, _huber_ratio, _soft_l1_ratio, _cauchy_ratio, _tukey_ratio)
_WEIGHTS = (_linear_weight, _huber_weight, _soft_l1_weight, _cauchy_weight, _tukey_weight)


def _custom_ratio(rho: Callable) -> Callable:
    def ratio(z):
        small = z < 1e-12
        zs = jnp.where(small, 1.0, z)
        return jnp.where(small, 1.0, rho(zs) / zs)

    return ratio


def _custom_weight(rho: Callable) -> Callable:
    drho = jax.grad(lambda z: jnp.asarray(rho(z), dtype=float))

    def weight(z):
        return jnp.vectorize(drho)(z)

    return weight


def _select(idx, branches, z):
    """`branches[idx](z)` for a traced `idx`: every branch is evaluated (they are
    cheap and elementwise) and one is picked. Unlike `lax.switch` this adds no control
    flow, which keeps the solver's compile time down (XLA fuses it)."""
    if isinstance(idx, int):
        return branches[idx](z)
    z = jnp.asarray(z)
    out = branches[0](z)
    for k, branch in enumerate(branches[1:], start=1):
        out = jnp.where(idx == k, branch(z), out)
    return out


def rho_over_z(idx, z, custom: Callable | None = None):
    r"""$\rho(z)/z$ for loss number `idx` (a traced integer), elementwise; 1 at $z=0$."""
    branches = list(_RATIOS) + ([_custom_ratio(custom)] if custom is not None else [])
    return _select(idx, branches, z)


def rho_prime(idx, z, custom: Callable | None = None):
    r"""$\rho'(z)$, the IRLS weight of each residual, for loss number `idx`."""
    branches = list(_WEIGHTS) + ([_custom_weight(custom)] if custom is not None else [])
    return _select(idx, branches, z)


def psi_prime(idx, u, custom: Callable | None = None):
    r"""$\psi'(u)$ for $\psi(u) = u\,\rho'(u^2)$, elementwise (the slope of the
    influence function, used in Huber's covariance)."""

    def psi(v):
        return v * rho_prime(idx, v * v, custom)

    return jnp.vectorize(jax.grad(psi))(u)


def mad_sigma(e, mask, fallback: bool = True):
    r"""Robust standard deviation $1.4826\,\mathrm{median}|e - \mathrm{median}(e)|$ of
    the residuals `e` where `mask` is true. Falls back to the RMS when the MAD is zero
    (an exact or nearly exact fit), then, with `fallback` (a scale for fitting must be
    positive), to 1; without it an exact fit gives 0."""
    a = jnp.where(mask, e, jnp.nan)
    med = jnp.nanmedian(a)
    s = MAD_FACTOR * jnp.nanmedian(jnp.abs(a - med))
    n = jnp.maximum(jnp.sum(mask), 1)
    rms = jnp.sqrt(jnp.sum(jnp.where(mask, e * e, 0.0)) / n)
    good = jnp.isfinite(s) & (s > 0)
    s = jnp.where(good, s, jnp.where(rms > 0, rms, 1.0 if fallback else 0.0))
    return s


@functools.lru_cache(maxsize=16)
def normal_variance_factor(loss: str) -> float:
    r"""$\kappa = E[\psi^2]/E[\psi']^2$ at the standard normal, for the named loss at its
    tuning constant $c$ (scale $c\sigma$): the variance of the M-estimator is
    $\kappa\,\sigma^2 (J^TJ)^{-1}$ against least squares' $\sigma^2 (J^TJ)^{-1}$
    (Huber 1981, sec. 6.2). 1 for `"linear"`, 1.0526 for Huber (95 % efficiency)."""
    import numpy as np

    idx = loss_id(loss)
    if idx == 0:
        return 1.0
    c = TUNING[LOSS_NAMES[idx]]
    u = np.linspace(-12.0, 12.0, 48001)
    v = jnp.asarray(u / c)
    psi = np.asarray(v * rho_prime(idx, v * v))
    dpsi = np.asarray(psi_prime(idx, v))
    w = np.exp(-0.5 * u * u) / np.sqrt(2.0 * np.pi) * (u[1] - u[0])
    return float(np.sum(w * psi**2) / np.sum(w * dpsi) ** 2 * c * c)


@functools.lru_cache(maxsize=16)
def fixed_weight_factor(loss: str) -> float:
    r"""$\kappa/\kappa_w$ at the standard normal, for the named loss at its tuning
    constant: the M-estimator's variance factor $\kappa$ ([`normal_variance_factor`][])
    over the fixed-weight sandwich's $\kappa_w = E[w^2]/E[w]^2$ ($w = \rho'$, the IRLS
    weight). The sandwich $\sigma^2 A^{-1}(J^TW^2J)A^{-1}$, $A = J^TWJ$, holds the final
    weights fixed although they follow the residuals: at the normal it is
    $\kappa_w\sigma^2(J^TJ)^{-1}$, short of the estimator's variance by this factor
    (1 for `"linear"`; Huber 1.040, i.e. 2.0 % in the standard error)."""
    import numpy as np

    idx = loss_id(loss)
    if idx == 0:
        return 1.0
    c = TUNING[LOSS_NAMES[idx]]
    u = np.linspace(-12.0, 12.0, 48001)
    w = np.asarray(rho_prime(idx, jnp.asarray((u / c) ** 2)))
    p = np.exp(-0.5 * u * u)
    kappa_w = float(np.sum(p * w * w) * np.sum(p) / np.sum(p * w) ** 2)
    return normal_variance_factor(loss) / kappa_w


#: [`fixed_weight_factor`][] of each of `LOSS_NAMES` at its `TUNING` constant, as
#: computed (a test recomputes them): a fit reads the table instead of integrating
#: (0.3 s a process)
FIXED_WEIGHT_FACTORS = (1.0, 1.0402091693447666, 1.020179234435524, 1.0291413249203547,
                        1.037177667109238)  # fmt: skip


def fixed_weight_factor_of(idx):
    """[`fixed_weight_factor`][] for loss number `idx` (an int or a traced integer),
    from `FIXED_WEIGHT_FACTORS`; 1 for a custom loss (its factor is not tabulated)."""
    table = [*FIXED_WEIGHT_FACTORS, 1.0]
    if isinstance(idx, int):
        return table[min(idx, CUSTOM)]
    return jnp.asarray(table)[jnp.clip(idx, 0, CUSTOM)]
