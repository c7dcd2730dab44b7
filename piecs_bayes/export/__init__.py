"""Renders and writes what the jobs return, in four rooms, each with its own face:
`export.report` (the report: HTML, PDF, its vocabulary in `export.report.model`),
`export.figures`, `export.machine` (error-spec files, LinuxCNC tables, tool offsets,
the plan's files) and `export.tables` (CSV, JSON, text); below them `export.raster`
draws figures into PNG, in a helper process where it can. Never re-fits.

Each room imports `_config` (float64) itself; this package does not, so that the
drawing helper (`raster`) starts without JAX."""
