"""Tool-offset (wear) updates: rules, G10 lines and JSON."""

import pytest

from piecs_bayes.compensate import OffsetSettings, ToolOffsets, WearOffset, tool_offset_update
from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.export.machine import g10_fanuc, g10_linuxcnc, offsets_from_json, offsets_to_json

ST = OffsetSettings(null_band=0.002, feedback_gain=0.8, upper_limit=0.1)
_ARGS = dict(
    x_error=0.012,
    u_x=0.001,
    z_error=-0.005,
    u_z=0.0008,
    nose_radius_error=0.001,
    u_r=0.002,
    settings=ST,
)


def _update(**kw):
    return tool_offset_update(WearOffset(3), **{**_ARGS, **kw})


def test_gain_null_band_and_uncertainty():
    u = _update()
    assert u.x.status == "update" and u.x.correction == pytest.approx(-0.0096)
    assert u.x.u_correction == pytest.approx(0.0008)
    assert u.z.status == "update" and u.z.correction == pytest.approx(0.004)
    assert u.z.u_correction == pytest.approx(0.00064)
    assert u.r.status == "null band" and u.r.correction == 0.0
    assert u.any_update and not u.blocked


def test_linuxcnc_g10_exact_text_diameter_mode():
    text = g10_linuxcnc(_update(), current=ToolOffsets(x=0.1234, z=-2.5, r=0.4))
    assert text == (
        "(piecs-bayes LinuxCNC wear update T3, X as diameter, mm)\n"
        "(standard uncertainties mm: X 0.0008 Z 0.0006)\n"
        "G21 G7\n"
        "G10 L1 P3 X0.1138 Z-2.4960\n"
    )


def test_linuxcnc_g10_exact_text_radius_mode_with_nose_radius():
    u = tool_offset_update(
        WearOffset(12, x_mode="radius"),
        x_error=-0.004,
        u_x=0.0005,
        nose_radius_error=0.006,
        u_r=0.001,
        settings=OffsetSettings(decimals=3),
    )
    text = g10_linuxcnc(u, current=ToolOffsets(x=-1.0, r=0.4))
    assert text.splitlines()[2:] == ["G21 G8", "G10 L1 P12 X-0.996 R0.406"]
    assert text.splitlines()[1] == "(standard uncertainties mm: X 0.001 R 0.001)"


def test_fanuc_incremental_and_absolute():
    u = _update()
    assert g10_fanuc(u).splitlines() == [
        "(piecs-bayes Fanuc wear update T0303: tool 3, wear offset 3, X as diameter, mm)",
        "(standard uncertainties mm: U 0.0008 W 0.0006)",
        "G10 P3 U-0.0096 W0.0040",
    ]
    assert g10_fanuc(u, current=ToolOffsets(x=0.02, z=0.0)).splitlines()[-1] == (
        "G10 P3 X0.0104 Z0.0040"
    )


def test_wear_offset_number_where_each_controller_needs_it():
    # T0211: tool 2 (turret station, LinuxCNC tool-table entry), wear offset 11
    u = tool_offset_update(
        WearOffset(2, offset=11, source="the T word T0211 on line 4 of finish.ngc (lines 8-14)"),
        **_ARGS,
    )
    fanuc = g10_fanuc(u).splitlines()
    assert fanuc[0] == (
        "(piecs-bayes Fanuc wear update T0211: tool 2, wear offset 11, X as diameter, mm)"
    )
    assert fanuc[1] == "(tool from the T word T0211 on line 4 of finish.ngc [lines 8-14])"
    assert fanuc[-1] == "G10 P11 U-0.0096 W0.0040"  # Fanuc: the wear offset register
    linuxcnc = g10_linuxcnc(u, current=ToolOffsets(x=0.1234, z=-2.5, r=0.4)).splitlines()
    assert linuxcnc[0] == "(piecs-bayes LinuxCNC wear update T2, X as diameter, mm)"
    assert linuxcnc[-1] == "G10 L1 P2 X0.1138 Z-2.4960"  # LinuxCNC: the tool's entry
    assert "wear offset 11" in repr(u)
    back = offsets_from_json(offsets_to_json(u))
    assert back == u and (back.tool, back.offset) == (2, 11) and back.source == u.source
    # a file written before the offset number existed reads as offset = tool
    old = offsets_to_json(_update()).replace('  "offset": 3,\n', "")
    assert '"offset"' not in old and offsets_from_json(old).offset == 3
    with pytest.raises(InputError, match="offset must be an integer >= 1, got 0"):
        tool_offset_update(WearOffset(2, offset=0), x_error=0.01)


