"""``piecs-bayes simulate gauge PROGRAM --study --truth --out``: the file, the exit
codes, never over the program; ``simulate demo|batch`` unchanged."""

from __future__ import annotations

import hashlib
import re
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
    assert re.search(rf"{re.escape(str(prog))}:\d+: G38\.2 \(point \d+ dia_24 ", text), text
    assert not (tmp_path / "o").exists()
    # simulate demo|batch as before; a program there is refused
    rc, text = _run(capsys, ["simulate", "demo", prog, "--out", tmp_path / "d"])
    assert rc == 2 and "did you mean 'simulate gauge'" in text, text


def test_pretravel_from_a_probe_calibration_is_a_lobing_probe(capsys, tmp_path):
    """`--pretravel probe_cal.json`: each trip comes r(theta) from the surface instead
    of the ball radius; with no noise the diameters' points (approached along -X, 180
    degrees) move out by r(180 deg) - 1 mm, the face's (along -Z, -90 degrees) by
    r(-90 deg) - 1 mm, to the file's 6 decimals."""
    import numpy as np
    from helpers import lobing_probe

    lobing = lobing_probe()
    (tmp_path / "probe_cal.json").write_text(lobing.to_json_text())
    prog = _plan(capsys, tmp_path)
    base = ["simulate", "gauge", prog, "--study", DEMO / "study.toml", "--truth",
            DEMO / "truth.json", "--repeatability", "0", "-q"]  # fmt: skip
    rc, _ = _run(capsys, [*base, "--out", tmp_path / "round.txt"])
    assert rc == 0
    rc, text = _run(capsys, [*base, "--out", tmp_path / "lobing.txt", "--pretravel",
                             tmp_path / "probe_cal.json"])  # fmt: skip
    assert rc == 0, text

    def xz(name):
        return np.loadtxt(tmp_path / name)[:, [0, 2]]

    from piecs_bayes.io import read_plan_points

    shift = xz("lobing.txt") - xz("round.txt")
    feature = np.asarray(read_plan_points(tmp_path / "plan" / "plan.json").feature)
    r = lobing.radius(np.radians([180.0, -90.0])) - 1.0
    dia, face = shift[feature == "dia_24"], shift[feature == "face_end"]
    assert len(dia) == len(face) == 5
    np.testing.assert_allclose(dia, np.tile([r[0], 0.0], (5, 1)), atol=2e-6)
    np.testing.assert_allclose(face, np.tile([0.0, r[1]], (5, 1)), atol=2e-6)
    rc, text = _run(capsys, [*base, "--out", tmp_path / "x.txt", "--pretravel", "nope.json"])
    assert rc == 2 and "expected a length in mm or an existing file" in text, text
