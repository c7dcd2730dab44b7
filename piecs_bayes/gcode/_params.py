"""The parameters of a running part program: numbered, named, local and global.

[`Parameters`][] holds them as the control does. LinuxCNC: ``#1``-``#30`` and
``#<name>`` are local to a subroutine call (the call's arguments are ``#1``..), ``#31``
and up and ``#<_name>`` are global, an unset numbered parameter reads 0 and an unset
name is an error. Fanuc macro B: ``#1``-``#33`` are local to a macro call, ``#100`` and
up are common, ``#0`` and unset ones are vacant (0 in arithmetic). What the control
computes (``#<_x>``, ``#5420``, ``#<_imperial>``, ``#4001``, ...) is read from the modal
state through a callback; whatever has no known value when a program is only read (probe
results, the HAL, timers) is refused by name with a [`ParameterError`][].

Which predefined parameters are read: docs/models/part_programs.md, "Parameters".
"""

from __future__ import annotations

from collections.abc import Callable


class ParameterError(Exception):
    """A parameter that cannot be read or set, with the reason."""


class Parameters:
    """Numbered and named parameters with call scopes (module docstring).

    **Arguments:**

    - `dialect`: ``"linuxcnc"`` or a Fanuc-style name (``"fanuc"``, ``"haas"``, ``"okuma"``).
    - `local`: numbered parameters local to a call: ``#1`` .. ``#local``.
    - `predefined`: ``(ref) -> float | None``: the value of a parameter the control
      computes (a lower-case name such as ``"_x"`` or a number such as 5420), None when
      ``ref`` is not one of them.
    """

    def __init__(self, dialect: str, local: int, predefined: Callable[[object], float | None]):
        self.linuxcnc = dialect == "linuxcnc"
        self.local = local
        self.predefined = predefined
        self.numbered: dict[int, float] = {}
        self.named: dict[str, float] = {}
        self.frames: list[tuple[dict[int, float], dict[str, float]]] = [({}, {})]
        self.special: dict[str, float] = {"_value": 0.0, "_value_returned": 0.0}

    # -- reading ------------------------------------------------------------------------

    def get(self, ref) -> float:
        """The value of ``#ref`` (a number or a lower-case name)."""
        if isinstance(ref, str):
            return self._get_named(ref)
        return self._get_numbered(ref)

    def is_set(self, ref) -> bool:
        """``ref`` holds a value (for Fanuc: is not vacant)."""
        if isinstance(ref, str):
            return self.exists(ref)
        if ref == 0:
            return False
        if 1 <= ref <= self.local:
            return ref in self.frames[-1][0]
        return ref in self.numbered or ref > 999

    def exists(self, ref) -> bool:
        """LinuxCNC's ``EXISTS[#<name>]``."""
        if not isinstance(ref, str):
            return True
        if ref in self.special or (ref.startswith("_") and ref in self.named):
            return True
        if ref in self.frames[-1][1]:
            return True
        try:
            return self.predefined(ref) is not None
        except ParameterError:
            return False

    def _get_named(self, name: str) -> float:
        if name in self.special:
            return self.special[name]
        if name.startswith("_"):
            if name in self.named:
                return self.named[name]
            value = self.predefined(name)
            if value is not None:
                return value
            raise ParameterError(f"named parameter #<{name}> is not set")
        scope = self.frames[-1][1]
        if name in scope:
            return scope[name]
        raise ParameterError(f"named parameter #<{name}> is not set")

    def _get_numbered(self, n: int) -> float:
        if n < 0:
            raise ParameterError(f"parameter #{n} does not exist")
        if n == 0 and not self.linuxcnc:
            return 0.0  # #0: vacant
        if 1 <= n <= self.local:
            return self.frames[-1][0].get(n, 0.0)
        if n in self.numbered:
            return self.numbered[n]
        value = self.predefined(n)
        if value is not None:
            return value
        if self._user(n):
            return 0.0
        raise ParameterError(f"parameter #{n} has no value when a program is only read")

    def _user(self, n: int) -> bool:
        if self.linuxcnc:  # the others of LinuxCNC's 5602 hold 0 unless a file sets them
            return n <= 5601 and not 5061 <= n <= 5070 and n != 5399
        return 100 <= n <= 999 or n == 0

    # -- writing ------------------------------------------------------------------------

    def set(self, ref, value: float) -> None:
        """Set ``#ref`` (named ones starting with ``_`` are global)."""
        if isinstance(ref, str):
            if ref in self.special or (ref.startswith("_") and self.predefined(ref) is not None):
                raise ParameterError(f"#<{ref}> is read-only")
            if ref.startswith("_"):
                self.named[ref] = value
            else:
                self.frames[-1][1][ref] = value
            return
        if 1 <= ref <= self.local:
            self.frames[-1][0][ref] = value
        elif (self._user(ref) or self.linuxcnc and 0 < ref <= 5601) and ref != 0:
            self.numbered[ref] = value  # LinuxCNC: any of its 5602, system ones included
        else:
            raise ParameterError(f"parameter #{ref} cannot be set by a program read here")

    def set_returned(self, value: float | None) -> None:
        """A subroutine returned ``value`` (LinuxCNC ``#<_value>``), or nothing."""
        if value is None:
            self.special["_value_returned"] = 0.0
        else:
            self.special["_value"] = value
            self.special["_value_returned"] = 1.0

    # -- calls --------------------------------------------------------------------------

    def push(self, args: dict[int, float]) -> None:
        """Enter a call: new local numbered (the arguments) and named parameters."""
        for n in args:
            if not 1 <= n <= self.local:
                raise ParameterError(f"argument #{n} is outside #1..#{self.local}")
        self.frames.append((dict(args), {}))
        self.special["_value_returned"] = 0.0

    def pop(self) -> None:
        if len(self.frames) > 1:
            self.frames.pop()

    @property
    def level(self) -> int:
        """The call level (0: the main program)."""
        return len(self.frames) - 1
