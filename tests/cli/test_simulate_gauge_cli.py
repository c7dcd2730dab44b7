"""``piecs-bayes simulate gauge PROGRAM --study --truth --out``: the file, the exit
codes, never over the program; ``simulate demo|batch`` unchanged."""

from __future__ import annotations

import hashlib
from pathlib import Path

from helpers import run_cli as _run

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo"


def _plan(capsys, tmp_path, *extra) -> Path:
    rc, text = _run(capsys, ["plan", DEMO / "study.toml", "--points", "3", "-q",
                             "--out", tmp_path / "plan", *extra])  # fmt: skip
    assert rc == 0, text
    return next(p for p in (tmp_path / "plan").iterdir() if p.suffix in (".ngc", ".nc"))


def test_simulate_gauge_writes_the_probe_file(capsys, tmp_path):
    prog = _plan(capsys, tmp_path)
    out = tmp_path / "probe_points.txt"
    argv = ["simulate", "gauge", prog, "--study", DEMO / "study.toml", "--truth",
            DEMO / "truth.json", "--out", out, "--seed", "4"]  # fmt: skip
    rc, text = _run(capsys, argv)
    assert rc == 0 and f"wrote {out}" in text, text
    lines = out.read_text().splitlines()
    assert len(lines) == 36 and all(len(x.split()) == 9 for x in lines)  # 5 a line, 6 the arc
    before = out.read_text()
    rc, _ = _run(capsys, [*argv, "--repeatability", "0", "--pretravel", "0.002"])
    assert rc == 0 and out.read_text() != before
    # never over the program
    digest = hashlib.sha256(prog.read_bytes()).hexdigest()
    rc, text = _run(capsys, [*argv[:-4], "--out", prog])
    assert rc == 2 and "refusing to overwrite an input file" in text, text
    assert hashlib.sha256(prog.read_bytes()).hexdigest() == digest


def test_simulate_gauge_fanuc_radius(capsys, tmp_path):
    prog = _plan(capsys, tmp_path, "--controller", "fanuc")
    out = tmp_path / "dprnt.txt"
    rc, text = _run(capsys, ["simulate", "gauge", prog, "--study", DEMO / "study.toml",
                             "--truth", DEMO / "truth.json", "--out", out,
                             "--fanuc-x-mode", "radius", "-q"])  # fmt: skip
    assert rc == 0 and text == "", text
    first = out.read_text().splitlines()[0]
    assert first.startswith("X   ") and first[11:13] == " Z", first
    # radius mode reads the program's X25.0 as a radius: the first probe is off the part
    assert float(first[1:11]) > 20.0


def test_a_miss_exits_1_and_bad_input_2(capsys, tmp_path):
    prog = _plan(capsys, tmp_path)
    miss = tmp_path / "miss.json"
    miss.write_text('{"deviations": {"dia_24": {"offset": -0.6, "rotation": 0.0}}}\n')
    base = ["simulate", "gauge", prog, "--study", DEMO / "study.toml", "--out", tmp_path / "o"]
    rc, text = _run(capsys, [*base, "--truth", miss])
    assert rc == 1 and "G38.2 move finished without making contact" in text, text
    assert f"{prog}:" in text and "point 1 dia_24" in text and not (tmp_path / "o").exists()
    # simulate demo|batch as before; a program there is refused
    rc, text = _run(capsys, ["simulate", "demo", prog, "--out", tmp_path / "d"])
    assert rc == 2 and "did you mean 'simulate gauge'" in text, text
