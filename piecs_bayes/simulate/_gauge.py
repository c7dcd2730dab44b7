"""A simulated machine: the gauging program run against a truth part, and the file
the control would write (`simulate_gauge` -> [`GaugeRun`][]).

[`simulate_gauge`][] reads the program's moves as the control would
(`gcode.read_gauge_program`: LinuxCNC or Fanuc; mm, X a radius, the study's part frame)
and the truth (per feature id its deviation, [`read_truth`][]). Along every probe move
the ball's first contact with the deviated profile (`_contact`) trips the probe later by
a normal draw of sd `repeatability` (one per probe move, in program order, from
``numpy.random.default_rng(seed)``) plus the `pretravel` (mm, or a function of the
contact normal's angle: a lobing probe). The control's errors are its messages (an
`AnalysisError` for a G38.2 move without contact, a probe tripped at a move's start or
during a non-probe move); a G38.3 or G31 without contact records its end. [`GaugeRun`][]
holds the trips and the file: LinuxCNC's PROBEOPEN lines (`%f`, X a radius even in G7)
and LOG lines, or Fanuc's DPRNT lines. The machine, move by move:
docs/models/gauging.md."""

from __future__ import annotations

import json
import math
import re
from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from ..errors import AnalysisError, InputError
from ..gcode import GaugeMove, read_gauge_program
from ..io import write_text_atomic
from ._contact import contact_direction, first_contact, piece_distance, truth_pieces

MM_PER_INCH = 25.4
#: mm: a move that starts this close to the part (just after a trip) leaves it; not checked
_LEAVING = 1e-6


@dataclass(frozen=True)
class GaugeTrip:
    """One probe move run: its number among the probe moves (from 1) and move;
    `touched` and the `feature` touched; `contact`, the ball centre at the first
    touch (exact, mm, radius X; None for a miss); `centre`, the position the control
    records (the trip: contact plus `noise` and `pretravel` along the move; the end
    point for a miss); `written`: lines it put in the output file."""

    index: int
    move: GaugeMove
    touched: bool
    feature: str | None
    contact: tuple[float, float] | None
    centre: tuple[float, float]
    noise: float
    pretravel: float
    written: int


@dataclass(frozen=True)
class GaugeRun:
    """A gauging program run on the simulated machine: `trips` in program order and
    `text`, the file the control writes (module docstring); LinuxCNC: `log_text`, the
    ``(LOGOPEN,...)`` file of the program's ``(LOG,...)`` lines (`log_file` its name)."""

    controller: str
    program: str | None
    probe_file: str | None
    x_mode: str
    trips: tuple[GaugeTrip, ...]
    text: str
    log_text: str = ""
    log_file: str | None = None

    @property
    def centres(self) -> np.ndarray:
        """``(n, 2)`` recorded ball centres (mm, radius X), one per probe move."""
        return np.array([t.centre for t in self.trips], dtype=float).reshape(-1, 2)

    def write(self, path, *, protect=()) -> Path:
        """Write `text` to `path` atomically, never over the program or `protect`."""
        keep = [*protect] + ([self.program] if self.program else [])
        return write_text_atomic(path, self.text, protect=keep)

    def write_log(self, path, *, protect=()) -> Path:
        """Write `log_text` (the LOG lines) to `path`, as `write`."""
        keep = [*protect] + ([self.program] if self.program else [])
        return write_text_atomic(path, self.log_text, protect=keep)

    def __repr__(self) -> str:
        hit = sum(t.touched for t in self.trips)
        return (f"GaugeRun({self.controller}, {len(self.trips)} probe moves, {hit} touched, "
                f"{len(self.text.splitlines())} lines)")  # fmt: skip


def _line_of(text: str, *keys: str) -> int | None:
    pos = 0
    for key in keys:
        k = text.find(f'"{key}"', pos)
        if k < 0:
            return None
        pos = k + 1
    return text.count("\n", 0, pos) + 1


