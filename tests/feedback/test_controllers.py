"""The controllers' own feedback rules, exactly as published: known answers.

Every expected value below is worked by hand from the published rule (docs/feedback.md,
"The controllers' own rules"), not by the code under test. A run is built so that the
parts come out at the measured values of the example: the deviation without
correction is the measured value minus the hand-computed correction in effect.
"""

import math

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.feedback import POLICIES, SHOP_SETTINGS, TUNING_GRIDS, replay, replay_runs
from piecs_bayes.feedback._controllers import siemens_step
from piecs_bayes.feedback._replay import schedule

UM = 1e-3
INF = math.inf
D_EXAMPLE = [30, 50, 60, 20, 40, 50, 50, 30, 70, 70]  # µm, the manual's D_i


def _siemens(k, tzl, tmv=INF, tdif=INF, tsa=INF):
    return {"_K": k, "_TZL": tzl, "_TMV": tmv, "_TDIF": tdif, "_TSA": tsa}


def _run_at(measured_um, corrections_um, policy, settings, tolerance, **kw):
    """Replay a run whose parts come out at `measured_um` with the hand-computed
    corrections `corrections_um`; check that they do and return the result."""
    meas = np.asarray(measured_um, dtype=float) * UM
    c = np.asarray(corrections_um, dtype=float) * UM
    res = replay(meas - c, UM, policy=policy, settings=settings, tolerance=tolerance, **kw)
    np.testing.assert_allclose(res.corrections, c, rtol=0, atol=1e-12)
    np.testing.assert_allclose(res.realised, meas, rtol=0, atol=1e-12)
    return res


def test_the_controllers_are_policies_with_grids_and_shop_settings():
    for name in ("siemens", "renishaw", "heidenhain"):
        assert name in POLICIES and name in TUNING_GRIDS and name in SHOP_SETTINGS
    assert POLICIES[-1] == "bayes"
    # the manuals' defaults: Inspection Plus F 100 %, no V, no U; TNC RBREAK 0
    assert SHOP_SETTINGS["renishaw"] == {"F": 1.0, "V": 0.0, "U": INF}
    assert SHOP_SETTINGS["heidenhain"] == {"RBREAK": 0.0}


def test_siemens_means_of_the_worked_example():
    """The mean M_i = M_{i-1} + (D_i - M_{i-1}) / k from M_0 = 0, cleared after a
    correction (|M_i| > _TZL = 40 µm), by hand (µm). The manual's table prints
    32.6 for M_5 with k = 3 (a slip: 30.37 + (40 - 30.37) / 3 = 33.58) and carries
    it on (38.4, 42.3); the corrections fall on the same measurements."""
    k3 = [10.0, 70 / 3, 320 / 9, 820 / 27, 2720 / 81, 9490 / 243, 31130 / 729, 10.0, 30.0,
          130 / 3]  # fmt: skip
    k2 = [15.0, 32.5, 46.25, 10.0, 25.0, 37.5, 43.75, 15.0, 42.5, 35.0]
    for k, want, fired in ((3, k3, {7, 10}), (2, k2, {3, 7, 9})):
        m, got, at = np.zeros(1), [], set()
        for i, d in enumerate(D_EXAMPLE, start=1):
            before = m.copy()
            m, adj = siemens_step(m, np.array([d * UM]), _siemens(k, 40 * UM), 1.0)
            mean = before + (d * UM - before) / k  # the M_i the cycle compares
            got.append(float(mean[0]) / UM)
            if adj[0] != 0.0:
                at.add(i)
                assert adj[0] == pytest.approx(-mean[0], abs=1e-15)
                assert m[0] == 0.0
        np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)
        assert at == fired


