"""A general ensemble MCMC engine: priors, moves, the emcee sampler and its lockstep
JAX counterpart for many problems at once, diagnostics and posteriors."""

from ... import _config  # noqa: F401  (float64 before any JAX array)
from ._core import gaussian_loglik as gaussian_loglik
from ._core import student_t_loglik as student_t_loglik
from ._diagnostics import split_rhat as split_rhat
from ._lockstep import sample_posteriors as sample_posteriors
from ._moves import check_moves as check_moves
from ._options import SamplerOptions as SamplerOptions
from ._posterior import frozen as frozen
from ._posterior import import_arviz as import_arviz
from ._posterior import quiet_arviz_notice as quiet_arviz_notice
from ._priors import HalfNormal as HalfNormal
from ._priors import LogNormal as LogNormal
from ._priors import Normal as Normal
from ._priors import Prior as Prior
from ._priors import ScaledInvChi2 as ScaledInvChi2
from ._priors import StudentT as StudentT
from ._priors import Uniform as Uniform
from ._priors import prior_from_spec as prior_from_spec
from ._sampler import ConvergenceError as ConvergenceError
from ._sampler import ConvergenceWarning as ConvergenceWarning
from ._sampler import Posterior as Posterior
from ._sampler import sample_posterior as sample_posterior