def read_truth(source, profile) -> dict[str, np.ndarray]:
    """The truth's deviations (feature id -> vector in `feature.param_names` order,
    mm/rad): a truth.json path (its ``deviations``: per feature id, parameter name
    -> value) or such a mapping. A feature the truth does not name is as drawn; an
    unknown feature or parameter, or a value that is not a finite number, is
    refused naming the file, line and value."""
    name, text = None, ""
    if isinstance(source, (str, Path)):
        name = str(source)
        try:
            text = Path(source).read_text(encoding="utf-8")
        except (OSError, UnicodeDecodeError) as exc:
            raise InputError(f"cannot read the truth file: {exc}", file=name) from None
        try:
            doc = json.loads(text)
        except json.JSONDecodeError as exc:
            raise InputError(f"not JSON: {exc.msg} (column {exc.colno})", file=name,
                             line=exc.lineno) from None  # fmt: skip
        devs = doc.get("deviations") if isinstance(doc, dict) else None
        if not isinstance(devs, dict):
            raise InputError("expected an object 'deviations' (feature id -> parameter -> "
                             "value, as data/demo/truth.json)", file=name)  # fmt: skip
    else:
        devs = source
    out = {}
    for fid, params in devs.items():
        if fid not in profile.ids:
            raise InputError(f"unknown feature id {fid!r}; the profile has "
                             f"{', '.join(profile.ids)}", file=name,
                             line=_line_of(text, fid) if text else None, feature=fid)  # fmt: skip
        f = profile[fid]
        if not isinstance(params, Mapping):
            vec = np.asarray(params, dtype=float).reshape(-1)
            if vec.size != f.nparams:
                raise InputError(f"expected {f.nparams} values {f.param_names}", file=name,
                                 feature=fid)  # fmt: skip
            params = dict(zip(f.param_names, vec, strict=True))
        vec = np.zeros(f.nparams)
        for key, v in params.items():
            line = _line_of(text, fid, key) if text else None
            if key not in f.param_names:
                raise InputError(f"unknown parameter {key!r} of a {f.kind}; expected "
                                 f"{', '.join(f.param_names)}", file=name, line=line,
                                 feature=fid)  # fmt: skip
            ok = isinstance(v, (int, float, np.floating)) and not isinstance(v, bool)
            if not ok or not math.isfinite(float(v)):
                raise InputError(f"{key}: expected a finite number (mm or rad), got {v!r}",
                                 file=name, line=line, feature=fid, value=v)  # fmt: skip
            vec[f.param_names.index(key)] = float(v)
        out[fid] = vec
    return out


_PARAM = re.compile(r"#(\d+)")


def log_line(template: str, rec, touched: bool) -> str:
    """A ``(LOG,...)`` text as LinuxCNC writes it after a probe: each ``#5061``,
    ``#5063`` (the trip's X, a radius, and Z, program units) and ``#5070`` (1 on a
    trip, 0 without) printed with 6 decimals; another parameter is refused."""
    vals = {5061: rec[0], 5062: 0.0, 5063: rec[1], 5070: 1.0 if touched else 0.0}

    def sub(m):
        k = int(m.group(1))
        if k not in vals:
            raise InputError(f"LOG parameter #{k}: the simulated machine knows #5061-#5063 "
                             "and #5070", value=k)  # fmt: skip
        return f"{vals[k]:.6f}"

    return _PARAM.sub(sub, template) + "\n"


def probeopen_line(x: float, z: float) -> str:
    """One line of a LinuxCNC PROBEOPEN file (program units, X a radius)."""
    # LinuxCNC's own printf format, verbatim
    return "%f %f %f %f %f %f %f %f %f\n" % (x, 0.0, z, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0)  # noqa: UP031


def _units(move: GaugeMove) -> float:
    return MM_PER_INCH if move.units == "in" else 1.0


def _fmt(p) -> str:
    return f"X {p[0]:.6f} Z {p[1]:.6f}"


def _where(prog, move: GaugeMove) -> str:
    name = prog.name or "<program>"
    label = f" ({move.label})" if move.label else ""
    return f"{name}:{move.line}: {move.code}{label}"


def _pretravel_of(pretravel, u) -> float:
    if pretravel is None:
        return 0.0
    if callable(pretravel):
        v = float(pretravel(math.atan2(u[0], u[1])))
    else:
        v = float(pretravel)
    if not math.isfinite(v):
        raise InputError(f"pretravel: expected a finite length (mm), got {v!r}", value=v)
    return v


def _touch(pieces, hit, centre) -> np.ndarray:
    """The inward contact normal of the first contact `hit` (a lobing probe's angle)."""
    piece = next(pc for pc in pieces if pc.feature == hit[1])
    return contact_direction(piece, centre)


def _clear_at(pieces, p, r) -> float:
    return min(piece_distance(pc, p) for pc in pieces) - r


