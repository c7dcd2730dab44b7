"""A small reader of LinuxCNC G7x programs for the cycle tests (not the package's reader).

It knows what the cycle programs here and the ones LinuxCNC ships use: named
parameters with ``[...]`` arithmetic (``#<_x>``/``#<_z>`` are the current position),
``o.. sub``/``endsub``/``call``/``repeat``, G0-G3, G7/G8, G20/G21, G90.1/G91.1, and the
G70/G71/G72 blocks, whose O-sub it reads into ContourMoves from the cycle's start
point, as rs274 does (R arcs by LinuxCNC's G7x formula, ``A``/``C`` corners).
Compensation, tools, feeds and M codes are skipped.
"""

from __future__ import annotations

import cmath
import re
from dataclasses import dataclass, field

from piecs_bayes.gcode import ContourMove, FinishCycle, RoughCycle, expand_cycle

_PARAM = re.compile(r"#<([_a-z0-9]+)>")


@dataclass
class Cycle:
    code: str
    words: dict
    line: int
    position: tuple[float, float]
    cycle: object
    contour: list
    moves: tuple


@dataclass
class _State:
    params: dict = field(default_factory=dict)
    pos: complex = 0j  # z + i x, program units, radius
    motion: str | None = None
    diameter: bool = False
    inch: bool = False
    ijk_absolute: bool = False


def _clean(text: str) -> str:
    text = re.sub(r"\([^)]*\)", "", text)
    return text.split(";")[0].strip().lower()


def _eval(expr: str, st: _State) -> float:
    def param(m):
        name = m.group(1)
        if name == "_x":
            return repr(st.pos.imag * (2 if st.diameter else 1))
        if name == "_z":
            return repr(st.pos.real)
        return repr(st.params[name])

    e = _PARAM.sub(param, expr).replace("[", "(").replace("]", ")")
    if not re.fullmatch(r"[-+*/(). 0-9e]*", e):
        raise ValueError(f"expression not understood: {expr!r}")
    return float(eval(e, {"__builtins__": {}}))  # noqa: S307 (digits and operators only)


def _words(text: str, st: _State) -> list[tuple[str, float]]:
    out = []
    pos = 0
    text = text.replace(" ", "").replace("\t", "")
    while pos < len(text):
        letter = text[pos]
        pos += 1
        if text[pos] == "[":
            depth, end = 0, pos
            while True:
                depth += {"[": 1, "]": -1}.get(text[end], 0)
                end += 1
                if depth == 0:
                    break
            out.append((letter, _eval(text[pos:end], st)))
        else:
            m = re.match(r"[-+]?[0-9.]+", text[pos:])
            end = pos + m.end()
            out.append((letter, float(text[pos:end])))
        pos = end
    return out


def _g(value: float) -> str:
    return f"G{value:g}"


def read_g7x_program(text: str) -> list:
    """The program's plain moves (``(kind, end_mm)``) and its cycles (expanded), in order."""
    lines = text.splitlines()
    subs: dict[str, list[tuple[int, str]]] = {}
    main: list[tuple[int, str]] = []
    k = 0
    while k < len(lines):
        t = _clean(lines[k])
        m = re.match(r"o(\d+|<[^>]+>)\s*sub", t)
        if m:
            body = []
            k += 1
            while not re.match(rf"o{re.escape(m.group(1))}\s*endsub", _clean(lines[k])):
                body.append((k + 1, lines[k]))
                k += 1
            subs[m.group(1)] = body
        else:
            main.append((k + 1, lines[k]))
        k += 1
    st = _State()
    events: list = []
    _run(main, subs, st, events)
    return events


def _unroll(body, st):
    out, k = [], 0
    while k < len(body):
        n, raw = body[k]
        t = _clean(raw)
        m = re.match(r"o(\d+)\s*repeat\s*(\[.*\])", t)
        if m:
            end = k + 1
            while not re.match(rf"o{m.group(1)}\s*endrepeat", _clean(body[end][1])):
                end += 1
            inner = body[k + 1 : end]
            for _ in range(int(_eval(m.group(2), st))):
                out += inner
            k = end + 1
        else:
            out.append((n, raw))
            k += 1
    return out


def _unit(st):
    return 25.4 if st.inch else 1.0


