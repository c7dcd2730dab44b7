"""The adjusted finish-cut program of a study (PIECS option 2), through the CLI."""

import re
import shutil
from pathlib import Path

from piecs_bayes.cli import main

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo"
WORD = re.compile(r"([A-Z])([-+]?\d*\.?\d+)")


def _words(line: str):
    code = re.sub(r"\(.*?\)", "", line)
    return [(m.group(1), m.group(2)) for m in WORD.finditer(code)]


def test_adjusted_demo_program_changes_only_finish_cut_coordinates(tmp_path):
    out = tmp_path / "finish_adjusted.ngc"
    rc = main(
        [
            "compensate",
            str(DEMO / "study.toml"),
            "--out",
            str(tmp_path),
            "--quiet",
            "--program-out",
            str(out),
        ]
    )
    assert rc == 0
    before = (DEMO / "finish.ngc").read_text().splitlines(keepends=True)
    after = out.read_text().splitlines(keepends=True)
    assert len(before) == len(after)
    changed = [i for i, (a, b) in enumerate(zip(before, after, strict=True)) if a != b]
    finish = {i for i, line in enumerate(before) if re.match(r"N(5|6|7|8|9|10|11|12)0 ", line)}
    assert changed and set(changed) <= finish  # only the finish-cut blocks N50..N120
    for i in changed:
        wa, wb = _words(before[i]), _words(after[i])
        assert [w for w, _ in wa] == [w for w, _ in wb]  # same words, same order
        for (w, va), (_, vb) in zip(wa, wb, strict=True):
            if w not in "XZIKR":
                assert va == vb, (before[i], after[i])
            else:
                assert len(va.split(".")[-1]) == len(vb.split(".")[-1])  # number format kept
                assert abs(float(va) - float(vb)) < 0.1
        assert re.sub(WORD, "", before[i]) == re.sub(WORD, "", after[i])  # comments, spacing kept
    diff = (tmp_path / "finish_adjusted.ngc.diff").read_text()
    assert diff.startswith("---") and diff.count("\n-N") == len(changed)
    # the 24 mm diameter is fitted ~21.6 um oversize in radius: mirrored to X23.95x
    n70 = next(line for line in after if line.startswith("N70 "))
    assert 23.950 <= float(_words(n70)[2][1]) <= 23.965


def test_program_out_never_overwrites_the_input_and_refuses_large_corrections(tmp_path, capsys):
    for name in ("study.toml", "probe_part01.csv", "finish.ngc"):
        shutil.copy(DEMO / name, tmp_path / name)
    original = (tmp_path / "finish.ngc").read_bytes()
    rc = main(
        [
            "compensate",
            str(tmp_path / "study.toml"),
            "--out",
            str(tmp_path / "o"),
            "--quiet",
            "--program-out",
            str(tmp_path / "finish.ngc"),
        ]
    )
    assert rc == 2 and "refusing to overwrite an input file" in capsys.readouterr().err
    assert (tmp_path / "finish.ngc").read_bytes() == original
    text = (
        (tmp_path / "study.toml")
        .read_text()
        .replace("max_correction = 0.1", "max_correction = 0.005")
    )
    (tmp_path / "study.toml").write_text(text)
    rc = main(
        [
            "compensate",
            str(tmp_path / "study.toml"),
            "--out",
            str(tmp_path / "o2"),
            "--quiet",
            "--program-out",
            str(tmp_path / "new.ngc"),
        ]
    )
    assert (
        rc == 1
        and "more than the configured maximum correction 0.005 mm" in capsys.readouterr().err
    )
    assert not (tmp_path / "new.ngc").exists()