def simulate_gauge(
    program,
    study,
    deviations,
    *,
    repeatability: float,
    seed: int | None,
    pretravel: float | Callable[[float], float] | None = None,
    x_mode_fanuc: str | None = None,
) -> GaugeRun:
    """Run the gauging `program` (text or path) on the part of `study` with the
    truth `deviations` (a truth.json path or a mapping, `read_truth`) (module
    docstring).

    - `repeatability`: sd (mm) of the trip along the move; `seed`: of
      ``numpy.random.default_rng``.
    - `pretravel`: mm along the move, or a function of the contact normal's angle (rad,
      ``atan2(u_x, u_z)`` of the unit direction from the ball's centre to the point it
      touches; along the move when the move is normal to the surface) giving mm; None:
      none.
    - `x_mode_fanuc`: a Fanuc control's X mode (``"diameter"``/``"radius"``); None:
      the study's ``[plan] x_mode`` (default diameter). Ignored for LinuxCNC.
    """
    if not (math.isfinite(repeatability) and repeatability >= 0.0):
        raise InputError(f"repeatability: expected a finite sd >= 0 (mm), got {repeatability!r}")
    mode = x_mode_fanuc or dict(study.plan).get("x_mode", "diameter")
    prog = read_gauge_program(program, x_mode=None, controller=None)
    if prog.controller == "fanuc" and mode != prog.x_mode:
        prog = read_gauge_program(program, controller="fanuc", x_mode=mode)
    profile, r = study.profile, float(study.probe.ball_radius)
    pieces = truth_pieces(profile, read_truth(deviations, profile))
    probes = prog.probe_moves
    noise = np.random.default_rng(seed).normal(0.0, 1.0, len(probes)) * repeatability
    trips: list[GaugeTrip] = []
    lines: list[str] = []
    log: list[str] = []
    last: tuple | None = None
    after_probe = False
    pos = None
    known = set()  # the axes whose position is known (programmed absolute)
    for move in prog.moves:
        start = move.start if pos is None else pos
        clear = known >= {"X", "Z"}
        if move.distance == "absolute":
            known |= set(move.axes)
        if move.kind == "probe" and not clear:
            raise InputError(f"{move.code} before X and Z were both programmed: where the "
                             "probe move starts is not known", file=prog.name or "<program>",
                             line=move.line)  # fmt: skip
        if move.kind != "probe":
            _check_travel(prog, move, start, pieces, r, clear, after_probe)
            pos = move.target
            continue
        after_probe = True
        k = len(trips)
        trip = _probe(prog, move, start, pieces, r, float(noise[k]), pretravel, k + 1)
        pos = trip.centre
        written = 0
        if prog.controller == "linuxcnc":
            unit = _units(move)
            rec = (trip.centre[0] / unit, trip.centre[1] / unit)
            if move.recording and rec != last:
                lines.append(probeopen_line(*rec))
                written, last = 1, rec
            log += [log_line(t, rec, trip.touched) for t in move.log]
        else:
            unit = _units(move)
            vals = {5061: trip.centre[0] * (2.0 if prog.x_mode == "diameter" else 1.0) / unit,
                    5062: trip.centre[1] / unit}  # fmt: skip
            for fmt in move.dprnt:
                try:
                    lines.append(fmt.render(vals) + "\n")
                except InputError as exc:
                    raise InputError(exc.reason, file=prog.name or "<program>",
                                     line=fmt.line) from None  # fmt: skip
            written = len(move.dprnt)
        trips.append(replace(trip, written=written))
    return GaugeRun(prog.controller, prog.name, prog.probe_file, prog.x_mode, tuple(trips),
                    "".join(lines), "".join(log), prog.log_file)  # fmt: skip


def _probe(prog, move, start, pieces, r, noise, pretravel, index) -> GaugeTrip:
    a = np.asarray(start, dtype=float)
    b = np.asarray(move.target, dtype=float)
    length = float(np.hypot(*(b - a)))
    u = (b - a) / length
    if _clear_at(pieces, a, r) <= 0.0:
        raise AnalysisError(f"{_where(prog, move)}: Probe is already tripped when starting "
                            f"G38.2 or G38.3 move (the ball touches the part at {_fmt(a)} mm, "
                            "radius)")  # fmt: skip
    hit = first_contact(a, b, pieces, r)
    pre = (
        0.0 if hit is None else _pretravel_of(pretravel, _touch(pieces, hit, a + hit[0] * (b - a)))
    )
    s_trip = None if hit is None else hit[0] + (noise + pre) / length
    if s_trip is not None and s_trip < 0.0:
        raise AnalysisError(f"{_where(prog, move)}: Probe is already tripped when starting "
                            "G38.2 or G38.3 move (the repeatability and pretravel put the "
                            "trip before the move's start)")  # fmt: skip
    if s_trip is None or s_trip > 1.0:
        if move.code == "G38.2":
            why = (
                "touches nothing"
                if hit is None
                else (f"touches feature {hit[1]!r}, but the trip would come after the end")
            )
            raise AnalysisError(f"{_where(prog, move)}: G38.2 move finished without making "
                                f"contact (the ball centre went from {_fmt(a)} to {_fmt(b)} "
                                f"mm, radius, and {why})")  # fmt: skip
        return GaugeTrip(index, move, False, None, None, (float(b[0]), float(b[1])), noise,
                         pre, 0)  # fmt: skip
    contact = a + hit[0] * (b - a)
    centre = contact + (noise + pre) * u
    return GaugeTrip(index, move, True, hit[1], (float(contact[0]), float(contact[1])),
                     (float(centre[0]), float(centre[1])), noise, pre, 0)  # fmt: skip


def _check_travel(prog, move, start, pieces, r, clear, after_probe) -> None:
    """A rapid or feed move: never incremental after a probe, never touching the part."""
    if after_probe and move.distance == "incremental":
        raise InputError(
            f"{move.code} in G91 after a probe move: its end depends on where the probe "
            "tripped; the simulated machine needs G90 there",
            file=prog.name or "<program>",
            line=move.line,
        )
    if not clear or move.kind == "arc" or _clear_at(pieces, start, r) <= _LEAVING:
        return
    hit = first_contact(start, move.target, pieces, r)
    if hit is not None:
        at = np.add(start, hit[0] * np.subtract(move.target, start))
        raise AnalysisError(
            f"{_where(prog, move)}: Probe tripped during non-probe move (the ball touches "
            f"feature {hit[1]!r} at {_fmt(at)} mm, radius)"
        )
