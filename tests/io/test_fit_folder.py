"""`io.read_more_points`: a fit folder's "measure more" verdicts and probed points,
read back for `plan --more`, with errors that name the file."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.io import read_more_points

GOLDEN = Path(__file__).resolve().parents[1] / "data" / "golden" / "demo"


def test_the_verdicts_and_the_probed_points_are_read(tmp_path):
    shutil.copy(GOLDEN / "residuals.csv", tmp_path)
    dec = json.loads((GOLDEN / "decisions.json").read_text())
    dec["features"][0].update(verdict="measure more", more_points=3)
    (tmp_path / "decisions.json").write_text(json.dumps(dec))
    more, probed = read_more_points(tmp_path)
    assert more == {dec["features"][0]["feature"]: 3}
    assert probed and all(len(p) == 2 for pts in probed.values() for p in pts)


def test_errors_name_the_file(tmp_path):
    with pytest.raises(InputError, match="cannot read") as e:
        read_more_points(tmp_path)
    assert "decisions.json" in str(e.value)
    (tmp_path / "decisions.json").write_text("{}")
    with pytest.raises(InputError, match="not a decisions file"):
        read_more_points(tmp_path)
    (tmp_path / "decisions.json").write_text('{"features": []}')
    with pytest.raises(InputError, match="cannot read") as e:
        read_more_points(tmp_path)
    assert "residuals.csv" in str(e.value)
    (tmp_path / "residuals.csv").write_text("feature,outlier\ndia_24,0\n")
    with pytest.raises(InputError, match="bad row") as e:
        read_more_points(tmp_path)
    assert e.value.line == 2
