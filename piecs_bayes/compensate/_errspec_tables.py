"""Error specifications (PIECS option 1) as data: compensation tables and their set.

A [`CompensationTable`][] holds the corrections of one machine axis (mm, added to the
commanded position of the table's `axis`) with their standard uncertainties and the
machine position of `position_axis` where each applies; X positions are radii. An
[`ErrorSpec`][] is a set of tables with metadata. Both validate on construction and
never touch a file: `piecs_bayes.export` writes and reads them (the native JSON + CSV
format, LinuxCNC comp tables).
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..errors import InputError

#: version of the native error-specification format these data classes map onto
ERRSPEC_FORMAT_VERSION = 1
AXES = ("x", "z")
FRAMES = ("machine", "part")
_NAME = re.compile(r"^[A-Za-z0-9][A-Za-z0-9_.-]*$")


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class CompensationTable:
    """Corrections of one machine axis as a function of one axis position.

    **Fields:**

    - `name`: identifier (letters, digits, `_.-`), used in file names.
    - `axis`: corrected machine axis, `"x"` (radius) or `"z"`.
    - `position_axis`: axis whose position indexes the table (the LinuxCNC table
      needs `position_axis == axis`).
    - `position`: positions (mm) of `position_axis` where the corrections apply; X as
      radius. Rows are kept sorted by position (stable).
    - `correction`: mm added to the commanded `axis` position (travelling forward, or
      both ways when no reverse column is given); `u_correction` its standard uncertainty.
    - `correction_reverse`, `u_correction_reverse`: optional, for reverse travel.
    - `feature`: optional feature id per row; `frame`: `"machine"` (default) or
      `"part"` coordinates; `description`: free text.
    """

    name: str
    axis: str
    position_axis: str
    position: np.ndarray
    correction: np.ndarray
    u_correction: np.ndarray
    correction_reverse: np.ndarray | None = None
    u_correction_reverse: np.ndarray | None = None
    feature: tuple[str, ...] | None = None
    frame: str = "machine"
    description: str = ""

    def __post_init__(self):
        if not isinstance(self.name, str) or not _NAME.match(self.name):
            raise InputError(
                f"table name must be letters, digits, '_', '.', '-' (got {self.name!r})",
                value=self.name,
            )
        for attr in ("axis", "position_axis"):
            if getattr(self, attr) not in AXES:
                raise InputError(
                    f"table {self.name!r}: {attr} must be one of {AXES}, got "
                    f"{getattr(self, attr)!r}",
                    value=getattr(self, attr),
                )
        if self.frame not in FRAMES:
            raise InputError(
                f"table {self.name!r}: frame must be one of {FRAMES}, got {self.frame!r}"
            )
        pos = np.asarray(self.position, dtype=float).ravel()
        n = pos.size
        arrays = {"position": pos}
        for attr in ("correction", "u_correction", "correction_reverse", "u_correction_reverse"):
            v = getattr(self, attr)
            if v is None:
                continue
            v = np.asarray(v, dtype=float).ravel()
            if v.size != n:
                raise InputError(
                    f"table {self.name!r}: {attr} has {v.size} values, position has {n}"
                )
            arrays[attr] = v
        if (self.correction_reverse is None) != (self.u_correction_reverse is None):
            raise InputError(
                f"table {self.name!r}: give both correction_reverse and u_correction_reverse"
            )
        for attr, v in arrays.items():
            bad = np.flatnonzero(~np.isfinite(v))
            if bad.size:
                i = int(bad[0])
                raise InputError(
                    f"table {self.name!r}: {attr}[{i}] is {float(v[i])!r}; expected a finite "
                    "number",
                    value=float(v[i]),
                )
            if attr.startswith("u_") and np.any(v < 0):
                i = int(np.flatnonzero(v < 0)[0])
                raise InputError(
                    f"table {self.name!r}: {attr}[{i}] = {float(v[i])!r} is negative",
                    value=float(v[i]),
                )
        feature = self.feature
        if feature is not None:
            feature = tuple(str(f) for f in feature)
            if len(feature) != n:
                raise InputError(f"table {self.name!r}: {len(feature)} feature ids for {n} rows")
        order = np.argsort(pos, kind="stable")
        for attr, v in arrays.items():
            object.__setattr__(self, attr, _ro(v[order]))
        if feature is not None:
            object.__setattr__(self, "feature", tuple(feature[i] for i in order))

    @property
    def directional(self) -> bool:
        """True when reverse travel has its own corrections."""
        return self.correction_reverse is not None

    def __len__(self) -> int:
        return int(self.position.size)

    def __repr__(self) -> str:
        span = f"{self.position[0]:.4g}..{self.position[-1]:.4g}" if len(self) else "empty"
        cmax = float(np.max(np.abs(self.correction))) if len(self) else 0.0
        return (
            f"CompensationTable({self.name!r}, corrects {self.axis} vs {self.position_axis} "
            f"({self.frame}), {len(self)} rows over {span} mm, |c| <= {cmax:.3g} mm"
            f"{', directional' if self.directional else ''})"
        )


@dataclass(frozen=True)
class ErrorSpec:
    """A set of compensation tables with metadata; `units` is always `"mm"` (internal)."""

    tables: tuple[CompensationTable, ...]
    description: str = ""
    source: Mapping[str, Any] = field(default_factory=dict)
    units: str = "mm"

    def __post_init__(self):
        object.__setattr__(self, "tables", tuple(self.tables))
        if self.units != "mm":
            raise InputError(f"error specifications are in mm, got units {self.units!r}")
        names = [t.name for t in self.tables]
        dup = {n for n in names if names.count(n) > 1}
        if dup:
            raise InputError(f"table names must be unique; repeated: {sorted(dup)}")

    def table(self, name: str) -> CompensationTable:
        """The table called `name`."""
        for t in self.tables:
            if t.name == name:
                return t
        raise KeyError(name)

    def __repr__(self) -> str:
        inner = "".join(f"\n  {t!r}" for t in self.tables)
        return f"ErrorSpec({len(self.tables)} table(s), format v{ERRSPEC_FORMAT_VERSION}){inner}"
