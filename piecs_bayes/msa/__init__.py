"""Measuring-system analysis: is the gauge (here the machine's own probe) capable of
the tolerance? The type-1 study (Cg, Cgk), the gauge R&R by ANOVA with its
average-and-range cross-check, and the VDA 5 / ISO 22514-7 uncertainty budget (Q_MS,
Q_MP). numpy and scipy only; reading the study files is the job's
(`piecs_bayes.jobs.gauge_type1_study`, `gauge_rr_study`). Model: docs/msa.md."""

from ._anova import AnovaRow as AnovaRow
from ._anova import AnovaTable as AnovaTable
from ._grr import COMPONENTS as COMPONENTS
from ._grr import GrrBatch as GrrBatch
from ._grr import GrrResult as GrrResult
from ._grr import VarianceComponent as VarianceComponent
from ._grr import gauge_rr as gauge_rr
from ._grr import gauge_rr_batch as gauge_rr_batch
from ._intervals import Interval as Interval
from ._range import RangeGrr as RangeGrr
from ._range import range_constants as range_constants
from ._range import range_method as range_method
from ._settings import MsaSettings as MsaSettings
from ._type1 import Reference as Reference
from ._type1 import Type1Batch as Type1Batch
from ._type1 import Type1Result as Type1Result
from ._type1 import type1_batch as type1_batch
from ._type1 import type1_study as type1_study
from ._vda5 import BudgetComponent as BudgetComponent
from ._vda5 import UncertaintyBudget as UncertaintyBudget
from ._vda5 import uncertainty_budget as uncertainty_budget
