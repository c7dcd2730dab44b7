"""argparse types for the command line: every number a person types is checked here,
with a message that says what was expected (argparse exits with code 2)."""

from __future__ import annotations

import argparse
import math
from pathlib import Path


def _number(text: str, what: str) -> float:
    try:
        return float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected {what}, got {text!r}") from None


def positive_mm(text: str) -> float:
    """A finite length > 0 (mm)."""
    v = _number(text, "a length in mm")
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0 (mm), got {text!r}")
    return v


def nonneg_mm(text: str) -> float:
    """A finite length >= 0 (mm)."""
    v = _number(text, "a length in mm")
    if not (math.isfinite(v) and v >= 0):
        raise argparse.ArgumentTypeError(f"expected a finite number >= 0 (mm), got {text!r}")
    return v


def finite_mm(text: str) -> float:
    """A finite length (mm), of either sign."""
    v = _number(text, "a length in mm")
    if not math.isfinite(v):
        raise argparse.ArgumentTypeError(f"expected a finite number (mm), got {text!r}")
    return v


def mm_or_file(text: str):
    """A finite length (mm) when it reads as a number, else an existing file's path."""
    try:
        float(text)
    except ValueError:
        if Path(text).is_file():
            return Path(text)
        raise argparse.ArgumentTypeError(
            f"expected a length in mm or an existing file, got {text!r}"
        ) from None
    return finite_mm(text)


def positive_float(text: str) -> float:
    """A finite number > 0."""
    v = _number(text, "a number")
    if not (math.isfinite(v) and v > 0):
        raise argparse.ArgumentTypeError(f"expected a finite number > 0, got {text!r}")
    return v


def gain(text: str) -> float:
    """A compensation gain in [0, 1] (1 = full PIECS mirroring)."""
    v = _number(text, "a gain in [0, 1]")
    if not (math.isfinite(v) and 0.0 <= v <= 1.0):
        raise argparse.ArgumentTypeError(
            f"expected a gain in [0, 1] (1 = full mirroring, 0 = none), got {text!r}"
        )
    return v


def _integer(text: str, low: int) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}") from None
    if v < low:
        raise argparse.ArgumentTypeError(f"expected an integer >= {low}, got {text!r}")
    return v


def positive_int(text: str) -> int:
    """An integer >= 1."""
    return _integer(text, 1)


def nonneg_int(text: str) -> int:
    """An integer >= 0 (a random seed)."""
    return _integer(text, 0)
