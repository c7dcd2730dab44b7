"""[`Posterior`][]: draws from a posterior with the diagnostics that say whether
to trust them, as NumPy arrays, ArviZ `InferenceData` or a netCDF file; built by
[`make_posterior`][] for both samplers (`sample_posterior`,
`sample_posteriors`)."""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np

from ...errors import InputError
from ._diagnostics import arviz_layout


def frozen(a) -> np.ndarray:
    a = np.array(a)
    a.flags.writeable = False
    return a


@dataclass(frozen=True, repr=False, eq=False)
class Posterior:
    """Draws from a posterior and the diagnostics that say whether to trust them.

    Fields:

    - `names`: parameter names, in the order of the last axis.
    - `chains`: kept draws, shape `(steps, n_ensembles * nwalkers, dim)` after
      `burn` and `thin`; walkers `k*nwalkers ... (k+1)*nwalkers - 1` form
      ensemble `k` (see `ensemble_chains`).
    - `log_prob`: log posterior of each kept draw, shape `(steps, walkers)`.
    - `acceptance_fraction`: per walker, over the whole run.
    - `tau`: integrated autocorrelation time per parameter, in steps of the
      unthinned run (mean over ensembles); `tau_reliable`: kept chain
      $\\ge$ `tau_factor` $\\tau$ in every ensemble.
    - `ess`: effective sample size per parameter; `rhat`: split $\\hat R$ across
      independent ensembles.
    - `converged`, `problems`: the verdict and, when false, why.
    - `wall_time`: seconds spent sampling (compilation excluded).
    - `sampler`: what made the draws: ``"emcee <version>"`` (`sample_posterior`) or
      ``"piecs_bayes lockstep ensembles (jax)"`` (the lockstep sampler, with its
      backend).
    """

    names: tuple[str, ...]
    chains: np.ndarray
    log_prob: np.ndarray
    acceptance_fraction: np.ndarray
    tau: np.ndarray
    tau_reliable: np.ndarray
    ess: np.ndarray
    rhat: np.ndarray
    converged: bool
    problems: tuple[str, ...]
    n_ensembles: int
    nwalkers: int
    nsteps: int
    burn: int
    thin: int
    wall_time: float
    criteria: dict[str, float] = field(default_factory=dict)
    sampler: str = ""

    @property
    def samples(self) -> np.ndarray:
        """Flat draws, shape `(steps * walkers, dim)`."""
        return self.chains.reshape(-1, self.chains.shape[-1])

    @property
    def ensemble_chains(self) -> np.ndarray:
        """Draws as `(n_ensembles, steps, nwalkers, dim)`."""
        s, _, d = self.chains.shape
        return self.chains.reshape(s, self.n_ensembles, self.nwalkers, d).transpose(1, 0, 2, 3)

    @property
    def mean(self) -> np.ndarray:
        return self.samples.mean(axis=0)

    @property
    def cov(self) -> np.ndarray:
        return np.atleast_2d(np.cov(self.samples, rowvar=False))

    @property
    def sd(self) -> np.ndarray:
        return self.samples.std(axis=0, ddof=1)

    @property
    def mcse(self) -> np.ndarray:
        """Monte Carlo standard error of the mean: $\\mathrm{sd}/\\sqrt{\\mathrm{ESS}}$."""
        return self.sd / np.sqrt(self.ess)

    @property
    def ess_per_second(self) -> float:
        """Smallest ESS over parameters divided by the sampling wall time."""
        return float(np.min(self.ess) / self.wall_time) if self.wall_time > 0 else math.inf

    def __getitem__(self, name: str) -> np.ndarray:
        """Flat draws of one parameter by name."""
        try:
            j = self.names.index(name)
        except ValueError:
            raise KeyError(f"no parameter {name!r}; have {list(self.names)}") from None
        return self.samples[:, j]

    def interval(self, p: float = 0.95) -> tuple[np.ndarray, np.ndarray]:
        """Equal-tailed `p` credible interval per parameter: `(lower, upper)` arrays."""
        if not 0.0 < p < 1.0:
            raise InputError(f"interval: got p={p!r}, expected 0 < p < 1", value=p)
        lo, hi = np.quantile(self.samples, [0.5 - p / 2, 0.5 + p / 2], axis=0)
        return lo, hi

    def summary(self) -> str:
        lo, hi = self.interval(0.95)
        w = max(8, *(len(n) for n in self.names))
        head = f"{'':{w}}  {'mean':>11} {'sd':>10} {'2.5%':>11} {'97.5%':>11}"
        lines = [head + f" {'tau':>7} {'ESS':>8} {'R-hat':>6}"]
        for j, n in enumerate(self.names):
            flag = "" if self.tau_reliable[j] else "*"
            lines.append(
                f"{n:{w}}  {self.mean[j]:11.5g} {self.sd[j]:10.4g} {lo[j]:11.5g} {hi[j]:11.5g}"
                f" {self.tau[j]:6.1f}{flag or ' '} {self.ess[j]:8.0f} {self.rhat[j]:6.3f}"
            )
        if not all(self.tau_reliable):
            lines.append("(* tau not trusted: kept chain shorter than 50 tau)")
        return "\n".join(lines)

    def __repr__(self) -> str:
        s = self.chains.shape[0]
        acc = float(np.mean(self.acceptance_fraction))
        head = (
            f"Posterior(converged={self.converged}, {self.n_ensembles} ensembles x "
            f"{self.nwalkers} walkers x {s} kept steps (nsteps {self.nsteps}, burn "
            f"{self.burn}, thin {self.thin}), acceptance {acc:.2f}, {self.wall_time:.2f} s, "
            f"{self.ess_per_second:.3g} ESS/s)"
        )
        tail = "".join(f"\n  ! {p}" for p in self.problems)
        return head + "\n" + self.summary() + tail

    @property
    def arviz_chains(self) -> np.ndarray:
        """Draws as ArviZ chains, `(n_ensembles, nwalkers * steps, dim)`: one chain
        per independent ensemble, its walkers' trajectories one after the other
        (see `piecs_bayes.fit.mcmc._diagnostics`). `ess` and `rhat` are ArviZ's
        numbers on exactly these chains."""
        return arviz_layout(self.ensemble_chains)

    @property
    def arviz_log_prob(self) -> np.ndarray:
        """Log posterior of each draw of `arviz_chains`, `(n_ensembles, nwalkers * steps)`."""
        s = self.log_prob.shape[0]
        lp = self.log_prob.reshape(s, self.n_ensembles, self.nwalkers).transpose(1, 0, 2)
        return arviz_layout(lp)

    def run_attrs(self) -> dict:
        """The run's settings and diagnostics as netCDF-ready attributes (numbers,
        strings, arrays): sampler, ensembles, walkers, steps, burn, thin, the
        verdict, and per parameter (`parameter_names` order) R-hat, ESS and tau."""
        return {
            "sampler": self.sampler or f"emcee {emcee_module().__version__}",
            "chain": "one independent ensemble",
            "draw": "walker-major: walker w's kept step s is draw w * steps + s",
            "n_ensembles": self.n_ensembles,
            "nwalkers_per_ensemble": self.nwalkers,
            "nsteps": self.nsteps,
            "burn": self.burn,
            "thin": self.thin,
            "converged": int(self.converged),
            "problems": "; ".join(self.problems),
            "rhat": np.asarray(self.rhat),
            "ess_bulk": np.asarray(self.ess),
            "tau_steps": np.asarray(self.tau),
            "tau_reliable": np.asarray(self.tau_reliable, dtype=int),
            "wall_time_s": self.wall_time,
            "parameter_names": list(self.names),
        }

    def to_arviz(self):
        """ArviZ `InferenceData` (arviz 0.2x) whose own diagnostics are the package's.

        The posterior group has one ArviZ *chain* per independent ensemble and
        `draw` = the ensemble's walker trajectories one after the other
        (`arviz_chains`); `arviz.ess(idata)` and `arviz.rhat(idata)` equal `ess`
        and `rhat`. Walkers of one ensemble are coupled, so one chain per walker
        (what `arviz.from_emcee` does) would make ArviZ's R-hat meaningless.
        `sample_stats.lp` holds the log posterior; tau, the verdict and the run
        settings (`run_attrs`) are in the posterior's attrs. One scalar variable
        per parameter name; a profile fit's `BayesProfileFit.to_arviz` gives the
        full form (dims, units, observed data, log likelihood, prior).
        """
        az = import_arviz()
        chains = self.arviz_chains
        post = {n: chains[:, :, j] for j, n in enumerate(self.names)}
        idata = az.from_dict(posterior=post, sample_stats={"lp": self.arviz_log_prob})
        idata.posterior.attrs.update(self.run_attrs())
        return idata

    def to_netcdf(self, path) -> str:
        """Write `to_arviz()` to a netCDF file; `arviz.from_netcdf` reads it. For a file
        that appears whole or not at all, write through
        `piecs_bayes.io.write_file_atomic(path, posterior.to_netcdf)` (the CLI does)."""
        return self.to_arviz().to_netcdf(str(path))


