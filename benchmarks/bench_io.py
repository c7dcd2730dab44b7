"""Probe CSV and part-program reading speed: the readers and their anchors (issues 16, 38).

    .venv/bin/python benchmarks/bench_io.py                 # 1,000,000 rows
    .venv/bin/python benchmarks/bench_io.py --rows 200000 --repeat 5

Writes a probe CSV of `--rows` rows (the shipped batch's rows, ``part,feature,x,z,
approach_x,approach_z``, repeated under new part ids) to a temporary folder, reads
it once so that it is in the page cache, then times, side by side in this one run:

- `read_probe_csv` (the vectorised fast path), best of `--repeat`;
- `read_probe_csv_by_rows` (the row-by-row reader it replaces), one run (slow);
- `pandas.read_csv` of the same file (no validation: the anchor), best of `--repeat`;
- `jobs.load_probe_data` with the batch study (reading, then the plausibility
  checks: distances, positions, repeated triggers), best of `--repeat`;
- `read_probe_csv` of the same file with one bad cell at row 500,123 (or the
  last row), which must name that row's line exactly as the row reader does,
  best of `--repeat`.

- `gcode.read_gcode` of a LinuxCNC program of `--blocks` executed blocks (25% of them
  in a subroutine called with arguments, its words computed from parameters), beside
  LinuxCNC's `rs274 -g` on the same file (when installed; it also writes its canon).

Prints rows per second of each (wall clock, and CPU time of this process, which a
busy machine disturbs less) and checks that both readers give identical arrays.

And part programs (issue 38): a LinuxCNC lathe program of `--blocks` blocks (100,000) with
subroutine calls and parameters, read by `piecs_bayes.gcode.read_gcode` (target: under 2 s;
skipped with a note while the reader refuses the file) beside LinuxCNC's `rs274 -g` on the
same file (skipped with a note when it is not installed). `--gcode-only` runs just that.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

from piecs_bayes.errors import InputError  # noqa: E402
from piecs_bayes.io import load_study, read_probe_csv  # noqa: E402
from piecs_bayes.io._probe import read_probe_csv_by_rows  # noqa: E402
from piecs_bayes.jobs import load_probe_data  # noqa: E402

BATCH = ROOT / "data" / "batch"


def write_probe_csv(path: Path, rows: int) -> None:
    """`rows` probe triggers: the rows of the shipped batch (data/batch/part*.csv), part
    after part, each repeat under new part ids (so every point passes the batch study's
    plausibility checks and no trigger repeats)."""
    head, body = None, []
    for f in sorted(BATCH.glob("part*.csv")):
        lines = [ln for ln in f.read_text().splitlines() if ln and not ln.startswith("#")]
        head = lines[0]
        body += [ln.split(",", 1)[1] for ln in lines[1:]]
    out = ["# Simulated for benchmarks/bench_io.py from data/batch", head]
    k = 0
    while len(out) < rows + 2:
        out += [f"p{k:06d},{r}" for r in body]
        k += 1
    path.write_text("\n".join(out[: rows + 2]) + "\n")


def best(fn, repeat: int) -> tuple[float, float]:
    """The best wall-clock and the best CPU seconds (this process) of `repeat` runs."""
    wall, cpu = [], []
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        fn()
        wall.append(time.perf_counter() - t0)
        cpu.append(time.process_time() - c0)
    return min(wall), min(cpu)


def probeopen_times(tmp: Path, rows: int, repeat: int, pd):
    """`read_control_probe` of a `rows`-line LinuxCNC PROBEOPEN file against a plan of
    as many points (the ball centres 1-5 um off the planned ones), and pandas."""
    import numpy as np

    from piecs_bayes.io import PlanPoints, read_control_probe

    rng = np.random.default_rng(1)
    centre = np.column_stack([rng.uniform(5, 25, rows), rng.uniform(-90, 0, rows)])
    approach = np.tile([-1.0, 0.0], (rows, 1))
    plan = PlanPoints("plan.json", "mm", ("dia",) * rows, centre, approach, centre - 0.5 * approach)
    got = centre + rng.normal(0.0, 0.003, centre.shape)
    path = tmp / "probe_points.txt"
    path.write_text("".join(f"{x:f} 0.000000 {z:f} 0.000000 0.000000 0.000000 0.000000 "
                            "0.000000 0.000000\n" for x, z in got))  # fmt: skip
    path.read_bytes()
    t = best(lambda: read_control_probe(path, "linuxcnc", plan), repeat)
    t_pd = best(lambda: pd.read_csv(path, sep=" ", header=None), repeat)
    back = read_control_probe(path, "linuxcnc", plan)
    assert np.allclose(back.points, np.round(got, 6), rtol=0, atol=1e-12)
    return t, t_pd


def write_gcode_program(path: Path, blocks: int) -> None:
    """A LinuxCNC lathe program of `blocks` lines (mm, diameter X): a named global and a
    named local parameter, a subroutine of two moves taking two arguments, then blocks that
    set a parameter, call the subroutine with it, move with an expression, and rapid back,
    in turn (every second block moves the tool; each call makes two moves more)."""
    head = [
        f"(benchmarks/bench_io.py: {blocks} blocks, subroutine calls and parameters)",
        "G18 G21 G7 G90 G95",
        "#<_step> = 0.05",
        "#<depth> = 0.5",
        "o100 sub",
        "  G1 X[#1] Z[#2]",
        "  G1 Z[#2 - 0.5]",
        "o100 endsub",
        "T1 M6",
        "S800 M3",
        "F0.1",
        "G0 X60 Z2",
    ]
    body = []
    for k in range(blocks - len(head) - 1):
        kind = k % 4
        if kind == 0:
            body.append(f"#<x> = [40 + {k % 50} * #<_step>]")
        elif kind == 1:
            body.append(f"o100 call [#<x>] [{-(k % 200) * 0.1:.1f}]")
        elif kind == 2:
            body.append(f"G1 X[#<x> + #<depth>] Z{-(k % 200) * 0.1 - 1:.1f}")
        else:
            body.append("G0 X60 Z2")
    path.write_text("\n".join([*head, *body, "M2"]) + "\n")


def gcode_times(tmp: Path, blocks: int, repeat: int) -> dict:
    """`read_gcode` and `rs274 -g` on a `blocks`-block program: {name: (wall, cpu) or a note}.
    rs274 runs with a HOME of its own (it keeps its tool table in $HOME/.tool.mmap, which
    two runs at once would share)."""
    import shutil
    import subprocess

    from piecs_bayes.gcode import read_gcode

    path = tmp / "big.ngc"
    write_gcode_program(path, blocks)
    path.read_bytes()  # page cache
    out: dict = {"size": path.stat().st_size}
    try:
        program = read_gcode(path)
    except InputError as exc:
        out["read_gcode"] = f"skipped: read_gcode refuses the file today ({exc})"
    else:
        out["read_gcode"] = best(lambda: read_gcode(path), repeat)
        out["moves"] = len(program.moves)
    exe = shutil.which("rs274")
    if exe is None:
        out["rs274"] = "skipped: rs274 is not installed (Debian package linuxcnc-uspace)"
        return out
    home = tmp / "home"
    home.mkdir(exist_ok=True)
    env = {**os.environ, "HOME": str(home)}

    def rs274():
        return subprocess.run(
            [exe, "-g", str(path), str(tmp / "canon.txt")],
            cwd=tmp, env=env, capture_output=True, text=True, stdin=subprocess.DEVNULL,
        )  # fmt: skip

    proc = rs274()
    messages = [ln for ln in (proc.stdout + proc.stderr).splitlines() if ln.strip() != "executing"]
    if proc.returncode != 0 or messages:
        out["rs274"] = f"skipped: rs274 stops: {' / '.join(messages)[:200]}"
        return out
    canon = (tmp / "canon.txt").read_text()
    out["rs274_moves"] = sum(canon.count(k) for k in ("STRAIGHT_FEED(", "STRAIGHT_TRAVERSE("))
    wall, cpu = [], []
    for _ in range(repeat):  # rs274's time is the child's: wall clock and its CPU time
        t0, c0 = time.perf_counter(), os.times()
        rs274()
        c1 = os.times()
        wall.append(time.perf_counter() - t0)
        cpu.append(c1.children_user + c1.children_system - c0.children_user - c0.children_system)
    out["rs274"] = (min(wall), min(cpu))
    return out


def print_gcode_times(t: dict, blocks: int) -> None:
    print()
    print(f"part program: {blocks:,} blocks ({t['size'] / 1e6:.1f} MB), subroutine calls and "
          "parameters (LinuxCNC)")  # fmt: skip
    print("| reader | wall s | blocks/s | CPU s |")
    print("|---|---:|---:|---:|")
    for name in ("read_gcode", "rs274"):
        v = t[name]
        label = "piecs_bayes.gcode.read_gcode" if name == "read_gcode" else "rs274 -g (LinuxCNC)"
        if isinstance(v, str):
            print(f"| {label} | - | - | - |")
            print(f"  {label}: {v}")
        else:
            print(f"| {label} | {v[0]:.3f} | {blocks / v[0]:,.0f} | {v[1]:.3f} |")
    if "rs274_moves" in t:
        print(f"rs274: {t['rs274_moves']:,} straight moves in its canon")
    if not isinstance(t["read_gcode"], str):
        verdict = "met" if t["read_gcode"][0] < 2.0 else "MISSED"
        print(f"read_gcode: {t['moves']:,} moves; target under 2 s: {verdict}")
        if not isinstance(t["rs274"], str):  # the same run: the machine's speed cancels out
            ratio = t["read_gcode"][0] / t["rs274"][0]
            print(f"read_gcode / rs274 on the same file, same run: {ratio:.2f}x")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=1_000_000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--no-rows-reader", action="store_true", help="skip the slow row reader")
    ap.add_argument("--blocks", type=int, default=100_000, help="blocks of the part program")
    ap.add_argument("--gcode-only", action="store_true", help="time only the part program")
    args = ap.parse_args()
    if args.gcode_only:
        with tempfile.TemporaryDirectory() as tmp:
            print_gcode_times(gcode_times(Path(tmp), args.blocks, args.repeat), args.blocks)
        return
    import pandas as pd

    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "probe_big.csv"
        t0 = time.perf_counter()
        write_probe_csv(path, args.rows)
        size = path.stat().st_size
        print(f"wrote {args.rows:,} rows ({size / 1e6:.1f} MB) in {time.perf_counter() - t0:.1f} s")
        path.read_bytes()  # page cache

        study = load_study(BATCH / "study.toml")
        kw = {"x_mode": study.probe.x_mode, "features": study.profile.ids}

        def fast():
            return read_probe_csv(path, **kw)

        t_fast = best(fast, args.repeat)
        t_pd = best(lambda: pd.read_csv(path, comment="#"), args.repeat)
        load_probe_data(study, [path])  # the plausibility checks' JAX code traced
        t_load = best(lambda: load_probe_data(study, [path]), args.repeat)
        t_rows = None
        if not args.no_rows_reader:
            t0, c0 = time.perf_counter(), time.process_time()
            ref = read_probe_csv_by_rows(path, **kw)
            t_rows = time.perf_counter() - t0, time.process_time() - c0
            got = fast()
            for f in ("feature", "points", "lines", "part", "approach"):
                a, b = getattr(got, f), getattr(ref, f)
                assert a.dtype == b.dtype and a.shape == b.shape, f
                assert a.tolist() == b.tolist() if a.dtype.kind == "U" else (
                    a.tobytes() == b.tobytes()
                ), f  # fmt: skip
            print("fast path and row reader: identical arrays")

        bad_row = min(500_123, args.rows)
        text = path.read_text().split("\n")
        line = bad_row + 2  # a comment and the header come first
        cells = text[line - 1].split(",")
        cells[2] = "26.0O5"  # a letter O for a zero
        text[line - 1] = ",".join(cells)
        bad = Path(tmp) / "probe_bad.csv"
        bad.write_text("\n".join(text))
        msg = "no error"

        def fails():
            nonlocal msg
            try:
                read_probe_csv(bad, **kw)
            except InputError as exc:
                msg = str(exc)

        t_bad = best(fails, args.repeat)
        assert f"probe_bad.csv:{line}," in msg, msg

        t_cnc, t_cnc_pd = probeopen_times(Path(tmp), args.rows, args.repeat, pd)
        t_gcode = gcode_times(Path(tmp), args.blocks, args.repeat)

    n = args.rows

    def row(name, t):
        print(f"| {name} | {t[0]:.3f} | {n / t[0]:,.0f} | {t[1]:.3f} | {n / t[1]:,.0f} |")

    print()
    print("| reader | wall s | rows/s | CPU s | rows/CPU-s |")
    print("|---|---:|---:|---:|---:|")
    row("read_probe_csv (fast path, validated)", t_fast)
    if t_rows is not None:
        row("read_probe_csv_by_rows (row reader)", t_rows)
    row("pandas.read_csv (anchor, no checks)", t_pd)
    row("jobs.load_probe_data (read + plausibility)", t_load)
    row(f"read_probe_csv, bad cell at row {bad_row:,}", t_bad)
    row("read_control_probe, LinuxCNC PROBEOPEN file (against its plan)", t_cnc)
    row("pandas.read_csv of that file (sep=' ', no checks)", t_cnc_pd)
    print()
    print(f"bad cell: {msg}")
    if t_rows is not None:
        print(f"fast path / row reader: {t_rows[0] / t_fast[0]:.1f}x wall")
    print(f"fast path / pandas.read_csv: {t_pd[0] / t_fast[0]:.2f}x wall (>1: faster than pandas)")
    print_gcode_times(t_gcode, args.blocks)
    print(f"load average {os.getloadavg()[0]:.2f} (1 min), {os.cpu_count()} CPUs")


if __name__ == "__main__":
    main()
