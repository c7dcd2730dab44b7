"""Typed access to a parsed study file (TOML tree) that names the key path
(``profile.feature[2].end``) in every error."""

from __future__ import annotations

import math

from ..errors import InputError


class Reader:
    """Typed access to the TOML tree that names the key path in every error."""

    def __init__(self, file: str):
        self.file = file

    def error(self, key: str, message: str, *, feature=None, value=None) -> InputError:
        return InputError(f"{key}: {message}", file=self.file, feature=feature, value=value)

    def table(self, tree: dict, key: str, path: str, *, required=False) -> dict:
        if key not in tree:
            if required:
                raise self.error(f"{path}{key}", "missing required table")
            return {}
        val = tree[key]
        if not isinstance(val, dict):
            raise self.error(f"{path}{key}", f"expected a table, got {val!r}", value=val)
        return val

    def number(self, tree, key, path, default=None, *, positive=False, nonneg=False, feature=None):
        if key not in tree:
            if default is None:
                raise self.error(f"{path}{key}", "missing required number", feature=feature)
            return default
        val = tree[key]
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise self.error(
                f"{path}{key}", f"expected a number, got {val!r}", feature=feature, value=val
            )
        val = float(val)
        if not math.isfinite(val):
            raise self.error(
                f"{path}{key}", f"expected a finite number, got {val!r}", feature=feature, value=val
            )
        if positive and val <= 0:
            raise self.error(
                f"{path}{key}", f"must be > 0, got {val!r}", feature=feature, value=val
            )
        if nonneg and val < 0:
            raise self.error(
                f"{path}{key}", f"must be >= 0, got {val!r}", feature=feature, value=val
            )
        return val

    def integer(self, tree, key, path, default: int, *, minimum: int = 1) -> int:
        val = tree.get(key, default)
        if isinstance(val, bool) or not isinstance(val, int):
            raise self.error(f"{path}{key}", f"expected an integer, got {val!r}", value=val)
        if val < minimum:
            raise self.error(f"{path}{key}", f"must be >= {minimum}, got {val!r}", value=val)
        return val

    def boolean(self, tree, key, path, default: bool) -> bool:
        val = tree.get(key, default)
        if not isinstance(val, bool):
            raise self.error(
                f"{path}{key}", f"expected true or false (no quotes), got {val!r}", value=val
            )
        return val

    def choice(self, tree, key, path, options, default):
        val = tree.get(key, default)
        if val not in options:
            raise self.error(
                f"{path}{key}",
                f"unknown value {val!r}; expected one of {', '.join(map(repr, options))}",
                value=val,
            )
        return val

    def point(self, tree, key, path, feature):
        if key not in tree:
            raise self.error(f"{path}{key}", "missing required point [x, z]", feature=feature)
        val = tree[key]
        if isinstance(val, dict):
            val = [val.get("x"), val.get("z")]
        if (
            not isinstance(val, list)
            or len(val) != 2
            or any(isinstance(v, bool) or not isinstance(v, (int, float)) for v in val)
        ):
            raise self.error(
                f"{path}{key}",
                f"expected a point [x, z] of two numbers, got {val!r}",
                feature=feature,
                value=val,
            )
        if not all(math.isfinite(v) for v in val):
            raise self.error(
                f"{path}{key}", f"point must be finite, got {val!r}", feature=feature, value=val
            )
        return [float(val[0]), float(val[1])]
