"""Probe files as the controls write them, read against the plan (issue 26): a
LinuxCNC PROBEOPEN file and the same points as a CSV give identical fits; Fanuc
DPRNT lines; every refusal with its message."""

from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.export.machine import plan_json
from piecs_bayes.io import load_study, read_control_probe, read_plan_points
from piecs_bayes.jobs import fit_study, load_probe_data, plan_study
from piecs_bayes.simulate import DEMO_ERRORS, process_deviations, simulate_probe

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"


@pytest.fixture(scope="module")
def gauged(tmp_path_factory):
    """The demo part in the work frame (z_offset 0), probed at a 5-point plan: the
    plan, the ball centres in plan order (mm, radius, rounded as LinuxCNC prints)."""
    tmp = tmp_path_factory.mktemp("gauge")
    text = DEMO.read_text().replace("z_offset = -312.4873", "z_offset = 0.0")
    (tmp / "study.toml").write_text(text)
    study = load_study(tmp / "study.toml")
    plan = plan_study(study, points=5)
    (tmp / "plan.json").write_text(plan_json(plan))
    truth = process_deviations(study.profile, DEMO_ERRORS)
    fr = {fid: [p.t for p in plan.points if p.feature == fid] for fid in study.profile.ids}
    sim = simulate_probe(
        study.profile, truth, ball_radius=study.probe.ball_radius, transform=study.transform,
        points={k: np.array(v) for k, v in fr.items()}, noise_sd=study.probe.repeatability, rng=3,
    )  # fmt: skip
    # back into the plan's order
    take = {fid: iter(np.flatnonzero(sim["feature"] == fid)) for fid in study.profile.ids}
    order = [next(take[p.feature]) for p in plan.points]
    centres = np.round(sim["points"][order], 6)
    return tmp, study, plan, centres


def _linuxcnc(path: Path, centres) -> Path:
    path.write_text("".join(f"{x:f} 0.000000 {z:f} 0.000000 0.000000 0.000000 0.000000 "
                            "0.000000 0.000000\n" for x, z in centres))  # fmt: skip
    return path


def _study(tmp, name, fmt, probe_file, extra=""):
    text = (tmp / "study.toml").read_text()
    text = text.replace('probe_files = ["probe_part01.csv"]', f'probe_files = ["{probe_file}"]')
    if fmt != "csv":
        text = text.replace("[profile]", f'probe_format = "{fmt}"\nprobe_plan = "plan.json"\n'
                                         f"{extra}\n[profile]", 1)  # fmt: skip
    (tmp / name).write_text(text)
    return load_study(tmp / name)


def test_a_probeopen_file_and_the_same_csv_give_identical_fits(gauged):
    tmp, study, plan, centres = gauged
    _linuxcnc(tmp / "part.txt", centres)
    rows = ["feature,x,z,approach_x,approach_z"] + [
        f"{p.feature},{2 * c[0]:.6f},{c[1]:.6f},{p.approach[0]!r},{p.approach[1]!r}"
        for p, c in zip(plan.points, centres, strict=True)
    ]
    (tmp / "part.csv").write_text("\n".join(rows) + "\n")
    a = fit_study(_study(tmp, "a.toml", "linuxcnc", "part.txt"))
    b = fit_study(_study(tmp, "b.toml", "csv", "part.csv"))
    for fid in study.profile.ids:
        np.testing.assert_allclose(a[fid].values, b[fid].values, rtol=0, atol=1e-15)
        np.testing.assert_allclose(a[fid].covariance, b[fid].covariance, rtol=1e-12, atol=0)
    probe = load_probe_data(_study(tmp, "a.toml", "linuxcnc", "part.txt"))
    assert list(probe.feature) == [p.feature for p in plan.points]
    np.testing.assert_allclose(probe.approach, [p.approach for p in plan.points], atol=1e-9)
    assert list(probe.lines) == list(range(1, plan.n_points + 1))


@pytest.mark.parametrize("x_mode", ["diameter", "radius"])
def test_fanuc_dprnt_lines_are_read_as_the_control_prints_them(gauged, x_mode):
    tmp, study, plan, centres = gauged
    xs = 2.0 if x_mode == "diameter" else 1.0
    lines = [f"X{xs * x:10.4f} Z{z:10.4f}" for x, z in centres]  # [44]: spaces for zeros
    (tmp / "dprnt.txt").write_text("\n".join(lines) + "\n")
    pl = read_plan_points(tmp / "plan.json")
    got = read_control_probe(tmp / "dprnt.txt", "fanuc-dprnt", pl, x_mode=x_mode)
    np.testing.assert_allclose(got.points, centres, rtol=0, atol=0.5e-4 + 1e-12)  # 4 decimals


