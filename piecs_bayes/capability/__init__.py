"""Process capability: within sigma, Cp/Cpk/Pp/Ppk with intervals, Bayesian capability,
stability checks and the capability predicted after a correction."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._bayes import BayesCapability as BayesCapability
from ._capability import CapabilityResult as CapabilityResult
from ._capability import capability as capability
from ._indices import Interval as Interval
from ._options import CapabilityOptions as CapabilityOptions
from ._prediction import PredictedCapability as PredictedCapability
from ._prediction import predict_capability as predict_capability
from ._sigma import SigmaEstimate as SigmaEstimate
from ._sigma import c4_constant as c4_constant
from ._sigma import d2_constant as d2_constant
from ._sigma import sigma_within as sigma_within
from ._stability import StabilityResult as StabilityResult
from ._stability import stability_check as stability_check
