"""The one route of a correction to the machine: [`apply_route`][].

A job's correction can reach the machine three ways, and each carries all of it: the
adjusted part program, the error specification (native tables, or LinuxCNC joint
compensation tables that act on every move of a joint) and the tool-offset update (a
constant wear offset of one tool). Loading two of them applies the correction twice,
so [`apply_route`][] returns the one route (of `APPLY_ROUTES`) with why: the command
line's (`--apply`), else the study's (`[compensation] apply`), else the default:
`"program"` when the study names a part program (the most local route: this program
only, nothing left loaded in the controller, the diff shows every change, arcs and
tapers exact), `"errspec"` otherwise (it still carries the shape of the error, a
correction per position, where a tool offset carries only a constant).

The routes, as the user chooses them: docs/formats.md, "Study file".
"""

from __future__ import annotations

from ..errors import InputError
from ..io import APPLY_ROUTES


def apply_route(study, route: str | None = None) -> tuple[str, str]:
    """The route of `study`'s correction to the machine and why it was chosen.

    **Arguments:**

    - `study`: a `Study`.
    - `route`: one of `APPLY_ROUTES` (the command line's `--apply`), or `None` for the
      study's `[compensation] apply`, else the default (see the module doc).

    **Returns:** `(route, why)`, `why` a short phrase for the console and the report.

    **Raises:** `InputError` for an unknown route, and for `"program"` when the study
    names no part program (the message names the key and the study file).
    """
    if route is not None:
        if route not in APPLY_ROUTES:
            raise InputError(
                f"--apply: unknown route {route!r}; expected one of "
                f"{', '.join(map(repr, APPLY_ROUTES))}",
                value=route,
            )
        key, why = "--apply", "chosen with --apply"
    elif study.compensation.apply is not None:
        route = study.compensation.apply
        key, why = "compensation.apply", "the study's [compensation] apply"
    elif study.program is not None:
        return "program", "the default: the study names a part program"
    else:
        return "errspec", "the default: the study names no part program"
    if route == "program" and study.program is None:
        raise InputError(
            f"{key}: 'program', but the study names no part program ([study] part_program); "
            "choose 'errspec', 'tool_offset' or 'none'",
            file=str(study.path),
            value=route,
        )
    return route, why
