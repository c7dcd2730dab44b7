"""Figures of a job's results (matplotlib): profile, residuals, posterior, budget,
capability, feedback, probe calibration, gauge studies."""

from ... import _config  # noqa: F401  (float64 before any JAX array)
from ._base import RC as RC
from ._base import param_unit as param_unit
from ._budget import budget_figure as budget_figure
from ._capability import capability_chart_figure as capability_chart_figure
from ._capability import capability_index_figure as capability_index_figure
from ._feedback import feedback_figures as feedback_figures
from ._feedback import feedback_policy_figure as feedback_policy_figure
from ._feedback import feedback_track_figure as feedback_track_figure
from ._gauge import grr_figure as grr_figure
from ._gauge import type1_run_chart_figure as type1_run_chart_figure
from ._posterior import corner_feature as corner_feature
from ._posterior import corner_figure as corner_figure
from ._posterior import diagnostics_figure as diagnostics_figure
from ._posterior import trace_figure as trace_figure
from ._probe import probe_calibration_figure as probe_calibration_figure
from ._profile import auto_exaggeration as auto_exaggeration
from ._profile import offset_figure as offset_figure
from ._profile import profile_figure as profile_figure
from ._residuals import residuals_figure as residuals_figure
