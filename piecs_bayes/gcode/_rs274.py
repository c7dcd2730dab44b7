"""LinuxCNC's standalone interpreter ``rs274`` as a reference: run it, read its canon.

:func:`run_rs274` runs ``rs274 -t tool.tbl -g program.ngc canon.txt`` (Debian package
``linuxcnc-uspace``; FileNotFoundError when it is not installed, see
:func:`rs274_path`) on a program file or text and returns an [`Rs274Result`][]: the
canonical moves ([`CanonMove`][], via :func:`parse_canon`) in mm, radius X, ``(x, z)``
points. Two facts of this standalone build matter: tool-table lengths are read as
**inches** whatever the program's units, and canonical coordinates are printed in the
program's current units with 4 decimals; G3 is ``ARC_FEED`` rotation +1 in the drawing
frame.

How to run it and read its canon: docs/models/nose_compensation.md, "The reference".
"""

from __future__ import annotations

import os
import re
import shutil
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

_CANON = re.compile(r"^\s*\d+\s+N\S*\s+([A-Z_0-9]+)\((.*)\)\s*$")


@dataclass(frozen=True)
class CanonMove:
    """A canonical move: ``kind`` is ``"rapid"``, ``"feed"``, ``"probe"`` or ``"arc"`` (mm,
    radius X); ``y`` the end's Y (mm)."""

    kind: str
    end: tuple[float, float]
    center: tuple[float, float] | None = None
    rotation: int = 0
    y: float = 0.0


@dataclass(frozen=True)
class Rs274Result:
    """Moves, the interpreter's error text (None when it ran to the end) and raw output."""

    moves: tuple[CanonMove, ...]
    error: str | None
    returncode: int
    output: str


def rs274_path() -> str | None:
    """Path of the ``rs274`` executable, or None when LinuxCNC is not installed."""
    return shutil.which("rs274")


def parse_canon(text: str) -> tuple[tuple[CanonMove, ...], list[str]]:
    """Motion canon of ``rs274`` output (mm) and the lines that are not canon calls."""
    moves: list[CanonMove] = []
    other: list[str] = []
    scale = 1.0
    for raw in text.splitlines():
        m = _CANON.match(raw)
        if m is None:
            if raw.strip() and raw.strip() != "executing":
                other.append(raw.strip())
            continue
        name, args = m.group(1), m.group(2)
        if name == "USE_LENGTH_UNITS":
            scale = 25.4 if "INCHES" in args else 1.0
            continue
        if name not in ("STRAIGHT_TRAVERSE", "STRAIGHT_FEED", "STRAIGHT_PROBE", "ARC_FEED"):
            continue
        vals = [float(v) for v in args.split(",")]
        if name == "ARC_FEED":
            z, x, cz, cx, rot, y = vals[:6]  # in the XZ plane: Y is the axis's end point
            end, center = (x * scale, z * scale), (cx * scale, cz * scale)
            moves.append(CanonMove("arc", end, center, int(rot), y * scale))
        else:
            x, y, z = vals[:3]
            kind = {"STRAIGHT_TRAVERSE": "rapid", "STRAIGHT_FEED": "feed"}.get(name, "probe")
            moves.append(CanonMove(kind, (x * scale, z * scale), y=y * scale))
    return tuple(moves), other


def run_rs274(program, *, tool_table=None, timeout: float = 60.0) -> Rs274Result:
    """Run ``rs274 -g`` on a program file (or text) and return its canonical moves.

    **Arguments:**

    - `program`: a path, or the program text (a str holding a newline).
    - `tool_table`: a path, or table text, in rs274's units (inches).
    - `timeout`: seconds.

    Raises FileNotFoundError when ``rs274`` is not installed.
    """
    exe = rs274_path()
    if exe is None:
        raise FileNotFoundError("rs274 (LinuxCNC, Debian package linuxcnc-uspace) is not installed")
    with tempfile.TemporaryDirectory(prefix="piecs-rs274-") as tmp:
        tmp = Path(tmp)
        prog = _materialise(program, tmp / "program.ngc")
        cmd = [exe]
        if tool_table is not None:
            cmd += ["-t", str(_materialise(tool_table, tmp / "tool.tbl"))]
        out = tmp / "canon.txt"
        cmd += ["-g", str(prog), str(out)]
        # rs274 (LinuxCNC 2.9) keeps its tool table in $HOME/.tool.mmap: runs side by
        # side under one HOME read each other's tables (tools not found, SIGBUS), so
        # each run gets its own HOME
        env = {**os.environ, "HOME": str(tmp)}
        proc = subprocess.run(
            cmd,
            cwd=tmp,
            capture_output=True,
            text=True,
            timeout=timeout,
            stdin=subprocess.DEVNULL,
            env=env,
        )
        canon = out.read_text() if out.exists() else ""
    moves, other = parse_canon(canon)
    messages = [ln.strip() for ln in (proc.stdout + "\n" + proc.stderr).splitlines()]
    messages = [ln for ln in messages if ln and ln != "executing"] + other
    error = "\n".join(messages) if (proc.returncode != 0 or messages) else None
    return Rs274Result(moves, error, proc.returncode, canon + proc.stdout + proc.stderr)


def _materialise(src, target: Path) -> Path:
    if isinstance(src, Path) or "\n" not in str(src):
        return Path(src).resolve()
    target.write_text(str(src))
    return target