def test_everything_inside_the_null_band_changes_nothing():
    u = tool_offset_update(WearOffset(5), x_error=0.0015, z_error=-0.002, settings=ST)
    assert not u.any_update and {u.x.status, u.z.status} == {"null band"}
    text = g10_linuxcnc(u, current=ToolOffsets())
    assert "G10" not in text and text.startswith("(piecs-bayes LinuxCNC wear update T5")
    assert "(no change: X: |error| 0.0015 mm <= null band 0.002 mm" in text


def test_upper_limit_blocks_the_whole_update():
    u = _update(x_error=0.15)
    assert u.blocked and not u.any_update
    assert u.x.status == "blocked" and u.z.status == "blocked" and u.z.correction == 0.0
    assert "update blocked, X error above the upper limit 0.1 mm" in u.reasons[0]
    with pytest.raises(AnalysisError, match="refusing to write a blocked update"):
        g10_linuxcnc(u, current=ToolOffsets(0.0, 0.0, 0.0))
    with pytest.raises(AnalysisError, match="refusing to write a blocked update"):
        g10_fanuc(u)
    with pytest.raises(AnalysisError, match="tool 3: update blocked"):
        _update(z_error=-0.5, raise_on_block=True)


def test_significance_factor():
    st = OffsetSettings(null_band=0.001, k_significance=2.0)
    u = tool_offset_update(
        WearOffset(1), x_error=0.003, u_x=0.002, z_error=0.003, u_z=0.001, settings=st
    )
    assert u.x.status == "not significant" and u.z.status == "update"


def test_linuxcnc_needs_current_values():
    with pytest.raises(InputError, match="absolute values: give the current Z of tool 3"):
        g10_linuxcnc(_update(), current=ToolOffsets(x=0.0))


def test_json_round_trip_and_errors():
    u = _update()
    text = offsets_to_json(u)
    assert '"format": "piecs-bayes-tool-offsets"' in text
    assert offsets_from_json(text) == u
    with pytest.raises(InputError, match="not a piecs-bayes-tool-offsets file"):
        offsets_from_json('{"format": "x"}')
    with pytest.raises(InputError, match="upd.json:1: not valid JSON"):
        offsets_from_json("{", file="upd.json")


@pytest.mark.parametrize(
    "kw, message",
    [
        ({"feedback_gain": 0.0}, "feedback_gain must be > 0.0"),
        ({"feedback_gain": 1.2}, "feedback_gain must be <= 1"),
        ({"upper_limit": 0.001}, "upper_limit .* must be above null_band"),
        ({"decimals": 9}, "decimals must be an integer 1..6"),
        ({"null_band": float("nan")}, "null_band must be a finite number"),
    ],
)
def test_settings_validation(kw, message):
    with pytest.raises(InputError, match=message):
        OffsetSettings(**kw)


def test_bad_update_arguments():
    with pytest.raises(InputError, match="tool must be an integer >= 1"):
        tool_offset_update(WearOffset(0), x_error=0.01)
    with pytest.raises(InputError, match="no error given"):
        tool_offset_update(WearOffset(2))
    with pytest.raises(InputError, match="x_mode must be"):
        tool_offset_update(WearOffset(2, x_mode="diametre"), x_error=0.01)


def test_wear_offset_defaults_and_refusal():
    """`WearOffset` holds what `tool_offset_update` took as `tool`, `offset`, `x_mode` and
    `source`, with the same defaults (offset: the tool); a bad value is refused."""
    assert WearOffset(3) == WearOffset(3, offset=3, x_mode="diameter", source="")
    u = tool_offset_update(WearOffset(3), x_error=0.01)
    assert (u.tool, u.offset, u.x_mode, u.source) == (3, 3, "diameter", "")
    with pytest.raises(InputError, match="tool must be an integer >= 1, got True"):
        WearOffset(True)
