"""The ensemble sampler's settings as one frozen object, [`SamplerOptions`][], shared by
the one-part [`sample_posterior`][] and the many-part [`sample_posteriors`][]: how long
and how many walkers, the moves, the convergence criteria and what a failed verdict
does. Checked when made (the messages the samplers gave before)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Literal

from ...errors import InputError
from ._core import check_thin
from ._moves import check_moves


@dataclass(frozen=True)
class SamplerOptions:
    """The settings of an ensemble MCMC run.

    **Fields:**

    - `nwalkers`: walkers per ensemble; default `max(64, 4 dim)` (even). Walkers
      are nearly free under `vectorize=True` (emcee's per-step Python overhead
      dominates), so more walkers buy effective samples per second: on Newcomb's
      2-parameter model, 64 walkers gave 2.8x the ESS/s of 32.
    - `nsteps`, `burn` (default `nsteps // 4`), `thin`: steps per ensemble,
      steps discarded, thinning of the kept steps: an int, or ``"auto"`` (the
      default): about half the smallest autocorrelation time, estimated on the
      unthinned draws (ESS and R-hat are then those of the stored draws).
    - `seed`: seeds every ensemble's start and random stream (reproducible).
    - `progress`: a tqdm progress bar (per ensemble with emcee, one for all with
      the lockstep sampler); a callable also gets a line before the diagnostics.
    - `n_ensembles`: independent ensembles, for $\\hat R$.
    - `init_scale`: walkers start at draws of $N(x_0,$ `init_scale`$^2 C_0)$.
    - `on_fail`: `"warn"` (`ConvergenceWarning`), `"raise"` (`ConvergenceError`)
      or `"ignore"` when the run does not meet the criteria below.
    - `rhat_max`, `min_ess`, `tau_factor`: criteria: split $\\hat R \\le$ `rhat_max`,
      ESS $\\ge$ `min_ess`, kept chain $\\ge$ `tau_factor` $\\tau$ for every parameter.
    - `moves`: ``None``/``"stretch"`` (emcee's stretch move) or ``"de"``: 80 %
      differential evolution, 20 % stretch (`piecs_bayes.fit.mcmc._moves`).
    - `sampler`: [`sample_posterior`][]'s: ``"emcee"`` (emcee's `EnsembleSampler`)
      or ``"lockstep"`` (the same ensembles and moves in one jitted JAX loop).
      [`sample_posteriors`][] is the lockstep sampler and does not read it.

    `InputError` for an unknown `on_fail`, `thin`, `moves` or `sampler`, fewer than
    8 kept steps, or fewer than one ensemble.
    """

    nwalkers: int | None = None
    nsteps: int = 2000
    burn: int | None = None
    thin: int | str = "auto"
    seed: int = 0
    progress: bool | Callable[[str], None] = True
    n_ensembles: int = 4
    init_scale: float = 1.0
    on_fail: Literal["warn", "raise", "ignore"] = "warn"
    rhat_max: float = 1.01
    min_ess: float = 400.0
    tau_factor: float = 50.0
    moves: str | None = None
    sampler: Literal["emcee", "lockstep"] = "emcee"

    def __post_init__(self) -> None:
        if self.on_fail not in ("warn", "raise", "ignore"):
            raise InputError(f"on_fail: got {self.on_fail!r}, expected 'warn', 'raise' or 'ignore'")
        check_moves(self.moves)
        burn, thin = self.kept_burn, self.run_thin
        nsteps = self.nsteps
        if not (0 <= burn < nsteps) or thin < 1 or (nsteps - burn) // thin < 8:
            raise InputError(
                f"nsteps={nsteps}, burn={burn}, thin={thin}: expected 0 <= burn < nsteps, "
                "thin >= 1 and at least 8 kept steps"
            )
        if self.n_ensembles < 1:
            raise InputError(f"n_ensembles: got {self.n_ensembles}, expected >= 1")
        if self.sampler not in ("emcee", "lockstep"):
            raise InputError(
                f"sampler: got {self.sampler!r}, expected 'emcee' or 'lockstep'",
                value=self.sampler,
            )

    @property
    def kept_burn(self) -> int:
        """The steps discarded: `burn`, or `nsteps // 4`."""
        return self.nsteps // 4 if self.burn is None else int(self.burn)

    @property
    def run_thin(self) -> int:
        """The thinning of the run itself (`"auto"` thins after it: 1)."""
        thin = check_thin(self.thin)
        return 1 if thin == "auto" else thin

    @property
    def criteria(self) -> dict[str, float]:
        """The convergence criteria, `{"rhat_max", "min_ess", "tau_factor"}`."""
        return {"rhat_max": self.rhat_max, "min_ess": self.min_ess, "tau_factor": self.tau_factor}

    def for_dim(self, ndim: int) -> SamplerOptions:
        """These options for a posterior of `ndim` parameters: `nwalkers` and `burn`
        with their defaults, `moves` by its canonical name, `thin` checked."""
        nwalkers = self.nwalkers
        if nwalkers is None:
            nwalkers = max(64, 4 * ndim)
            nwalkers += nwalkers % 2
        return replace(self, nwalkers=nwalkers, burn=self.kept_burn,
                       thin=check_thin(self.thin), moves=check_moves(self.moves))  # fmt: skip
