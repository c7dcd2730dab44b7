"""Is compensation justified for a feature: conformance, action losses, verdicts and
the decision table's rules, one part or many at once."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._actions import ActionLoss as ActionLoss
from ._conformance import Conformance as Conformance
from ._conformance import conformance as conformance
from ._corrections import corrections as corrections
from ._decision import Decision as Decision
from ._decision import DrawnFeature as DrawnFeature
from ._decision import decide as decide
from ._settings import DecisionSettings as DecisionSettings
from ._settings import settings_from_spec as settings_from_spec
