"""How sure: the characteristic of a feature (normal deviation and its u), GUM and
Monte Carlo (JCGM 101) propagation to the adjusted tool path, bands, budgets, and
the design of probe points for the characteristic's uncertainty."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._bands import Bands as Bands
from ._bands import bands_from_samples as bands_from_samples
from ._bands import bands_linear as bands_linear
from ._characteristic import AT_FRACTION as AT_FRACTION
from ._characteristic import Characteristic as Characteristic
from ._characteristic import at_fractions as at_fractions
from ._characteristic import characteristic_arrays as characteristic_arrays
from ._characteristic import deviation_and_jacobian as deviation_and_jacobian
from ._characteristic import feature_characteristic as feature_characteristic
from ._characteristic import nominal_points as nominal_points
from ._characteristic import normal_deviation as normal_deviation
from ._characteristic import normal_deviation_at as normal_deviation_at
from ._characteristic import normal_deviation_draws as normal_deviation_draws
from ._characteristic import u_systematic as u_systematic
from ._design import DesignSettings as DesignSettings
from ._design import FeaturePrediction as FeaturePrediction
from ._design import augment_fractions as augment_fractions
from ._design import design_fractions as design_fractions
from ._design import points_for_ratio as points_for_ratio
from ._design import predict_feature as predict_feature
from ._design import uniform_fractions as uniform_fractions
from ._propagate import AdaptiveMCResult as AdaptiveMCResult
from ._propagate import adaptive_monte_carlo as adaptive_monte_carlo
from ._propagate import coverage_interval as coverage_interval
from ._propagate import propagate_linear as propagate_linear
from ._propagate import propagate_mc as propagate_mc
from ._propagate import uncertainty_budget as uncertainty_budget
from ._toolpath import LINEARISED_SOURCES as LINEARISED_SOURCES
from ._toolpath import LinearisedOptions as LinearisedOptions
from ._toolpath import PathGrid as PathGrid
from ._toolpath import ToolpathUncertainty as ToolpathUncertainty
from ._toolpath import linearised_toolpath as linearised_toolpath
from ._toolpath import monte_carlo_toolpath as monte_carlo_toolpath
from ._toolpath import path_function as path_function
from ._toolpath import path_grid as path_grid
from ._toolpath import path_jacobian_function as path_jacobian_function