def _refused(tmp, study_plan, lines, fmt="linuxcnc", **kw):
    (tmp / "bad.txt").write_text("".join(lines))
    with pytest.raises(InputError) as exc:
        read_control_probe(tmp / "bad.txt", fmt, study_plan, **kw)
    return str(exc.value)


def test_each_refusal_names_the_file_the_line_and_the_point(gauged):
    tmp, study, plan, centres = gauged
    pl = read_plan_points(tmp / "plan.json")
    good = _linuxcnc(tmp / "good.txt", centres).read_text().splitlines(keepends=True)
    # fewer points than the plan
    msg = _refused(tmp, pl, good[:-1])
    assert f"35 probe points in the file, the plan plan.json has {plan.n_points}" in msg
    # a truncated line
    msg = _refused(tmp, pl, good[:3] + [" ".join(good[3].split()[:4]) + "\n"] + good[4:])
    assert re.search(r"bad\.txt:4: not a LinuxCNC probe line: \d numbers, expected nine", msg), msg
    # comma decimals
    msg = _refused(tmp, pl, good[:2] + [good[2].replace(".", ",", 1)] + good[3:])
    assert "bad.txt:3: not a LinuxCNC probe line:" in msg and "is not a number" in msg
    # an extra column
    msg = _refused(tmp, pl, good[:5] + [good[5].rstrip("\n") + " 1.0\n"] + good[6:])
    assert "bad.txt:6: not a LinuxCNC probe line: 10 numbers" in msg
    # a failed probe: the position is the programmed target
    t = plan.points[6].target
    failed = f"{t[0]:f} 0 {t[1]:f} 0 0 0 0 0 0\n"
    msg = _refused(tmp, pl, good[:6] + [failed] + good[7:])
    assert "bad.txt:7" in msg and "point 7 of the plan" in msg and "failed probe" in msg
    # X and Z swapped on one line: far from the planned centre
    x, z = centres[9]
    msg = _refused(tmp, pl, good[:9] + [f"{z:f} 0 {x:f} 0 0 0 0 0 0\n"] + good[10:])
    assert "bad.txt:10" in msg and "point 10 of the plan" in msg and "mm from it" in msg
    # a touch repeated: every line after it is the next point's
    msg = _refused(tmp, pl, good[:12] + [good[11]] + good[12:-1])
    assert "bad.txt:13" in msg and "point 13 of the plan" in msg
    # a diameter written where a radius is expected (LinuxCNC writes radii)
    doubled = [f"{2 * x:f} 0 {z:f} 0 0 0 0 0 0\n" for x, z in centres]
    msg = _refused(tmp, pl, doubled)
    assert "bad.txt:1" in msg and "mm from it" in msg


def test_the_study_keys_are_checked(gauged):
    tmp, study, plan, centres = gauged
    text = (tmp / "study.toml").read_text()
    (tmp / "k1.toml").write_text(
        text.replace("[profile]", 'probe_format = "linuxcnc"\n\n[profile]', 1)
    )
    with pytest.raises(InputError, match=r"study\.probe_plan: missing: probe_format 'linuxcnc'"):
        load_study(tmp / "k1.toml")
    (tmp / "k2.toml").write_text(
        text.replace("[profile]", 'probe_format = "heidenhain"\n\n[profile]', 1)
    )
    with pytest.raises(InputError, match=r"study\.probe_format: unknown value 'heidenhain'"):
        load_study(tmp / "k2.toml")
    (tmp / "k3.toml").write_text(
        DEMO.read_text().replace("[profile]", 'probe_format = "linuxcnc"\nprobe_plan = "p.json"\n\n[profile]', 1)
    )  # fmt: skip
    with pytest.raises(InputError, match=r"machine\.z_offset: -312\.487 mm with probe_format"):
        load_study(tmp / "k3.toml")
    # the plan of another study (its own probe file: tests of this module may run
    # on other workers)
    _linuxcnc(tmp / "k4.txt", centres)
    other = _study(tmp, "k4.toml", "linuxcnc", "k4.txt")
    body = (tmp / "plan.json").read_text().replace('"feature": "fillet"', '"feature": "round"')
    (tmp / "other.json").write_text(body)
    with pytest.raises(InputError, match="names feature.s. 'round'"):
        load_probe_data(replace(other, probe_plan=tmp / "other.json"))


