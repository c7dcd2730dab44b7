"""Errors a user sees. Each names the offending thing: file, line, column, feature, value."""

from __future__ import annotations

__all__ = ["PiecsError", "InputError", "AnalysisError"]


class PiecsError(Exception):
    """Base class of every error piecs_bayes raises on purpose."""


class InputError(PiecsError, ValueError):
    """Bad input: a file, a cell, a setting. The CLI exits with code 2.

    **Arguments:**

    - `message`: what is wrong and what was expected.
    - `file`, `line`, `column`, `feature`, `value`: where, when known. They are
      kept as attributes and prefixed to the message as ``file:line: column 'c':``
      (more than three files, comma-joined, as the first, the last and a count).
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | None = None,
        line: int | None = None,
        column: str | None = None,
        feature: str | None = None,
        value: object = None,
    ):
        self.file = file
        self.line = line
        self.column = column
        self.feature = feature
        self.value = value
        self.reason = message
        where = []
        if file is not None:
            shown = _files(str(file))
            where.append(f"{shown}:{line}" if line is not None else shown)
        elif line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {column!r}")
        if feature is not None:
            where.append(f"feature {feature!r}")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


def _files(file: str) -> str:
    """`file` as a message shows it: the probe files of a run (joined by commas,
    `jobs.load_probe_data`) as the first, the last and how many; the `file`
    attribute keeps them all."""
    names = file.split(",")
    return file if len(names) <= 3 else f"{names[0]}, ..., {names[-1]} ({len(names)} files)"


class AnalysisError(PiecsError, RuntimeError):
    """The analysis could not give a trustworthy answer (no convergence, gouge,
    a correction above the limit...). The CLI exits with code 1.

    **Arguments:**

    - `*args`: the message (as for any exception).
    - `result`: what was computed before the analysis gave up (e.g. the
      [`LsqResult`][piecs_bayes.fit.LsqResult] of a fit that did not converge),
      kept as the attribute `result` so that the caller can still look at it;
      `None` when there is nothing to show.
    """

    def __init__(self, *args: object, result: object = None):
        super().__init__(*args)
        self.result = result