@pytest.mark.parametrize(
    ("k", "corrections"),
    [
        # corrections by M_7 = 42.702 and M_10 = 43.333 µm (measurements 7 and 10)
        (3, [0] * 7 + [-31130 / 729] * 3 + [-31130 / 729 - 130 / 3]),
        # by M_3 = 46.25, M_7 = 43.75, M_9 = 42.5 µm (measurements 3, 7 and 9)
        (2, [0] * 3 + [-46.25] * 4 + [-90.0] * 2 + [-132.5] * 2),
    ],
)
def test_siemens_worked_example_replayed(k, corrections):
    """SINUMERIK measuring cycles, mean value with tool offset, D = 30 ... 70 µm,
    _TZL = 40 µm: the tool offset changes after measurements 7 and 10 (k = 3) and
    3, 7 and 9 (k = 2); an eleventh part shows the last correction."""
    res = _run_at(D_EXAMPLE + [0], corrections, "siemens", _siemens(k, 40 * UM),
                  (-200 * UM, 200 * UM))  # fmt: skip
    changed = (np.flatnonzero(np.diff(res.corrections)) + 1).tolist()  # 0-based part
    assert changed == ([7, 10] if k == 3 else [3, 7, 9])  # = after measurement i (1-based)
    assert res.flags == 0


def test_siemens_bands():
    """_K = 2, _TZL = 4, _TMV = 30, _TDIF = 80, _TSA = 200 µm, tolerance ±50 µm:
    D = 35 (beyond _TMV: corrected by D, mean cleared), 60 (oversize: corrected by D,
    alarm), 90 (beyond _TDIF: no correction, alarm), 300 (beyond _TSA: no correction,
    alarm), then 6 (M = 3: held) and 8 (M = 5.5 > 4: corrected)."""
    st = _siemens(2, 4 * UM, 30 * UM, 80 * UM, 200 * UM)
    meas = [2, 35, 60, 90, 300, 6, 8, 0]
    c = [0, 0, -35, -95, -95, -95, -95, -100.5]
    res = _run_at(meas, c, "siemens", st, (-50 * UM, 50 * UM))
    assert res.flags == 3


def test_siemens_setpoint_is_the_middle_of_the_tolerance():
    """The cycle places the setpoint in the middle of an asymmetric tolerance: with
    (0, 100) µm the difference of a part at 80 µm is +30 µm."""
    res = _run_at([80, 50, 50], [0, -30, -30], "siemens", _siemens(1, 10 * UM),
                  (0.0, 100 * UM))  # fmt: skip
    assert res.flags == 0


def test_renishaw_inspection_plus():
    """F = 0.5 (F.5), null band V = 5 µm, upper tolerance limit U = 50 µm: 4 and 5 µm
    (inside the null band: held), 20 (offset -10), 60 (above U: held, alarm), -12
    (offset +6)."""
    st = {"F": 0.5, "V": 5 * UM, "U": 50 * UM}
    res = _run_at([4, 5, 20, 60, -12, 0], [0, 0, 0, -10, -10, -4], "renishaw", st,
                  (-30 * UM, 30 * UM))  # fmt: skip
    assert res.flags == 1


def test_heidenhain_tool_monitoring_and_a_new_tool():
    """Every deviation added to DR; RBREAK = 50 µm: 80 µm locks the tool (alarm, no
    further correction); the tool change declared at part 5 unlocks it."""
    st = {"RBREAK": 50 * UM}
    meas = [10, 4, -6, 80, 10, 2, 0]
    c = [0, -10, -14, -8, -8, -8, -10]
    res = _run_at(meas, c, "heidenhain", st, (-30 * UM, 30 * UM), tool_changes=(5,))
    assert res.flags == 1
    locked = _run_at(meas, [0, -10, -14, -8, -8, -8, -8], "heidenhain", st,
                     (-30 * UM, 30 * UM))  # fmt: skip
    assert locked.flags == 1


