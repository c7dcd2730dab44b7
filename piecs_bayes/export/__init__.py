"""Renders and writes what the jobs return, in four rooms, each with its own face:
`export.report` (the report: HTML, PDF, its vocabulary in `export.report.model`),
`export.figures`, `export.machine` (error-spec files, LinuxCNC tables, tool offsets,
the plan's files) and `export.tables` (CSV, JSON, text). Never re-fits."""

from .. import _config  # noqa: F401  (float64 before any JAX array)
