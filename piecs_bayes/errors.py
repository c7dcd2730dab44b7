"""Errors a user sees. Each names the offending thing: file, line, column, feature, value."""

from __future__ import annotations

import os


class PiecsError(Exception):
    """Base class of every error piecs_bayes raises on purpose."""


class InputError(PiecsError, ValueError):
    """Bad input: a file, a cell, a setting. The CLI exits with code 2.

    **Arguments:**

    - `message`: what is wrong and what was expected.
    - `file`, `line`, `column`, `feature`, `value`: where, when known. They are
      kept as attributes and prefixed to the message as ``file:line: column 'c':``.
      `file` is a path or a sequence of paths (the probe files of a run, e.g.
      `ProbeData.file`): one is kept as that path, several as a tuple of them all,
      shown as `shown_files` does (more than three: the first, the last and a count).
    """

    def __init__(
        self,
        message: str,
        *,
        file: str | os.PathLike | tuple | list | None = None,
        line: int | None = None,
        column: str | None = None,
        feature: str | None = None,
        value: object = None,
    ):
        if file is not None and not isinstance(file, (str, os.PathLike)):
            names = tuple(str(f) for f in file)
            file = names[0] if len(names) == 1 else names
        self.file = file
        self.line = line
        self.column = column
        self.feature = feature
        self.value = value
        self.reason = message
        where = []
        if file is not None:
            shown = shown_files(file)
            where.append(f"{shown}:{line}" if line is not None else shown)
        elif line is not None:
            where.append(f"line {line}")
        if column is not None:
            where.append(f"column {column!r}")
        if feature is not None:
            where.append(f"feature {feature!r}")
        prefix = ", ".join(where)
        super().__init__(f"{prefix}: {message}" if prefix else message)


def shown_files(file) -> str:
    """A path, or a sequence of paths (the probe files of a run), as a message shows
    it: up to three joined by ", ", more as the first, the last and how many (a name
    may hold a comma: it is never split)."""
    if isinstance(file, (str, os.PathLike)):
        return str(file)
    names = [str(f) for f in file]
    if len(names) <= 3:
        return ", ".join(names)
    return f"{names[0]}, ..., {names[-1]} ({len(names)} files)"


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