def test_heidenhain_adds_to_the_current_offset_when_results_are_late():
    """A result arriving one part late is added to DR as it stands: a constant 10 µm
    deviation gives c = 0, 0, -10, -20, -20, -10, 0, 0, -10 µm."""
    c = [0, 0, -10, -20, -20, -10, 0, 0, -10]
    dev = np.full(len(c), 10 * UM)
    res = replay(dev, UM, policy="heidenhain", settings={"RBREAK": 0.0},
                 tolerance=(-30 * UM, 30 * UM), delay=1)  # fmt: skip
    np.testing.assert_allclose(res.corrections, np.array(c) * UM, rtol=0, atol=1e-12)


def test_siemens_tool_change_clears_the_mean():
    """k = 2, _TZL = 4 µm, D = 6, 6, 6 µm: M = 3, then (new tool at part 1) 3 again
    instead of 4.5, then 4.5 > 4: corrected once, after part 2."""
    res = _run_at([6, 6, 6, 0], [0, 0, 0, -4.5], "siemens", _siemens(2, 4 * UM),
                  (-30 * UM, 30 * UM), tool_changes=(1,))  # fmt: skip
    again = replay(np.array([6, 6, 6, 0]) * UM, UM, policy="siemens",
                   settings=_siemens(2, 4 * UM), tolerance=(-30 * UM, 30 * UM))  # fmt: skip
    assert res.corrections[2] == 0.0 and again.corrections[2] == pytest.approx(-4.5 * UM)


@pytest.mark.parametrize("policy", ["siemens", "renishaw", "heidenhain"])
def test_controllers_change_only_when_a_result_arrives(policy):
    rng = np.random.default_rng(4)
    dev = (rng.normal(0, 3, (4, 30)) + 0.5 * np.arange(30)) * UM
    st = TUNING_GRIDS[policy][min(5, len(TUNING_GRIDS[policy]) - 1)]
    c, flags, pit = replay_runs(dev, UM, policy=policy, settings=st,
                                tolerance=(-10 * UM, 10 * UM), inspect_every=5, delay=1)  # fmt: skip
    _, source = schedule(30, 5, 1)
    changes = np.flatnonzero(np.any(np.diff(c, axis=1) != 0, axis=0)) + 1
    assert set(changes) <= set(np.flatnonzero(source >= 0).tolist()) and pit is None
    assert flags.shape == (4,)


@pytest.mark.parametrize(
    ("policy", "settings", "match"),
    [
        ("siemens", _siemens(0, 0.0), "_K .* got 0"),
        ("siemens", _siemens(2.5, 0.0), "_K .* got 2.5"),
        ("siemens", _siemens(True, 0.0), "_K .* got True"),
        ("siemens", _siemens(3, -0.001), "_TZL .* got -0.001"),
        ("siemens", _siemens(3, 0.01, 0.005), "_TMV=0.005 < _TZL=0.01"),
        ("siemens", _siemens(3, 0.0, 0.02, 0.1, 0.05), "_TSA=0.05 < _TDIF=0.1"),
        ("siemens", _siemens(3, 0.0, 0.0), "_TMV .* got 0.0"),
        ("renishaw", {"F": 50, "V": 0.0, "U": INF}, "F .* got 50"),
        ("renishaw", {"F": 0.0, "V": 0.0, "U": INF}, "F .* got 0.0"),
        ("renishaw", {"F": 0.5, "V": -0.001, "U": INF}, "V .* got -0.001"),
        ("renishaw", {"F": 0.5, "V": 0.01, "U": 0.01}, "U=0.01, V=0.01"),
        ("renishaw", {"F": 0.5, "V": INF, "U": INF}, "V .* got inf"),
        ("heidenhain", {"RBREAK": -0.01}, "RBREAK .* got -0.01"),
        ("heidenhain", {"RBREAK": math.nan}, "RBREAK .* got nan"),
        ("heidenhain", {"RBREAK": 0.05, "RTOL": 0.01}, "exactly \\['RBREAK'\\]"),
    ],
)
def test_bad_settings_are_refused_by_name(policy, settings, match):
    with pytest.raises(InputError, match=match):
        replay(np.zeros(4), UM, policy=policy, settings=settings, tolerance=(-0.01, 0.01))
