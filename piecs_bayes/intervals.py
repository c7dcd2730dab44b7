"""A two-sided interval of a statistic: [`Interval`][], shared by the capability
indices (`capability`) and the measuring-system analysis (`msa`), which compute
their bounds each by their own methods."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Interval:
    """A two-sided interval `[lower, upper]` at probability/confidence `level`."""

    lower: float
    upper: float
    level: float

    def __iter__(self):
        return iter((self.lower, self.upper))

    def __contains__(self, value: float) -> bool:
        return self.lower <= value <= self.upper

    def __repr__(self) -> str:
        return f"[{self.lower:.4g}, {self.upper:.4g}] ({self.level:.0%})"

    def scaled(self, factor: float) -> Interval:
        """The interval of `factor` times the quantity (`factor` > 0)."""
        return Interval(self.lower * factor, self.upper * factor, self.level)

    def sqrt(self) -> Interval:
        """The interval of the square root (a variance's interval -> its sd's)."""
        return Interval(float(np.sqrt(self.lower)), float(np.sqrt(self.upper)), self.level)

    def as_dict(self) -> dict:
        return {"lower": self.lower, "upper": self.upper, "level": self.level}
