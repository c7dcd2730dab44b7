"""The gauging program: a probe plan's moves as a program the control runs.

:func:`gauging_program` writes the plan's path (part frame, mm, radius X) as a program
in one of `CONTROLLERS`, one comment block per point under the traceability header:

- **LinuxCNC** (`"linuxcnc"`): G18, G7/G8 (the study's X mode), G20/G21, G90, G40, G94;
  the probe as a tool (``T<n> M6 G43``), the spindle stopped, the probe switched on by
  the configured words (`probe_on`; none by default, and the program says so), probe
  moves ``G38.2`` inside ``(PROBEOPEN <file>)`` ... ``(PROBECLOSE)``, and a
  ``(LOG,<k> #5070 #5061 #5063)`` line after each inside ``(LOGOPEN,<log file>)``.
- **Fanuc** (`"fanuc"`): the same moves with ``G31`` (skip) at ``G98``, ``POPEN`` /
  ``DPRNT[X#5061[44]*Z#5062[44]]`` after each skip / ``PCLOS``, the probe as
  ``T<nn><nn>``, X words as the study's X mode says (a control setting there).

Every move but the probe moves is a rapid. The programs: docs/models/gauging.md.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from ..errors import InputError
from ._header import comment_text
from ._lexer import format_number

CONTROLLERS = ("linuxcnc", "fanuc")
#: the gauging program's file name by controller (beside plan.json)
GAUGING_NAMES = {"linuxcnc": "gauging.ngc", "fanuc": "gauging_fanuc.nc"}
MM_PER_INCH = 25.4


def _coord(v_mm: float, *, x: bool, diameter: bool, inch: bool, decimals: int) -> str:
    v = v_mm * (2.0 if (x and diameter) else 1.0) / (MM_PER_INCH if inch else 1.0)
    return format_number(v, decimals=decimals)


@dataclass(frozen=True)
class GaugingOptions:
    """How the gauging program is written for the control.

    - `controller`: one of `CONTROLLERS`; `units`: `"mm"` or `"in"` (of the program);
      `x_mode`: `"diameter"` or `"radius"`.
    - `tool`, `feed_mm_min`: the probe's tool number and probing feed.
    - `probe_file`, `log_file`: LinuxCNC's probe results and log files.
    - `probe_on`, `probe_off`: the words that switch the probe on and off (`None`: a
      comment says none is configured).
    - `program_number`: Fanuc's `O` number; `decimals`: of the coordinates (default 4
      in mm, 5 in inches).
    """

    controller: str
    units: str
    x_mode: str
    tool: int
    feed_mm_min: float
    probe_file: str = "probe_points.txt"
    log_file: str = "probe_log.txt"
    probe_on: str | None = None
    probe_off: str | None = None
    program_number: int = 9001
    decimals: int | None = None

    def __post_init__(self):
        if self.controller not in CONTROLLERS:
            raise InputError(f"controller: got {self.controller!r}, expected one of {CONTROLLERS}")


def gauging_program(
    home: tuple[float, float],
    path: Sequence[tuple[str, tuple[float, float]]],
    points: Sequence,
    *,
    options: GaugingOptions,
    header: Sequence[str],
) -> str:
    """The program text (module docstring).

    **Arguments:**

    - `home`: the plan's start on the retract line, reached X first, then Z (start the
      program in front of the part, e.g. at the tool-change position);
      `path`: the `(kind, end)` moves from there (`"rapid"` or `"probe"`; part frame,
      mm, radius X).
    - `points`: the plan's points in the same order as its probe moves (for the
      comments).
    - `options`: the control, units, X mode, probe tool and feed, files and codes
      (a [`GaugingOptions`][]).
    - `header`: the traceability texts (one comment line each).
    """
    o = options
    inch, dia = o.units == "in", o.x_mode == "diameter"
    dec = o.decimals if o.decimals is not None else (5 if inch else 4)

    def xz(p):
        return (
            f"X{_coord(p[0], x=True, diameter=dia, inch=inch, decimals=dec)} "
            f"Z{_coord(p[1], x=False, diameter=dia, inch=inch, decimals=dec)}"
        )

    feed = format_number(
        o.feed_mm_min / (MM_PER_INCH if inch else 1.0), decimals=1 if not inch else 3
    )
    fanuc = o.controller == "fanuc"
    out = ["%"]
    if fanuc:
        out.append(f"O{o.program_number:04d} (PIECS GAUGING)")
    out += [f"({comment_text(t)})" for t in header]
    units_g = "G20" if inch else "G21"
    if fanuc:
        out.append(f"G18 {units_g} G40 G90 G98")
        out.append(f"T{o.tool:02d}{o.tool:02d} (PROBE)")
    else:
        out.append(f"G18 {'G7' if dia else 'G8'} {units_g} G40 G90 G94")
        out.append(f"T{o.tool} M6 G43 (probe)")
    out.append("M5 (spindle stopped before any probe move)")
    out.append(o.probe_on if o.probe_on else "(probe on: no code configured, see [plan] probe_on)")
    out.append("POPEN" if fanuc else f"(PROBEOPEN {o.probe_file})")
    if not fanuc:
        out.append(f"(LOGOPEN,{o.log_file})")
    x_home = _coord(home[0], x=True, diameter=dia, inch=inch, decimals=dec)
    z_home = _coord(home[1], x=False, diameter=dia, inch=inch, decimals=dec)
    out += [f"G0 X{x_home} (retract line)", f"G0 Z{z_home}"]
    k = 0
    for kind, p in path:
        if kind == "probe":
            pt = points[k]
            k += 1
            c = pt.contact
            out.append(
                f"({'P' if fanuc else 'point '}{pt.index} {comment_text(pt.feature)} "
                f"t={pt.t:.3f} contact {xz(c)})"
            )
            if fanuc:
                out.append(f"G31 {xz(p)} F{feed}")
                digits = "35" if inch else "44"
                out.append(f"DPRNT[X#5061[{digits}]*Z#5062[{digits}]]")
            else:
                out.append(f"G38.2 {xz(p)} F{feed}")
                out.append(f"(LOG,{pt.index} #5070 #5061 #5063)")
        else:
            out.append(f"G0 {xz(p)}")
    if not fanuc:
        out.append("(LOGCLOSE)")
    out.append("PCLOS" if fanuc else "(PROBECLOSE)")
    out.append(
        o.probe_off if o.probe_off else "(probe off: no code configured, see [plan] probe_off)"
    )
    out.append("M30")
    out.append("%")
    return "\n".join(out) + "\n"