def emcee_module():
    """emcee, imported on first use: it imports scipy.stats (~0.5 s), which a CLI
    run that does not sample should not pay for."""
    import emcee

    return emcee


#: arviz 0.2x announces its 1.x refactor with a FutureWarning on import: expected, not
#: actionable for our users (we pin < 1), so exactly that one is silenced
ARVIZ_NOTICE = r"\s*ArviZ is undergoing a major refactor"


def import_arviz():
    with warnings.catch_warnings():
        warnings.filterwarnings("ignore", message=ARVIZ_NOTICE, category=FutureWarning)
        import arviz as az
    return az


def quiet_arviz_notice() -> None:
    """Silence arviz's refactor notice in the current warning filters, for an import of
    arviz in another thread (where `warnings.catch_warnings` is not safe: it swaps the
    process's filters under the other threads)."""
    warnings.filterwarnings("ignore", message=ARVIZ_NOTICE, category=FutureWarning)


def make_posterior(names, draws, diag, problems, options, *, thin, wall_time, sampler
                   ) -> Posterior:  # fmt: skip
    """The [`Posterior`][] of thinned draws: `draws` = `(kept, lps, acceptance)`, the
    draws `(K, S, W, d)` of `K` ensembles of `W` walkers, their log posteriors
    `(K, S, W)` and the acceptance per walker; `diag` = `(tau, tau_reliable, ess,
    rhat)` per parameter, `problems` the failed criteria (none: converged),
    `options` the run's `SamplerOptions` (`for_dim`: its steps, burn and criteria),
    `thin` the total thinning, `sampler` the name of what made them."""
    kept, lps, acceptance = draws
    k, s, w, d = kept.shape
    tau, reliable, ess, rhat = diag
    return Posterior(
        names=names,
        chains=frozen(kept.transpose(1, 0, 2, 3).reshape(s, k * w, d)),
        log_prob=frozen(lps.transpose(1, 0, 2).reshape(s, k * w)),
        acceptance_fraction=frozen(acceptance),
        tau=frozen(tau),
        tau_reliable=frozen(reliable),
        ess=frozen(ess),
        rhat=frozen(rhat),
        converged=not problems,
        problems=tuple(problems),
        n_ensembles=k,
        nwalkers=w,
        nsteps=options.nsteps,
        burn=options.burn,
        thin=thin,
        wall_time=wall_time,
        criteria=options.criteria,
        sampler=sampler,
    )
