"""The report's sections, in order: each builds its blocks from a job's results."""

from __future__ import annotations

from ._capability import _capability_section
from ._fit import _budget_section, _posterior_section, _profile_section, _residuals_section
from ._machine import _errspec_section, _program_section
from ._summary import _inputs_section, _summary_section
from ._verdict import verdict_section

#: (id, title) of the report's sections, in order
SECTIONS = (
    ("verdict", "Verdict"),
    ("summary", "Decisions per feature"),
    ("profile", "Profile and adjusted tool path"),
    ("residuals", "Residuals"),
    ("posterior", "Posterior diagnostics"),
    ("budget", "Uncertainty budget"),
    ("capability", "Capability"),
    ("program", "Adjusted part program"),
    ("errspec", "Error specification and tool offsets"),
    ("inputs", "Inputs and reproducibility"),
)


_BUILDERS = {
    "verdict": verdict_section,
    "summary": _summary_section,
    "profile": _profile_section,
    "residuals": _residuals_section,
    "posterior": _posterior_section,
    "budget": _budget_section,
    "capability": _capability_section,
    "program": _program_section,
    "errspec": _errspec_section,
    "inputs": _inputs_section,
}


def _sections(res):
    return [(sid, title, _BUILDERS[sid](res)) for sid, title in SECTIONS]
