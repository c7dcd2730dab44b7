"""ISO 2768-1 general tolerances: the limit deviations a drawing implies where it
gives no tolerance of its own ("general tolerances ISO 2768-m").

[`iso2768_tolerance`][] gives the symmetric limit deviation ±t (mm) of a nominal size
(mm) for a tolerance class f (fine), m (medium), c (coarse) or v (very coarse), from
Table 1 (`table="linear"`: a diameter, a length, an axial position) or Table 2
(`table="radius"`: radii of curvature and chamfer heights), as a [`GeneralTolerance`][]
with the range it was taken from. A range "a-b" holds sizes above a up to and including
b (3 mm is in 0.5-3). Where the standard gives no value (a size below 0.5 mm or above
4000 mm, class f above 2000 mm, class v up to 3 mm) it uses the **nearest range that
has one** and says so in `note`, rather than refusing: the value is a general tolerance
to be replaced by the drawing's, and a study needs one.

The two tables: docs/models/geometry.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: the tolerance classes of ISO 2768-1
ISO2768_CLASSES = ("f", "m", "c", "v")

#: Table 1: upper bounds of the ranges (mm; the first starts at 0.5) and ±t per class
_LINEAR_UPPER = (3.0, 6.0, 30.0, 120.0, 400.0, 1000.0, 2000.0, 4000.0)
_LINEAR = {
    "f": (0.05, 0.05, 0.1, 0.15, 0.2, 0.3, 0.5, None),
    "m": (0.1, 0.1, 0.2, 0.3, 0.5, 0.8, 1.2, 2.0),
    "c": (0.2, 0.3, 0.5, 0.8, 1.2, 2.0, 3.0, 4.0),
    "v": (None, 0.5, 1.0, 1.5, 2.5, 4.0, 6.0, 8.0),
}
#: Table 2: radii of curvature and chamfer heights
_RADIUS_UPPER = (3.0, 6.0, math.inf)
_RADIUS = {
    "f": (0.2, 0.5, 1.0),
    "m": (0.2, 0.5, 1.0),
    "c": (0.4, 1.0, 2.0),
    "v": (0.4, 1.0, 2.0),
}
_LOWEST = 0.5


@dataclass(frozen=True)
class GeneralTolerance:
    """A general tolerance ±`value` (mm) for a nominal `size_mm`.

    `table` is ``"linear"`` (Table 1) or ``"radius"`` (Table 2), `tol_class` the
    class, `low`/`high` the range the value was taken from (mm; `high` is
    ``inf`` for Table 2's last range), `note` why another range than the size's
    own was used (``None`` when it was its own)."""

    value: float
    size_mm: float
    tol_class: str
    table: str
    low: float
    high: float
    note: str | None = None

    @property
    def limits(self) -> tuple[float, float]:
        """``(-value, +value)``."""
        return (-self.value, self.value)

    @property
    def label(self) -> str:
        """``"ISO 2768-m"``."""
        return f"ISO 2768-{self.tol_class}"


def _range_text(low: float, high: float) -> str:
    if math.isinf(high):
        return f">{low:g} mm"
    return f"{low:g}-{high:g} mm" if low == _LOWEST else f">{low:g}-{high:g} mm"


def iso2768_tolerance(size_mm: float, tol_class: str = "m", *, table: str = "linear"):
    """The ISO 2768-1 general tolerance of a nominal size.

    **Arguments:**

    - `size_mm`: the nominal size (mm, >= 0): a diameter, a length, an axial
      position (Table 1) or a radius (Table 2).
    - `tol_class`: ``"f"``, ``"m"``, ``"c"`` or ``"v"`` (``"ISO2768-m"`` is read too).
    - `table`: ``"linear"`` (Table 1) or ``"radius"`` (Table 2).

    **Returns:** a [`GeneralTolerance`][]; where the standard has no value for
    the size in that class, the nearest range's, with a `note` (module doc).

    **Raises:** `ValueError` for an unknown class or table, or a size that is
    not a finite number >= 0.
    """
    cls = str(tol_class).strip()
    if cls.upper().startswith("ISO2768-"):
        cls = cls[len("ISO2768-") :]
    cls = cls.lower()
    if cls not in ISO2768_CLASSES:
        raise ValueError(
            f"unknown ISO 2768 tolerance class {tol_class!r}; expected one of "
            + ", ".join(f"ISO2768-{c}" for c in ISO2768_CLASSES)
        )
    if table not in ("linear", "radius"):
        raise ValueError(f"unknown ISO 2768 table {table!r}; expected 'linear' or 'radius'")
    size = float(size_mm)
    if not (math.isfinite(size) and size >= 0):
        raise ValueError(f"a nominal size must be a finite number >= 0, got {size_mm!r}")
    uppers = _LINEAR_UPPER if table == "linear" else _RADIUS_UPPER
    values = (_LINEAR if table == "linear" else _RADIUS)[cls]
    own = next((i for i, u in enumerate(uppers) if size <= u), None)
    defined = [i for i, v in enumerate(values) if v is not None]
    if own is None:
        pick = defined[-1]
    else:
        pick = min(defined, key=lambda i: (abs(i - own), -i))
    low = _LOWEST if pick == 0 else uppers[pick - 1]
    note = None
    if size < _LOWEST:
        note = f"ISO 2768 gives none below 0.5 mm; the {_range_text(low, uppers[pick])} range's"
    elif pick != own:
        note = (
            f"ISO 2768-{cls} gives none for {size:g} mm; "
            f"the nearest range's ({_range_text(low, uppers[pick])})"
        )
    return GeneralTolerance(float(values[pick]), size, cls, table, low, uppers[pick], note)
