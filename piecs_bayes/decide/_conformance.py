"""Conformance of a measured value with a tolerance, ISO 14253-1.

With $U = k_\\text{cov}\\,u$ the acceptance zone is $[T_L + rU, T_U - rU]$; a value
inside *conforms*, one outside $[T_L - rU, T_U + rU]$ *does not conform*, otherwise it
is *ambiguous*; the conformance probability is
$p_c = \\Phi((T_U - y)/u) - \\Phi((T_L - y)/u)$. When $u$ comes with finite (effective)
degrees of freedom $\\nu$, $p_c$ uses the $t_\\nu$ cdf and the coverage factor is
$t_\\nu$ at the probability $k_\\text{cov}$ has under the normal (95.45 % for $k = 2$,
JCGM 100 G.6).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .. import _config

special = _config.LazyModule("scipy.special")


@dataclass(frozen=True)
class Conformance:
    """ISO 14253-1 conformance of a value with standard uncertainty `u`.

    `state` is `"conforms"`, `"does not conform"` or `"ambiguous"`; `acceptance` is the
    guarded acceptance zone (empty, i.e. lower > upper, when $2rU$ exceeds the tolerance).
    """

    value: float
    u: float
    expanded: float
    tolerance: tuple[float, float]
    acceptance: tuple[float, float]
    p_conform: float
    state: str

    def __repr__(self) -> str:
        lo, hi = self.acceptance
        return (
            f"Conformance({self.state}, value={self.value:+.4g}, U={self.expanded:.2g}, "
            f"acceptance=[{lo:+.4g}, {hi:+.4g}], p_c={self.p_conform:.3f})"
        )


def conformance(
    value: float,
    u: float,
    tolerance: tuple[float, float],
    *,
    coverage_factor: float = 2.0,
    guard_band_factor: float = 1.0,
    dof: float = math.inf,
) -> Conformance:
    """ISO 14253-1 decision with guard bands $rU$, $U = k u$, and $p_c$ (see module doc).

    With finite `dof` the coverage factor is Student-t's at the normal coverage of
    `coverage_factor` and $p_c$ uses the $t_\\nu$ cdf."""
    lo, hi = (float(t) for t in tolerance)
    if math.isfinite(dof):
        p_cov = 2.0 * float(special.ndtr(coverage_factor)) - 1.0
        big_u = float(special.stdtrit(dof, 0.5 + p_cov / 2.0)) * u
    else:
        big_u = coverage_factor * u
    g = guard_band_factor * big_u
    acc = (lo + g, hi - g)
    if u > 0 and math.isfinite(dof):
        p_c = float(special.stdtr(dof, (hi - value) / u) - special.stdtr(dof, (lo - value) / u))
    elif u > 0:
        p_c = float(special.ndtr((hi - value) / u) - special.ndtr((lo - value) / u))
    else:
        p_c = float(lo <= value <= hi)
    if acc[0] <= value <= acc[1]:
        state = "conforms"
    elif value < lo - g or value > hi + g:
        state = "does not conform"
    else:
        state = "ambiguous"
    return Conformance(float(value), float(u), big_u, (lo, hi), acc, p_c, state)
