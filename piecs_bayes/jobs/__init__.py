"""The user's jobs: what the CLI and the notebooks call.

Each job composes the numerical layers on a study and returns immutable data;
`piecs_bayes.export` renders and writes it. One part: `load_probe_data`, `fit_study`,
`bayes_study`, `compensate_study`, `toolpath_uncertainty` (`linearised_uncertainty` +
`monte_carlo_uncertainty`), `adjust_study_program`, `decide_study`, `machine_data`; the
main job end to end (`run_job` -> `JobResults`). Many parts: `fit_study_batch`,
capability studies in chunks, in-process or on Dask (`capability_study`),
`path_uncertainty_batch`, `feedback_study`. Also: the coverage
check (`coverage_check`), the study's settings (`fit_options`, ...), a study from a part
program (`init_study`), the probe plan (`plan_study`), a probe's r(theta) (`calibrate_probe`),
the route (`apply_route`), gauge studies (`gauge_type1_study`, `gauge_rr_study`, ...).

Each name is imported when first used (PEP 562): a command pays only for its jobs (`fit`
imports neither the G-code reader nor the batch path). Simulated data: `simulate`.
"""

from __future__ import annotations

import importlib

from .. import _config  # noqa: F401  (float64 before any JAX array)

_EXPORTS = {
    "APPLY_ROUTES": "_apply",
    "apply_route": "_apply",
    "CapabilityJob": "_batch",
    "PathUncertaintyBatch": "_batch",
    "capability_job": "_batch",
    "capability_values": "_batch",
    "fit_study_batch": "_batch",
    "path_uncertainty_batch": "_batch",
    "CapabilityStudy": "_capability",
    "FeatureCapability": "_capability",
    "capability_from_values": "_capability",
    "capability_study": "_capability",
    "CoverageOptions": "_coverage",
    "CoverageResult": "_coverage",
    "coverage_check": "_coverage",
    "DecisionTable": "_decide",
    "characteristics": "_decide",
    "decide_features": "_decide",
    "decide_study": "_decide",
    "GaugeStudyFile": "_gauge_file",
    "read_gauge_study": "_gauge_file",
    "GaugeStudy": "_gauge_study",
    "gauge_rr_study": "_gauge_study",
    "gauge_type1_study": "_gauge_study",
    "Type1Program": "_gauge_program",
    "gauge_type1_program": "_gauge_study",
    "FeatureFeedback": "_feedback",
    "FeedbackResult": "_feedback",
    "FeedbackSettings": "_feedback",
    "feedback_from_values": "_feedback",
    "feedback_study": "_feedback",
    "feedback_comparison": "_feedback_result",
    "feedback_policy_label": "_feedback_result",
    "adjust_study_program": "_fit",
    "bayes_study": "_fit",
    "compensate_study": "_fit",
    "fit_study": "_fit",
    "inliers": "_fit",
    "load_probe_data": "_fit",
    "pooled_sigma": "_fit",
    "toolpath_uncertainty": "_fit",
    "linearised_uncertainty": "_fit",
    "monte_carlo_uncertainty": "_fit",
    "InitResult": "_init",
    "ToolNose": "_init",
    "init_study": "_init",
    "study_from_program": "_init",
    "MACHINE_ROUTES": "_machine",
    "MachineData": "_machine",
    "error_spec": "_machine",
    "machine_data": "_machine",
    "tool_offsets": "_machine",
    "JobOptions": "_main",
    "run_job": "_main",
    "bayes_options": "_options",
    "bayes_sources": "_options",
    "decision_settings": "_options",
    "fit_options": "_options",
    "offset_settings": "_options",
    "robust_scale": "_options",
    "sampler_options": "_options",
    "source_sds": "_options",
    "FeaturePlan": "_plan",
    "PlannedPoint": "_plan",
    "PlanSettings": "_plan",
    "ProbePlan": "_plan",
    "feature_fractions": "_plan",
    "plan_more": "_plan",
    "plan_study": "_plan",
    "UnreachableFeature": "_plan_reach",
    "calibrate_probe": "_probe_cal",
    "calibration_points": "_probe_cal",
    "parse_directions_option": "_probe_cal",
    "parse_orders_option": "_probe_cal",
    "approach_directions": "_probe_radius",
    "calibrated_points": "_probe_radius",
    "calibration_warnings": "_probe_radius",
    "contact_directions": "_probe_radius",
    "lobing_pretravel": "_probe_radius",
    "radius_components": "_probe_radius",
    "InputFile": "_results",
    "JobResults": "_results",
    "package_versions": "_results",
}
__all__ = sorted(_EXPORTS)


def __getattr__(name: str):
    """A public name, imported from its module on first use (then cached here)."""
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    value = getattr(importlib.import_module("." + module, __name__), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
