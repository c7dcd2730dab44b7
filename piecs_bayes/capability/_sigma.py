"""Within-subgroup (short-term) sigma estimators and their control-chart constants.

$\\bar R/d_2$ and $\\bar S/c_4$ for subgroups, $s_p/c_4(\\nu+1)$ for subgroups of any
size, $\\overline{MR}/d_2(2)$ for individuals, and the overall sample standard deviation.
Each estimate carries its effective degrees of freedom (Patnaik:
$\\nu = 1/(2\\,\\mathrm{Var}(\\hat\\sigma/\\sigma))$; $\\bar R$: $m d_2^2/(2 d_3^2)$;
$\\bar S$: $m c_4^2/(2(1-c_4^2))$; $\\overline{MR}$: about $0.6(n-1)$; overall $s$: $n-1$),
or $\\nu = n - 1$ and 3-/4-decimal table constants under `convention="qcc"` (see
docs/models/capability.md).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Literal

import numpy as np

from .. import _config
from ..errors import InputError

integrate = _config.LazyModule("scipy.integrate")
special = _config.LazyModule("scipy.special")


Convention = Literal["piecs", "qcc"]
#: the conventions of the table constants and degrees of freedom (module docstring)
CONVENTIONS = ("piecs", "qcc")
#: the within-sigma estimators of `sigma_within`
SIGMA_METHODS = ("auto", "rbar", "sbar", "pooled", "mr", "overall")


def check_convention(convention: str) -> None:
    if convention not in CONVENTIONS:
        raise InputError(f"unknown convention {convention!r}; expected one of {CONVENTIONS}")


# --------------------------------------------------------------------------- constants


@lru_cache(maxsize=64)
def _range_moments(n: int) -> tuple[float, float]:
    """$E[W]$ and $E[W^2]$ of the range $W$ of $n$ standard normal values.

    $E[W] = \\int 1 - \\Phi^n - (1-\\Phi)^n\\,dx$;
    $E[W^2] = \\int_0^\\infty 2w(1 - F_W(w))\\,dw$ with
    $F_W(w) = n\\int \\phi(x)[\\Phi(x+w) - \\Phi(x)]^{n-1}dx$ (Simpson, ~1e-11).
    """
    x = np.linspace(-8.5, 8.5, 681)
    cdf = special.ndtr(x)
    ew = integrate.simpson(1.0 - cdf**n - (1.0 - cdf) ** n, x=x)
    w = np.linspace(0.0, 12.0, 481)
    pdf = np.exp(-0.5 * x**2) / math.sqrt(2 * math.pi)
    inner = (special.ndtr(x[None, :] + w[:, None]) - cdf[None, :]) ** (n - 1)
    fw = n * integrate.simpson(pdf[None, :] * inner, x=x, axis=1)
    ew2 = integrate.simpson(2.0 * w * (1.0 - fw), x=w)
    return float(ew), float(ew2)


def d2_constant(n: int, *, convention: Convention = "piecs") -> float:
    """Control-chart constant $d_2(n) = E[R]/\\sigma$ for subgroups of size `n` (2..50).

    `convention="qcc"` returns the 3-decimal table value (Montgomery, Appendix VI).
    """
    if not 2 <= int(n) <= 50:
        raise InputError(f"subgroup size must be 2..50 for d2, got {n}", value=n)
    if n == 2:
        exact = 2.0 / math.sqrt(math.pi)
    else:
        exact = _range_moments(int(n))[0]
    return round(exact, 3) if convention == "qcc" else exact


def d3_constant(n: int) -> float:
    if n == 2:
        return math.sqrt(2.0 - 4.0 / math.pi)
    ew, ew2 = _range_moments(int(n))
    return math.sqrt(ew2 - ew**2)


def c4_constant(n: int, *, convention: Convention = "piecs") -> float:
    """$c_4(n) = E[S]/\\sigma = \\sqrt{2/(n-1)}\\,\\Gamma(n/2)/\\Gamma((n-1)/2)$.

    `convention="qcc"` rounds to the 4-decimal table value.
    """
    if n < 2:
        raise InputError(f"c4 needs n >= 2, got {n}", value=n)
    v = math.sqrt(2.0 / (n - 1)) * math.exp(special.gammaln(n / 2) - special.gammaln((n - 1) / 2))
    return round(v, 4) if convention == "qcc" else v


def _mr_sigma_df(k: int) -> float:
    """Effective degrees of freedom of $\\overline{MR}/d_2(2)$ from `k` moving ranges.

    $\\mathrm{Var}(\\overline{MR}) = \\sigma^2[k v + 2(k-1)c]/k^2$ with $v = 2-4/\\pi$ and
    $c = (4/\\pi)(\\sqrt3/2 + \\pi/12 - 1)$ (neighbouring ranges share a value).
    """
    v = 2.0 - 4.0 / math.pi
    c = (4.0 / math.pi) * (math.sqrt(3.0) / 2.0 + math.pi / 12.0 - 1.0)
    var_mr = (k * v + 2.0 * (k - 1) * c) / k**2
    var_sigma = var_mr / (4.0 / math.pi)
    return 1.0 / (2.0 * var_sigma)


# --------------------------------------------------------------------------- estimate


@dataclass(frozen=True)
class SigmaEstimate:
    """A standard-deviation estimate with its method and effective degrees of freedom."""

    value: float
    method: str
    df: float

    def __repr__(self) -> str:
        return f"SigmaEstimate({self.value:.6g}, method={self.method!r}, df={self.df:.1f})"


def as_groups(data, subgroups) -> tuple[np.ndarray, list[np.ndarray] | None]:
    """Flatten the input; return (all values, subgroups or None for individuals)."""
    if subgroups is not None:
        y = np.asarray(data, dtype=float)
        labels = np.asarray(subgroups)
        if y.ndim != 1 or labels.shape != y.shape:
            raise InputError(
                f"subgroups must be one label per value: got {labels.shape} labels for "
                f"{y.shape} values"
            )
        _, first = np.unique(labels, return_index=True)
        order = np.argsort(first)  # subgroups in order of first appearance
        keys = np.unique(labels)[order]
        groups = [y[labels == k] for k in keys]
    elif isinstance(data, np.ndarray) or not _is_ragged(data):
        arr = np.asarray(data, dtype=float)
        if arr.ndim == 1:
            groups = None
        elif arr.ndim == 2:
            groups = [row for row in arr]
        else:
            raise InputError(f"data must be 1-D (individuals) or 2-D (subgroups), got {arr.ndim}-D")
    else:
        groups = [np.asarray(g, dtype=float).ravel() for g in data]
    y = np.concatenate(groups) if groups is not None else np.asarray(data, dtype=float).ravel()
    bad = np.flatnonzero(~np.isfinite(y))
    if bad.size:
        raise InputError(
            f"capability data must be finite numbers; value {int(bad[0])} is {float(y[bad[0]])!r}",
            value=float(y[bad[0]]),
        )
    if y.size < 2:
        raise InputError(f"capability needs at least 2 values, got {y.size}")
    return y, groups


def _is_ragged(data) -> bool:
    if not isinstance(data, Sequence) or isinstance(data, str | bytes) or len(data) == 0:
        return False
    first = data[0]
    if not isinstance(first, Sequence | np.ndarray):
        return False
    sizes = {len(g) for g in data}
    return len(sizes) > 1


def sigma_within(
    data,
    *,
    subgroups=None,
    method: str = "auto",
    convention: Convention = "piecs",
) -> SigmaEstimate:
    """Within-subgroup (short-term) standard deviation.

    **Arguments:**

    - `data`: 1-D values in time order (individuals), a 2-D array (one row per
      subgroup), a list of 1-D subgroups, or 1-D values with `subgroups` labels.
    - `method`: `"auto"` (`"rbar"` for subgroups, `"mr"` for individuals), `"rbar"`
      ($\\bar R/d_2$), `"sbar"` ($\\bar S/c_4$), `"pooled"` ($s_p/c_4(\\nu+1)$, any sizes),
      `"mr"` ($\\overline{MR}/d_2(2)$), `"overall"` (sample sd, $n-1$).
    - `convention`: `"piecs"` or `"qcc"` (table constants, $\\nu = n - 1$).

    **Returns:** a [`SigmaEstimate`][] with its effective degrees of freedom.
    """
    check_convention(convention)
    if method not in SIGMA_METHODS:
        raise InputError(f"unknown sigma method {method!r}; expected one of {SIGMA_METHODS}")
    y, groups = as_groups(data, subgroups)
    n = y.size
    if method == "auto":
        method = "mr" if groups is None or all(g.size == 1 for g in groups) else "rbar"
    if method == "overall":
        return SigmaEstimate(float(np.std(y, ddof=1)), "overall", float(n - 1))
    if method == "mr":
        if n < 3:
            raise InputError(f"moving-range sigma needs at least 3 values, got {n}")
        mr = np.abs(np.diff(y))
        sigma = float(mr.mean() / d2_constant(2, convention=convention))
        df = float(n - 1) if convention == "qcc" else _mr_sigma_df(n - 1)
        return SigmaEstimate(sigma, "mr", df)
    if groups is None:
        raise InputError(f"sigma method {method!r} needs subgroups; got individual values")
    sizes = np.array([g.size for g in groups])
    if np.any(sizes < 2):
        raise InputError(
            f"every subgroup needs at least 2 values for method {method!r}; "
            f"subgroup {int(np.argmin(sizes))} has {int(sizes.min())}"
        )
    m = len(groups)
    if method == "pooled":
        dof = int(np.sum(sizes - 1))
        sp = math.sqrt(sum(float(np.var(g, ddof=1)) * (g.size - 1) for g in groups) / dof)
        sigma = sp / c4_constant(dof + 1, convention=convention)
        return SigmaEstimate(sigma, "pooled", float(n - 1 if convention == "qcc" else dof))
    if np.unique(sizes).size != 1:
        raise InputError(
            f"method {method!r} needs subgroups of equal size; got sizes "
            f"{sorted(set(sizes.tolist()))}; use method='pooled'"
        )
    k = int(sizes[0])
    if method == "rbar":
        rbar = float(np.mean([np.ptp(g) for g in groups]))
        d2 = d2_constant(k, convention=convention)
        sigma = rbar / d2
        df = float(n - 1) if convention == "qcc" else m * d2**2 / (2.0 * d3_constant(k) ** 2)
        return SigmaEstimate(sigma, "rbar", df)
    # sbar
    sbar = float(np.mean([np.std(g, ddof=1) for g in groups]))
    c4 = c4_constant(k, convention=convention)
    df = float(n - 1) if convention == "qcc" else m * c4**2 / (2.0 * (1.0 - c4**2))
    return SigmaEstimate(sbar / c4, "sbar", df)
