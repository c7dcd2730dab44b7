"""Is compensation justified for a feature: conformance, action losses, verdicts and
the decision table's rules, one part or many at once; the conformity risks (JCGM 106)
of accepting or correcting it."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._actions import ActionLoss as ActionLoss
from ._conformance import Conformance as Conformance
from ._conformance import conformance as conformance
from ._corrections import corrections as corrections
from ._decision import Decision as Decision
from ._decision import DrawnFeature as DrawnFeature
from ._decision import decide as decide
from ._risk import ConformityRisk as ConformityRisk
from ._risk import GlobalRisks as GlobalRisks
from ._risk import GuardBand as GuardBand
from ._risk import ProcessPrior as ProcessPrior
from ._risk import conformity_risk as conformity_risk
from ._risk import global_risks as global_risks
from ._risk import guard_band_width as guard_band_width
from ._risk import p_nonconforming as p_nonconforming
from ._risk import tur as tur
from ._settings import DecisionSettings as DecisionSettings
from ._settings import settings_from_spec as settings_from_spec