def test_the_log_lines_of_the_plan_s_program_are_read_and_checked(gauged):
    """`linuxcnc-log`: '<point> <#5070> <X> <Z>' per probe, as the program's
    (LOG,k #5070 #5061 #5063) prints it; the same points as the PROBEOPEN file."""
    tmp, study, plan, centres = gauged
    pl = read_plan_points(tmp / "plan.json")
    log = [f"{k} 1.000000 {x:.6f} {z:.6f}\n" for k, (x, z) in enumerate(centres, start=1)]
    (tmp / "log.txt").write_text("".join(log))
    got = read_control_probe(tmp / "log.txt", "linuxcnc-log", pl)
    np.testing.assert_array_equal(got.points, centres)
    # #5070 = 0: the probe did not trip
    msg = _refused(tmp, pl, log[:4] + [log[4].replace(" 1.000000 ", " 0.000000 ")] + log[5:],
                   fmt="linuxcnc-log")  # fmt: skip
    assert "bad.txt:5" in msg and "point 5 of the plan" in msg and "#5070 is 0" in msg
    # a touch repeated: the numbers run out of order
    msg = _refused(tmp, pl, log[:3] + [log[2]] + log[3:-1], fmt="linuxcnc-log")
    assert "bad.txt:4: the line logs point 3, expected point 4 of the plan" in msg
    # not a LOG line
    msg = _refused(tmp, pl, log[:1] + ["1 1.0 13.0\n"] + log[2:], fmt="linuxcnc-log")
    assert "bad.txt:2: not a LOG line of the plan's program" in msg


@pytest.mark.parametrize("fmt", ["linuxcnc", "fanuc-dprnt"])
def test_a_failed_probe_at_its_rounded_target_is_refused(gauged, fmt):
    """The control reports a failed move's end point: the program's target words,
    rounded to 4 decimals (mm); found along the approach, not only by equality."""
    tmp, study, plan, centres = gauged
    pl = read_plan_points(tmp / "plan.json")
    pts = centres.copy()
    t = plan.points[8].target
    pts[8] = np.round(t, 4)  # as the G38.3 / G31 word wrote it
    if fmt == "linuxcnc":
        lines = [f"{x:f} 0 {z:f} 0 0 0 0 0 0\n" for x, z in pts]
    else:  # the plan's program writes X as a diameter
        lines = [f"X{2 * x:10.4f} Z{z:10.4f}\n" for x, z in pts]
    msg = _refused(tmp, pl, lines, fmt=fmt)
    assert "bad.txt:9" in msg and "point 9 of the plan" in msg and "failed probe" in msg


def _dprnt_bytes(centres, *, crlf=True, port=True, percent=True, header=False) -> bytes:
    """A DPRNT print as it arrives from a Haas port: DC2 and `%` from POPEN, one line per
    touch (`[44]` widths), `%` and DC4 from PCLOS; a CAM system's print adds START/END."""
    end = "\r\n" if crlf else "\n"
    lines = [f"X{2 * x:10.4f} Z{z:10.4f}" for x, z in centres]
    if header:
        lines = ["START", *lines, "END"]
    if percent:
        lines = ["%", *lines, "%"]
    body = end.join(lines) + end
    return (("\x12" + body + "\x14") if port else body).encode("ascii")


@pytest.mark.parametrize(
    "kw",
    [{}, {"crlf": False}, {"port": False}, {"percent": False, "port": False}, {"header": True},
     {"header": True, "crlf": False, "percent": False}],
    ids=["haas-port", "lf", "no-dc", "plain", "cam-header", "cam-header-lf"],
)  # fmt: skip
def test_a_dprnt_file_as_the_port_wrote_it_is_read(gauged, kw):
    tmp, study, plan, centres = gauged
    (tmp / "port.txt").write_bytes(_dprnt_bytes(centres, **kw))
    pl = read_plan_points(tmp / "plan.json")
    got = read_control_probe(tmp / "port.txt", "fanuc-dprnt", pl, x_mode="diameter")
    np.testing.assert_allclose(got.points, centres, rtol=0, atol=0.5e-4 + 1e-12)
    first = 1 + kw.get("percent", True) + kw.get("header", False)
    assert list(got.lines) == list(range(first, first + len(centres)))


@pytest.mark.parametrize(
    ("mutate", "line", "words"),
    [
        (lambda b: b.replace(b"Z", b"Z\x07", 1), 2, ["0x07", "line 2, column 14"]),
        (lambda b: b.replace(b"X", b"X\x12", 1), 2, ["0x12", "line 2, column 2"]),
        (lambda b: b.replace(b"\r\nX", b"\r\n\x00X", 1), 2, ["0x00", "line 2, column 1"]),
        (lambda b: b.replace(b"\r\nX", b"\r\nPROBE\r\nX", 2), 4, ["'PROBE' between the points"]),
    ],
    ids=["bel", "dc2-inside", "nul", "word-between"],
)
def test_any_other_byte_of_a_dprnt_file_is_refused_naming_line_and_column(
    gauged, mutate, line, words
):
    tmp, study, plan, centres = gauged
    (tmp / "bad_port.txt").write_bytes(mutate(_dprnt_bytes(centres)))
    with pytest.raises(InputError) as exc:
        read_control_probe(tmp / "bad_port.txt", "fanuc-dprnt", read_plan_points(tmp / "plan.json"))
    msg = str(exc.value)
    assert f"bad_port.txt:{line}" in msg, msg
    for w in words:
        assert w in msg, msg
