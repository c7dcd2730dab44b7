"""Fitting: general (robust) least squares on optimistix, feature models."""

from ._least_squares import LsqArrays as LsqArrays
from ._least_squares import LsqResult as LsqResult
from ._least_squares import Status as Status
from ._least_squares import least_squares as least_squares
from ._least_squares import solve_arrays as solve_arrays
from ._features import FeatureFit as FeatureFit
from ._features import feature_residuals as feature_residuals
from ._features import fit_feature as fit_feature
from ._profile_fit import ProfileFit as ProfileFit
from ._profile_fit import fit_profile as fit_profile
