"""The lathe fits' settings as frozen objects, each default in one place: the
least-squares fits' [`FitOptions`][] (one part, a batch of parts, a joint fit), the
batch path's [`BatchOptions`][], the Bayesian profile model's [`BayesOptions`][] with
the Bayesian fits' sampler settings `BAYES_SAMPLING`, and the probe calibration's
[`CalibrationOptions`][]. Each is checked when made (the messages of the entry
points that checked them before)."""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from typing import Any

from ..errors import InputError
from ..geometry import MachineTransform
from ..io import parse_fix
from ._measurement import RadiusComponents, is_calibration_source
from ._sigma import DECLARED_DOF
from .lsq import SolverOptions
from .mcmc import SamplerOptions

#: parts per chunk of a batch fit (progress is reported per chunk)
CHUNK_PARTS = 1024
#: problems per compiled call. One fixed size: every study, chunking and cluster
#: reuses one compilation per group, and a problem's result does not depend on
#: which others share its batch. (Padding a small study to it costs milliseconds.)
BATCH = 256
#: the solvers of `FitOptions.solver` (`fit_profile` takes `"lm"` and `"auto"`)
FIT_SOLVERS = ("auto", "fast", "lm", "gauss_newton", "dogleg")
#: the sampler settings of the Bayesian profile fits (`fit_profile_bayes`,
#: `fit_profiles_bayes`): the engine's (`SamplerOptions`) but for 3,000 steps, the
#: differential-evolution mixture and the lockstep sampler
BAYES_SAMPLING = SamplerOptions(nsteps=3000, moves="de", sampler="lockstep")
#: the probe calibration's (`fit_probe_calibration(options.method="bayes")`): the
#: Bayesian fits' without a progress bar
CALIBRATION_SAMPLING = replace(BAYES_SAMPLING, progress=False)


@dataclass(frozen=True)
class FitOptions:
    """The (robust) least-squares fit of a profile's features: what
    [`fit_feature`][], [`fit_profile`][], [`fit_profiles`][] and
    [`fit_profile_joint`][] share.

    **Fields:**

    - `method`: `"lsq"` (plain least squares) or `"robust"` (the loss `loss` with
      the scale `scale`: `None` estimates it from the residuals).
    - `sigma`: the probe sigma, known (every covariance scaled by it, $\\nu = \\infty$).
    - `declared`, `declared_dof`: with `sigma=None` (the default), the covariances
      are scaled by the residual sd **pooled over every feature** of the part,
      combined with the declared repeatability as a prior worth `declared_dof`
      degrees of freedom (`piecs_bayes.fit._sigma`).
    - `fix`: `{feature_id: (param, ...)}` (or the study's `"feature.param"` names)
      held at nominal.
    - `min_points`: `{"line": 3, "arc": 4}` by default (a given kind replaces its
      entry); fewer (but some) points on a feature is an error.
    - `solver`: `"auto"` (the default): the batch kernel, with the engine's
      Levenberg-Marquardt for what it does not solve; `"lm"`: the engine's
      Levenberg-Marquardt, one solve per feature (the reference the batch path is
      tested against); `fit_profiles` also takes `"fast"` (the kernel alone),
      `"gauss_newton"` and `"dogleg"` (engine solvers).
    - `rtol`, `atol`, `max_steps`: the solvers' tolerances and step limit
      ([`SolverOptions`][]'s defaults).

    `ValueError` for an unknown `method`, `InputError` for an unknown `solver`.
    """

    method: str = "lsq"
    loss: str = "huber"
    scale: float | None = None
    sigma: float | None = None
    declared: float | None = None
    declared_dof: float = DECLARED_DOF
    fix: Mapping[str, Sequence[str]] | Sequence[str] | None = None
    min_points: Mapping[str, int] | None = None
    solver: str = "auto"
    rtol: float = SolverOptions.rtol
    atol: float = SolverOptions.atol
    max_steps: int = SolverOptions.max_steps

    def __post_init__(self) -> None:
        if self.method not in ("lsq", "robust"):
            raise ValueError(f"unknown method {self.method!r}; expected 'lsq' or 'robust'")
        if self.solver not in FIT_SOLVERS:
            raise InputError(
                f"unknown solver {self.solver!r}; expected 'auto', 'fast', 'lm', "
                "'gauss_newton' or 'dogleg'"
            )
        fix = self.fix or {}
        fix = fix if isinstance(fix, Mapping) else parse_fix(fix)
        object.__setattr__(self, "fix", {k: tuple(v) for k, v in fix.items()})
        object.__setattr__(self, "min_points", {"line": 3, "arc": 4, **(self.min_points or {})})

    @property
    def solve_loss(self) -> str:
        """The loss the solves minimise: `"linear"` for `method="lsq"`, else `loss`."""
        return "linear" if self.method == "lsq" else self.loss

    @property
    def reference_sigma(self) -> float:
        """The sigma the solves' covariances are computed at (rescaled per part to its
        probe sigma): the known or the declared one (it also sets the scale of the
        stationarity test, so it should be realistic), else 1 mm."""
        ref = self.sigma if self.sigma is not None else self.declared
        return float(ref if ref is not None else 1.0)

    def engine_solver(self, method: str = "lm") -> SolverOptions:
        """The engine's [`SolverOptions`][] with these tolerances."""
        return SolverOptions(method=method, rtol=self.rtol, atol=self.atol,
                             max_steps=self.max_steps)  # fmt: skip


