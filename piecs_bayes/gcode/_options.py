"""How a part program is read: the dialect and the state before its first block.

[`ReadOptions`][] travels with every read program (``GcodeProgram.options``) so that an
edited copy is read alike; [`ReadOptions.resolved`][] fills what was left to the dialect
(diameter or radius X, the machine zero).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

from ..errors import InputError
from ._dialect import DIALECTS, dialect_table

#: executed blocks after which a program is taken for an endless loop
STEP_LIMIT = 1_000_000


@dataclass(frozen=True)
class ReadOptions:
    """Settings of a read (all keyword, all optional).

    - `dialect`: ``"linuxcnc" | "fanuc" | "haas" | "okuma"``; None: detected from the
      program (``GcodeProgram.dialect`` says which and why).
    - `units`: ``"mm"`` or ``"in"`` before the first G20/G21 (default mm).
    - `diameter_mode`: X words are diameters before the first G7/G8; None: the
      dialect's (LinuxCNC radius, Fanuc/Haas/Okuma diameter).
    - `start`: the tool position ``(x, z)`` (mm, radius) before the first move
      (``(0, 0)``, where LinuxCNC's standalone ``rs274`` starts).
    - `step_limit`: executed blocks after which a loop is taken for endless.
    - `block_delete`: skip the lines that begin with ``/`` (the switch on); default
      off: they run, as on a control whose block-delete switch is off.
    - `machine_zero`: where the machine zero lies in the program's coordinates (mm,
      radius), for G28/G30/G53; None: LinuxCNC's ``(0, 0)`` (``rs274`` with no offsets),
      unknown for the other dialects (a reference return leaves the position unknown).
    """

    dialect: str | None = None
    units: str = "mm"
    diameter_mode: bool | None = None
    start: tuple[float, float] = (0.0, 0.0)
    step_limit: int = STEP_LIMIT
    block_delete: bool = False
    machine_zero: tuple[float, float] | None = None

    def __post_init__(self):
        if self.dialect is not None and self.dialect not in DIALECTS:
            raise InputError(
                f"dialect: got {self.dialect!r}, expected one of {', '.join(DIALECTS)}"
            )
        if self.units not in ("mm", "in"):
            raise InputError(f"units must be 'mm' or 'in', got {self.units!r}")
        if not (isinstance(self.step_limit, int) and self.step_limit > 0):
            raise InputError(f"step_limit must be a whole number > 0, got {self.step_limit!r}")
        start = tuple(float(v) for v in self.start)
        if len(start) != 2 or not all(math.isfinite(v) for v in start):
            raise InputError(f"start must be two finite numbers (x, z), got {self.start!r}")
        object.__setattr__(self, "start", start)
        if self.machine_zero is not None:
            object.__setattr__(self, "machine_zero", tuple(float(v) for v in self.machine_zero))

    def resolved(self, dialect: str) -> ReadOptions:
        """These options with the dialect named and its defaults filled in."""
        table = dialect_table(dialect)
        diameter = table.diameter if self.diameter_mode is None else self.diameter_mode
        zero = self.machine_zero
        if zero is None and dialect == "linuxcnc":
            zero = (0.0, 0.0)
        return replace(self, dialect=dialect, diameter_mode=diameter, machine_zero=zero)
