"""Fitting: general (robust) least squares on optimistix, feature models, Bayesian fits."""

from ._least_squares import LsqArrays as LsqArrays
from ._least_squares import LsqResult as LsqResult
from ._least_squares import Status as Status
from ._least_squares import least_squares as least_squares
from ._least_squares import solve_arrays as solve_arrays
from ._bayes import ConvergenceError as ConvergenceError
from ._bayes import ConvergenceWarning as ConvergenceWarning
from ._bayes import Posterior as Posterior
from ._bayes import gaussian_loglik as gaussian_loglik
from ._bayes import sample_posterior as sample_posterior
from ._bayes import split_rhat as split_rhat
from ._bayes import student_t_loglik as student_t_loglik
from ._priors import HalfNormal as HalfNormal
from ._priors import LogNormal as LogNormal
from ._priors import Normal as Normal
from ._priors import Prior as Prior
from ._priors import StudentT as StudentT
from ._priors import Uniform as Uniform
from ._priors import prior_from_spec as prior_from_spec
from ._features import FeatureFit as FeatureFit
from ._features import feature_residuals as feature_residuals
from ._features import fit_feature as fit_feature
from ._profile_fit import ProfileFit as ProfileFit
from ._profile_fit import fit_profile as fit_profile
from ._joint import TRANSFORM_PARAMS as TRANSFORM_PARAMS
from ._joint import fit_profile_joint as fit_profile_joint
