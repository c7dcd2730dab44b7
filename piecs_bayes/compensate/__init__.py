"""From fitted deviations to decisions: PIECS mirroring, capability, decision rules."""

from ._capability import BayesCapability as BayesCapability
from ._capability import CapabilityResult as CapabilityResult
from ._capability import Interval as Interval
from ._capability import PredictedCapability as PredictedCapability
from ._capability import SigmaEstimate as SigmaEstimate
from ._capability import StabilityResult as StabilityResult
from ._capability import c4_constant as c4_constant
from ._capability import capability as capability
from ._capability import d2_constant as d2_constant
from ._capability import predict_capability as predict_capability
from ._capability import sigma_within as sigma_within
from ._capability import stability_check as stability_check
from ._decision import ActionLoss as ActionLoss
from ._decision import Conformance as Conformance
from ._decision import Decision as Decision
from ._decision import DecisionSettings as DecisionSettings
from ._decision import conformance as conformance
from ._decision import decide as decide
from ._decision import settings_from_spec as settings_from_spec
from ._mirror import AdjustedPath as AdjustedPath
from ._mirror import adjusted_geometry as adjusted_geometry
from ._mirror import adjusted_path as adjusted_path
from ._mirror import compensated_deviations as compensated_deviations
