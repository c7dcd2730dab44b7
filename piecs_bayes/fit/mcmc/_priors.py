r"""Prior distributions for Bayesian least squares.

Each prior is an immutable object with a JAX `log_pdf` (normalised, `-inf` outside the
support, differentiable inside it), a NumPy `sample(rng, n)`, its `mean`, `sd` and
`support`: [`Normal`][], [`Uniform`][], [`HalfNormal`][], [`LogNormal`][],
[`StudentT`][], [`ScaledInvChi2`][]. [`prior_from_spec`][] builds one from a study
file's `{dist = ..., ...}` table, refusing (`InputError`, naming the file and key) an
unknown distribution, key or value. Keys per `dist`: `normal` (`mean`, `sd`),
`uniform` (`low`, `high`, or `mean`, `half_width`), `half_normal` (`sd`), `lognormal`
(`mu`, `sigma` of $\log x$), `student_t` (`nu`, `loc` or `mean`, `scale`),
`scaled_inv_chi2` (`nu`, `scale`).

The densities and which prior when: docs/models/sampling.md, "Priors".
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import ClassVar

import jax.numpy as jnp
import jax.scipy.special as jsp
import numpy as np

from ...errors import InputError

_LOG_2PI = math.log(2.0 * math.pi)


class Prior:
    """Abstract base of the priors. Subclasses are frozen dataclasses."""

    dist: ClassVar[str] = ""

    def log_pdf(self, x):
        """Log density at `x` (JAX, elementwise), `-inf` outside the support."""
        raise NotImplementedError

    def sample(self, rng: np.random.Generator, n: int) -> np.ndarray:
        """`n` independent draws (NumPy) from a `numpy.random.Generator`."""
        raise NotImplementedError

    @property
    def mean(self) -> float:
        raise NotImplementedError

    @property
    def sd(self) -> float:
        raise NotImplementedError

    @property
    def support(self) -> tuple[float, float]:
        return (-math.inf, math.inf)


@dataclass(frozen=True)
class Normal(Prior):
    """$N(\\mu, \\sigma^2)$ with `mean` $\\mu$ and `sd` $\\sigma > 0$."""

    mu: float
    sigma: float
    dist: ClassVar[str] = "normal"

    def log_pdf(self, x):
        u = (jnp.asarray(x) - self.mu) / self.sigma
        return -0.5 * u * u - math.log(self.sigma) - 0.5 * _LOG_2PI

    def sample(self, rng, n):
        return rng.normal(self.mu, self.sigma, size=n)

    @property
    def mean(self):
        return float(self.mu)

    @property
    def sd(self):
        return float(self.sigma)


@dataclass(frozen=True)
class Uniform(Prior):
    """Rectangular $R(a, b)$, density $1/(b-a)$ on $[a, b]$."""

    low: float
    high: float
    dist: ClassVar[str] = "uniform"

    def log_pdf(self, x):
        x = jnp.asarray(x)
        inside = (x >= self.low) & (x <= self.high)
        return jnp.where(inside, -math.log(self.high - self.low), -jnp.inf)

    def sample(self, rng, n):
        return rng.uniform(self.low, self.high, size=n)

    @property
    def mean(self):
        return 0.5 * (self.low + self.high)

    @property
    def sd(self):
        return (self.high - self.low) / math.sqrt(12.0)

    @property
    def support(self):
        return (float(self.low), float(self.high))


@dataclass(frozen=True)
class HalfNormal(Prior):
    """$\\lvert N(0, \\sigma^2) \\rvert$: density $2\\varphi(x/\\sigma)/\\sigma$ for $x \\ge 0$."""

    sigma: float
    dist: ClassVar[str] = "half_normal"

    def log_pdf(self, x):
        x = jnp.asarray(x)
        u = x / self.sigma
        lp = -0.5 * u * u - math.log(self.sigma) + math.log(2.0) - 0.5 * _LOG_2PI
        return jnp.where(x >= 0.0, lp, -jnp.inf)

    def sample(self, rng, n):
        return np.abs(rng.normal(0.0, self.sigma, size=n))

    @property
    def mean(self):
        return self.sigma * math.sqrt(2.0 / math.pi)

    @property
    def sd(self):
        return self.sigma * math.sqrt(1.0 - 2.0 / math.pi)

    @property
    def support(self):
        return (0.0, math.inf)


@dataclass(frozen=True)
class LogNormal(Prior):
    """$\\log x \\sim N(\\mu, \\sigma^2)$, $x > 0$."""

    mu: float
    sigma: float
    dist: ClassVar[str] = "lognormal"

    def log_pdf(self, x):
        x = jnp.asarray(x)
        safe = jnp.where(x > 0.0, x, 1.0)
        lx = jnp.log(safe)
        u = (lx - self.mu) / self.sigma
        lp = -0.5 * u * u - lx - math.log(self.sigma) - 0.5 * _LOG_2PI
        return jnp.where(x > 0.0, lp, -jnp.inf)

    def sample(self, rng, n):
        return rng.lognormal(self.mu, self.sigma, size=n)

    @property
    def mean(self):
        return math.exp(self.mu + 0.5 * self.sigma**2)

    @property
    def sd(self):
        s2 = self.sigma**2
        return math.sqrt(math.expm1(s2)) * math.exp(self.mu + 0.5 * s2)

    @property
    def support(self):
        return (0.0, math.inf)


@dataclass(frozen=True)
class StudentT(Prior):
    """Location-scale Student-t: $(x - \\ell)/s \\sim t_\\nu$."""

    nu: float
    loc: float
    scale: float
    dist: ClassVar[str] = "student_t"

    def log_pdf(self, x):
        u = (jnp.asarray(x) - self.loc) / self.scale
        nu = self.nu
        const = (
            jsp.gammaln(0.5 * (nu + 1.0))
            - jsp.gammaln(0.5 * nu)
            - 0.5 * math.log(nu * math.pi)
            - math.log(self.scale)
        )
        return const - 0.5 * (nu + 1.0) * jnp.log1p(u * u / nu)

    def sample(self, rng, n):
        return self.loc + self.scale * rng.standard_t(self.nu, size=n)

    @property
    def mean(self):
        return float(self.loc) if self.nu > 1 else math.nan

    @property
    def sd(self):
        if self.nu > 2:
            return self.scale * math.sqrt(self.nu / (self.nu - 2.0))
        return math.inf if self.nu > 1 else math.nan


@dataclass(frozen=True)
class ScaledInvChi2(Prior):
    """A prior on a standard deviation $\\sigma$ whose variance is scaled-inverse-$\\chi^2$:
    $\\sigma^2 \\sim \\nu s^2/\\chi^2_\\nu$. The conjugate prior of a normal variance:
    a declared value $s$ worth $\\nu$ degrees of freedom (after $n$ residuals with sum of
    squares $S$, the posterior is the same family with $\\nu + n$ and
    $(\\nu s^2 + S)/(\\nu + n)$). The package's default prior on the probe sigma
    when it is estimated (`[probe] repeatability`, `repeatability_dof`)."""

    nu: float
    scale: float
    dist: ClassVar[str] = "scaled_inv_chi2"

    def log_pdf(self, x):
        x = jnp.asarray(x)
        safe = jnp.where(x > 0.0, x, 1.0)
        h = 0.5 * self.nu
        # density of x = sigma: p(sigma^2) * 2 sigma
        lp = (
            h * math.log(h) - jsp.gammaln(h) + self.nu * math.log(self.scale)
            - (2.0 * h + 1.0) * jnp.log(safe) - h * self.scale**2 / (safe * safe)
            + math.log(2.0)
        )  # fmt: skip
        return jnp.where(x > 0.0, lp, -jnp.inf)

    def sample(self, rng, n):
        return self.scale * np.sqrt(self.nu / rng.chisquare(self.nu, size=n))

    @property
    def mean(self):
        if self.nu <= 1:
            return math.inf
        h = 0.5 * self.nu
        return self.scale * math.sqrt(h) * math.exp(math.lgamma(h - 0.5) - math.lgamma(h))

    @property
    def sd(self):
        if self.nu <= 2:
            return math.inf
        m2 = self.scale**2 * self.nu / (self.nu - 2.0)
        return math.sqrt(max(m2 - self.mean**2, 0.0))

    @property
    def support(self):
        return (0.0, math.inf)


# --------------------------------------------------------------------------- spec parsing

# dist -> (alternative key sets, in order of preference); each set is all required
_KEYS: dict[str, tuple[tuple[str, ...], ...]] = {
    "normal": (("mean", "sd"),),
    "uniform": (("low", "high"), ("mean", "half_width")),
    "half_normal": (("sd",),),
    "lognormal": (("mu", "sigma"),),
    "student_t": (("nu", "loc", "scale"), ("nu", "mean", "scale")),
    "scaled_inv_chi2": (("nu", "scale"),),
}
_ALIASES = {"gaussian": "normal", "rectangular": "uniform", "halfnormal": "half_normal"}
_ALIASES |= {"log_normal": "lognormal", "t": "student_t", "studentt": "student_t"}


def _number(name, key, value, file):
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise InputError(
            f"prior {name!r}: key {key!r} = {value!r}: expected a number",
            file=file,
            value=value,
        )
    x = float(value)
    if not math.isfinite(x):
        raise InputError(
            f"prior {name!r}: key {key!r} = {value!r}: expected a finite number",
            file=file,
            value=value,
        )
    return x


def _positive(name, key, x, file):
    if x <= 0.0:
        raise InputError(
            f"prior {name!r}: key {key!r} = {x!r}: expected a value > 0", file=file, value=x
        )
    return x


def prior_from_spec(name: str, spec: dict, *, file: str | None = None) -> Prior:
    """Build a prior from a study-file table such as `{dist = "normal", mean = 0.0, sd = 0.002}`.

    **Arguments:**

    - `name`: the uncertainty source the prior belongs to (e.g. `"machine.scale_x"`);
      every error message names it.
    - `spec`: the table; `dist` is one of `normal`, `uniform`, `half_normal`,
      `lognormal`, `student_t` (a few aliases: `gaussian`, `rectangular`, `t`),
      plus the keys listed in the module docstring.
    - `file`: the study file, for error messages.

    **Returns:** a `Prior`.

    **Raises:** `InputError` naming `name`, the offending key and its value for a
    missing `dist`, an unknown distribution, a missing or unknown key, a value
    that is not a finite number, or a non-positive scale.
    """
    dist = _distribution(name, spec, file)
    keys = _parameter_keys(name, spec, dist, file)
    v = {k: _number(name, k, spec[k], file) for k in keys}
    if dist == "normal":
        return Normal(v["mean"], _positive(name, "sd", v["sd"], file))
    if dist == "uniform":
        if "half_width" in v:
            hw = _positive(name, "half_width", v["half_width"], file)
            return Uniform(v["mean"] - hw, v["mean"] + hw)
        if not v["high"] > v["low"]:
            raise InputError(
                f"prior {name!r}: key 'high' = {v['high']!r}: expected high > low = {v['low']!r}",
                file=file,
                value=v["high"],
            )
        return Uniform(v["low"], v["high"])
    if dist == "half_normal":
        return HalfNormal(_positive(name, "sd", v["sd"], file))
    if dist == "lognormal":
        return LogNormal(v["mu"], _positive(name, "sigma", v["sigma"], file))
    nu = _positive(name, "nu", v["nu"], file)
    if dist == "scaled_inv_chi2":
        return ScaledInvChi2(nu, _positive(name, "scale", v["scale"], file))
    loc = v.get("loc", v.get("mean"))
    return StudentT(nu, loc, _positive(name, "scale", v["scale"], file))


def _distribution(name: str, spec, file) -> str:
    """The canonical distribution name of `spec` (a table with a known `dist`)."""
    if not isinstance(spec, dict):
        raise InputError(
            f'prior {name!r}: expected a table like {{dist = "normal", mean = 0, sd = 1}}, '
            f"got {spec!r}",
            file=file,
            value=spec,
        )
    if "dist" not in spec:
        raise InputError(
            f"prior {name!r}: key 'dist' missing; expected one of {sorted(_KEYS)}",
            file=file,
        )
    raw = spec["dist"]
    dist = _ALIASES.get(str(raw).lower(), str(raw).lower()) if isinstance(raw, str) else None
    if dist not in _KEYS:
        raise InputError(
            f"prior {name!r}: key 'dist' = {raw!r}: unknown distribution, expected one of "
            f"{sorted(_KEYS)}",
            file=file,
            value=raw,
        )
    return dist


def _parameter_keys(name: str, spec: dict, dist: str, file) -> tuple[str, ...]:
    """The parameter keys of `spec`: exactly one of the key sets of `dist`."""
    given = {k for k in spec if k != "dist"}
    choices = _KEYS[dist]
    keys = next((ks for ks in choices if set(ks) == given), None)
    if keys is None:
        allowed = set().union(*map(set, choices))
        unknown = sorted(given - allowed)
        if unknown:
            raise InputError(
                f"prior {name!r}: key {unknown[0]!r} = {spec[unknown[0]]!r} is not a parameter "
                f"of a {dist} prior; expected " + " or ".join(map(str, map(list, choices))),
                file=file,
                value=spec[unknown[0]],
            )
        missing = sorted(set(choices[0]) - given)
        raise InputError(
            f"prior {name!r}: a {dist} prior needs keys "
            + " or ".join(map(str, map(list, choices)))
            + f"; missing {missing}",
            file=file,
        )
    return keys