@dataclass(frozen=True)
class BatchOptions:
    """How [`fit_profiles`][] runs (its results do not depend on them).

    **Fields:**

    - `chunk_size`: parts per compiled call (memory grows with it).
    - `batch_size`: problems per compiled call (see `BATCH`; fewer for buckets
      over `BATCH_POINTS // batch_size` points).
    - `progress`: `True` for a tqdm bar, or a callable `progress(done, total, part)`
      called after each chunk.

    `InputError` for a `chunk_size` or `batch_size` below 1.
    """

    chunk_size: int = CHUNK_PARTS
    batch_size: int = BATCH
    progress: bool | Callable[[int, int, str], None] = False

    def __post_init__(self) -> None:
        if self.chunk_size < 1 or self.batch_size < 1:
            raise InputError(
                f"chunk_size and batch_size must be >= 1, got {self.chunk_size!r}, "
                f"{self.batch_size!r}"
            )


@dataclass(frozen=True)
class BayesOptions:
    """The Bayesian model of a profile ([`fit_profile_bayes`][],
    [`fit_profiles_bayes`][], [`profile_log_posterior`][]).

    **Fields:**

    - `sources`: the study's uncertainty sources (prior specs, its `[uncertainty]`
      tables); a probe calibration's components (`probe_cal_<j>`) need `radius`.
    - `ball_radius`: the stylus ball radius (mm).
    - `sigma`: the known probe repeatability (used unless `repeatability` is a
      source, in which case it is estimated with that prior).
    - `transform`: the study's machine -> part transform.
    - `likelihood`: `"gaussian"` or `"student_t"` (with `nu` degrees of freedom).
    - `radius`: the probe calibration's `RadiusComponents`, when `sources` holds its
      components.
    - `file`: where the sources were read (for messages).

    `InputError` for an unknown likelihood or a calibration source without its
    calibration.
    """

    sources: Mapping[str, Any]
    ball_radius: float
    sigma: float
    transform: MachineTransform = MachineTransform()
    likelihood: str = "gaussian"
    nu: float = 4.0
    radius: RadiusComponents | None = None
    file: str | None = None

    def __post_init__(self) -> None:
        if self.transform is None:
            object.__setattr__(self, "transform", MachineTransform())
        radius = self.radius
        unknown = [
            n
            for n in self.sources
            if is_calibration_source(n) and (radius is None or n not in radius.names)
        ]
        if unknown:
            raise InputError(
                f"source {unknown[0]!r} needs the probe calibration it belongs to", file=self.file
            )
        if self.likelihood not in ("gaussian", "student_t"):
            raise InputError(
                f"unknown likelihood {self.likelihood!r}; expected 'gaussian' or 'student_t'",
                value=self.likelihood,
            )


@dataclass(frozen=True)
class CalibrationOptions:
    """The probe calibration fit ([`fit_probe_calibration`][]).

    **Fields:**

    - `orders`: `"auto"` (chosen by the u of r(theta) at the parts' directions,
      `choose_orders`), `"a2"` (one radius per axis) or a tuple of orders in (2, 3)
      (`()`: one radius).
    - `sigma_dof`: what the declared repeatability is worth (the scaled-inverse-chi^2
      prior's nu, `method="bayes"`).
    - `sigma_known`: the covariance from the declared repeatability (dof infinite)
      instead of the residuals (dof = n - p).
    - `method`: `"lsq"` ((robust) least squares, `loss`; Huber by default with the
      package's tuning times the declared repeatability as its scale, as the part
      fits; the linear loss below 3 dof) or `"bayes"` (the certificate a normal
      prior on the sizes; started at the fit).

    `InputError` for an unknown `method`.
    """

    orders: str | tuple[int, ...] = "auto"
    sigma_dof: float = DECLARED_DOF
    sigma_known: bool = False
    method: str = "lsq"
    loss: str = "huber"

    def __post_init__(self) -> None:
        if self.method not in ("lsq", "bayes"):
            raise InputError(
                f"method {self.method!r}; expected 'lsq' or 'bayes'", value=self.method
            )