def _run(body, subs, st: _State, events: list):
    for n, raw in _unroll(body, st):
        t = _clean(raw)
        if not t or t == "%":
            continue
        m = re.match(r"#<([_a-z0-9]+)>\s*=\s*(.*)$", t)
        if m:
            st.params[m.group(1)] = _eval(m.group(2), st)
            continue
        m = re.match(r"o(\d+)\s*call", t)
        if m:
            _run(subs[m.group(1)], subs, st, events)
            continue
        words = _words(t, st)
        gs = [_g(v) for c, v in words if c == "g"]
        w = {c: v for c, v in words if c not in "gm"}
        for g in gs:
            if g in ("G7", "G8"):
                st.diameter = g == "G7"
            if g in ("G20", "G21"):
                st.inch = g == "G20"
            if g in ("G90.1", "G91.1"):
                st.ijk_absolute = g == "G90.1"
        cyc = [g for g in gs if g.split(".")[0] in ("G70", "G71", "G72")]
        if cyc:
            events.append(_cycle(cyc[0], w, n, subs, st))
            continue
        for g in gs:
            if g in ("G0", "G1", "G2", "G3"):
                st.motion = g
        if ("x" in w or "z" in w) and st.motion in ("G0", "G1"):
            x = w["x"] / (2 if st.diameter else 1) if "x" in w else st.pos.imag
            z = w.get("z", st.pos.real)
            st.pos = complex(z, x)
            u = _unit(st)
            events.append(("rapid" if st.motion == "G0" else "feed", (x * u, z * u)))


def _cycle(code, w, n, subs, st) -> Cycle:
    u = _unit(st)
    position = (st.pos.imag * u, st.pos.real * u)
    x = w["x"] / (2 if st.diameter else 1) if "x" in w else st.pos.imag
    z = w.get("z", st.pos.real)
    start = complex(z, x)
    contour = _contour(subs[str(int(w["q"]))], start, st)
    xs = None if "x" not in w else x * u
    zs = None if "z" not in w else z * u
    if code == "G70":
        cycle = FinishCycle(n, xs, zs, w.get("d", 0.0) * u, w.get("e", 0.0) * u, w.get("p", 1.0))
    else:
        cycle = RoughCycle(
            code, n, xs, zs, w.get("d", 0.0) * u, w.get("i", 1.0) * u, w.get("r", 0.5) * u
        )
    moves = expand_cycle(cycle, contour, position, unit_mm=u)
    if moves:
        st.pos = complex(moves[-1].end[1], moves[-1].end[0]) / u
    return Cycle(code, w, n, position, cycle, contour, moves)


def _contour(body, start: complex, st: _State) -> list[ContourMove]:
    u = _unit(st)
    pos = start
    motion = None
    moves = []
    saved = st.pos
    for n, raw in _unroll(body, st):
        t = _clean(raw)
        if not t:
            continue
        st.pos = pos
        words = _words(t, st)
        for c, v in words:
            if c == "g" and _g(v) in ("G0", "G1", "G2", "G3"):
                motion = _g(v)
        w = {c: v for c, v in words if c not in "gm"}
        end = pos
        if "u" in w:
            end = complex(end.real, end.imag + w["u"] / (2 if st.diameter else 1))
        elif "x" in w:
            end = complex(end.real, w["x"] / (2 if st.diameter else 1))
        if "w" in w:
            end = complex(end.real + w["w"], end.imag)
        elif "z" in w:
            end = complex(w["z"], end.imag)
        if end == pos or motion is None:
            continue
        center = None
        if motion in ("G2", "G3"):
            if "r" in w:
                r = w["r"]
                d = cmath.sqrt((r * r - abs(end - pos) ** 2 / 4) / abs(end - pos) ** 2).real
                c = (pos + end) / 2
                c += (1 if motion == "G3" else -1) * 1j * d * (end - pos)
            else:
                c = complex(w.get("k", 0.0), w.get("i", 0.0))
                if not st.ijk_absolute:
                    c += pos
            center = (c.imag * u, c.real * u)
        kind = {"G0": "rapid", "G1": "feed", "G2": "cw", "G3": "ccw"}[motion]
        moves.append(
            ContourMove(
                kind,
                (pos.imag * u, pos.real * u),
                (end.imag * u, end.real * u),
                n,
                center,
                w.get("a", 0.0) * u,
                w.get("c", 0.0) * u,
            )
        )
        pos = end
    st.pos = saved
    return moves
