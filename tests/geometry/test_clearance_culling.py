"""The probe window's culling of far segments (`_clearance._near`) changes no answer:
a segment whose bounding box is farther than the threshold from every probe move's
cannot fail the test `distance >= threshold`."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import piecs_bayes.geometry._clearance as clearance
from piecs_bayes.io import load_study

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"


@pytest.mark.parametrize("standoff", [0.0, 0.5, 2.0])
def test_culling_far_segments_changes_no_usable_point(monkeypatch, standoff):
    profile = load_study(DEMO).profile
    polys = [clearance.feature_polyline(g) for g in profile.features]
    t = np.linspace(0.0, 1.0, 257)
    cases = [(i, r, ec) for i in range(len(profile.features))
             for r in (0.25, 1.0, 3.0) for ec in (0.05, 0.3)]  # fmt: skip
    culled = [clearance._usable(profile, i, t, r, ec, standoff, polys) for i, r, ec in cases]
    monkeypatch.setattr(clearance, "_near", lambda a, b, points, reach: (a, b))
    whole = [clearance._usable(profile, i, t, r, ec, standoff, polys) for i, r, ec in cases]
    for (i, r, ec), got, want in zip(cases, culled, whole, strict=True):
        np.testing.assert_array_equal(got, want, err_msg=f"feature {i}, r {r}, ec {ec}")
    # the culling does cut: on the demo some usable points exist and some are refused
    assert any(w.any() for w in whole) and any((~w).any() for w in whole)


def test_near_keeps_a_segment_within_reach_and_drops_one_beyond():
    a = np.array([[0.0, 0.0], [10.0, 0.0]])
    b = np.array([[0.0, 1.0], [10.0, 1.0]])
    points = np.array([[2.0, 0.0], [3.0, 0.5]])
    ka, kb = clearance._near(a, b, points, 2.0)  # 2 mm from the first, 7 from the second
    np.testing.assert_array_equal(ka, a[:1])
    np.testing.assert_array_equal(kb, b[:1])
    assert len(clearance._near(a, b, points, 1.999)[0]) == 0
