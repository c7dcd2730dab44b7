"""The user's jobs: what the CLI and the notebooks call.

Each job composes the numerical layers on a study and returns immutable data;
`piecs_bayes.export` renders and writes it. One part: `load_probe_data`, `fit_study`,
`bayes_study`, `compensate_study`, `toolpath_uncertainty`, `adjust_study_program`, its
decision table (`decide_study`) and machine data (`error_spec`, `tool_offsets`, both:
`machine_data`); the
main job end to end (`run_job` -> `JobResults`). Many parts: batch fits
(`fit_study_batch`), capability studies in chunks, in-process or on Dask
(`capability_study`, `capability_values`), path uncertainty of every part
(`path_uncertainty_batch`), feedback over a run (`feedback_study`). Also: the coverage
check of the stated uncertainty (`coverage_check`), the one translation of a study into
the layers' settings (`fit_options`, ...), a study from a part program (`init_study`),
the probe plan (`plan_study`), a probe's r(theta) (`calibrate_probe`) and the one route
of the correction to the machine (`apply_route`). Simulated data: `piecs_bayes.simulate`.
"""

from .. import _config  # noqa: F401  (float64 before any JAX array)
from ._apply import APPLY_ROUTES as APPLY_ROUTES
from ._apply import apply_route as apply_route
from ._batch import CapabilityJob as CapabilityJob
from ._batch import PathUncertaintyBatch as PathUncertaintyBatch
from ._batch import capability_job as capability_job
from ._batch import capability_values as capability_values
from ._batch import fit_study_batch as fit_study_batch
from ._batch import path_uncertainty_batch as path_uncertainty_batch
from ._capability import CapabilityStudy as CapabilityStudy
from ._capability import FeatureCapability as FeatureCapability
from ._capability import capability_from_values as capability_from_values
from ._capability import capability_study as capability_study
from ._coverage import CoverageOptions as CoverageOptions
from ._coverage import CoverageResult as CoverageResult
from ._coverage import coverage_check as coverage_check
from ._decide import DecisionTable as DecisionTable
from ._decide import characteristics as characteristics
from ._decide import decide_features as decide_features
from ._decide import decide_study as decide_study
from ._feedback import FeatureFeedback as FeatureFeedback
from ._feedback import FeedbackResult as FeedbackResult
from ._feedback import FeedbackSettings as FeedbackSettings
from ._feedback import feedback_from_values as feedback_from_values
from ._feedback import feedback_study as feedback_study
from ._feedback_result import feedback_comparison as feedback_comparison
from ._feedback_result import feedback_policy_label as feedback_policy_label
from ._fit import adjust_study_program as adjust_study_program
from ._fit import bayes_study as bayes_study
from ._fit import compensate_study as compensate_study
from ._fit import fit_study as fit_study
from ._fit import inliers as inliers
from ._fit import load_probe_data as load_probe_data
from ._fit import pooled_sigma as pooled_sigma
from ._fit import toolpath_uncertainty as toolpath_uncertainty
from ._init import InitResult as InitResult
from ._init import ToolNose as ToolNose
from ._init import init_study as init_study
from ._init import study_from_program as study_from_program
from ._machine import MACHINE_ROUTES as MACHINE_ROUTES
from ._machine import MachineData as MachineData
from ._machine import error_spec as error_spec
from ._machine import machine_data as machine_data
from ._machine import tool_offsets as tool_offsets
from ._main import JobOptions as JobOptions
from ._main import run_job as run_job
from ._options import bayes_options as bayes_options
from ._options import bayes_sources as bayes_sources
from ._options import decision_settings as decision_settings
from ._options import fit_options as fit_options
from ._options import offset_settings as offset_settings
from ._options import robust_scale as robust_scale
from ._options import sampler_options as sampler_options
from ._options import source_sds as source_sds
from ._plan import FeaturePlan as FeaturePlan
from ._plan import PlannedPoint as PlannedPoint
from ._plan import PlanSettings as PlanSettings
from ._plan import ProbePlan as ProbePlan
from ._plan import feature_fractions as feature_fractions
from ._plan import plan_more as plan_more
from ._plan import plan_study as plan_study
from ._probe_cal import calibrate_probe as calibrate_probe
from ._probe_cal import calibration_points as calibration_points
from ._probe_cal import parse_orders_option as parse_orders_option
from ._probe_radius import approach_directions as approach_directions
from ._probe_radius import calibrated_points as calibrated_points
from ._probe_radius import calibration_warnings as calibration_warnings
from ._probe_radius import lobing_pretravel as lobing_pretravel
from ._probe_radius import radius_components as radius_components
from ._results import InputFile as InputFile
from ._results import JobResults as JobResults
from ._results import package_versions as package_versions
