"""The report's sections, in order: each builds its blocks from a job's results."""

from __future__ import annotations

from ._capability import capability_section
from ._fit import budget_section, posterior_section, profile_section, residuals_section
from ._machine import errspec_section, program_section
from ._summary import inputs_section, summary_section
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
    "summary": summary_section,
    "profile": profile_section,
    "residuals": residuals_section,
    "posterior": posterior_section,
    "budget": budget_section,
    "capability": capability_section,
    "program": program_section,
    "errspec": errspec_section,
    "inputs": inputs_section,
}


def report_sections(res):
    return [(sid, title, _BUILDERS[sid](res)) for sid, title in SECTIONS]
