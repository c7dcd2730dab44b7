"""What a probe plan reaches (issue 42, items 2 and 4): the stepped bore whose step face
a 1 mm ball cannot probe with the defaults is planned without it, the face listed with
why and the settings that reach it (closed forms), refused under `strict`, and decided
"not measured"; the plan's retract line follows the study's declared `[profile] kind`
where the normals cannot tell a bore from a shaft."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.export.machine import plan_json, plan_program
from piecs_bayes.geometry import profile_kind
from piecs_bayes.io import load_study
from piecs_bayes.jobs import decide_study, fit_study, load_probe_data, plan_more, plan_study
from piecs_bayes.simulate import probe_csv_text, simulate_probe

#: mm: the window rule's distance slack (geometry._clearance: 2 chord errors)
SLACK_MM = 2.5e-4
BORE = Path(__file__).resolve().parents[1] / "data" / "stepped_bore" / "study.toml"


@pytest.fixture(scope="module")
def bore():
    return load_study(BORE)


def _with_plan(study, **plan):
    return replace(study, plan={**study.plan, **plan})


#: what the plan says of the step face with the defaults
FACE_REASON = (
    "wherever the 1 mm ball can touch it, the probe's stand-off (stock + clearance = 1.5 "
    "mm out along the normal) comes nearer than that to feature 'bore_32' (a corner or "
    "groove too narrow for the ball with stock and clearance)"
)


def test_the_stepped_bore_is_planned_without_its_step_face(bore):
    """The defaults (clearance 1, end clearance e = 0.2, 0.5 mm of stock, a 1 mm ball):
    on the step face the ball clears the convex edge at x = 13 by e from x = 13 +
    sqrt(2 e + e^2) = 13.663, and its stand-off keeps clearance from the Ø32 bore's
    stock up to x = 16 - 1 - 1.5 = 13.5: no window. A line's fit needs 5 points 0.1 mm
    apart, 0.4 mm: reached when 13.663 + 0.4 <= 14.5 - clearance (clearance <= 0.4367)
    or 13 + sqrt(2 e + e^2) + 0.4 <= 13.5 (e <= 0.00499); found to the rule's 0.2 um
    distance slack and rounded down to 0.001. The bores: from their free ends the ball
    radius plus e (1.2 mm), from the step's convex edge 0.663, and 2.5 mm (ball + stock
    + clearance) short of the face, where the stand-off would come nearer to it."""
    plan = plan_study(bore)
    assert [f.feature for f in plan.features] == ["bore_32", "bore_26"]
    (u,) = plan.unreachable
    assert (u.feature, u.reason, u.now) == ("face_z20", FACE_REASON, (1.0, 0.2, 0.1))
    assert u.spacing is None  # no window: no spacing reaches it
    assert u.clearance == pytest.approx(1.5 - math.sqrt(0.44) - 0.4, abs=1e-3)
    assert u.end_clearance == pytest.approx(math.sqrt(1.01) - 1.0, abs=1e-3)
    assert u.remedy == (
        f"reached with [plan] clearance = {u.clearance:g} (now 1) or [plan] end_clearance "
        f"= {u.end_clearance:g} (now 0.2)"
    )
    assert {p.feature for p in plan.points} == {"bore_32", "bore_26"}
    t0, t1 = plan.feature("bore_32").window
    assert (t0 * 20, t1 * 20) == pytest.approx((1.2, 17.5), abs=SLACK_MM)
    t0, t1 = plan.feature("bore_26").window
    assert math.hypot(t0 * 20, 1.0) - 1.2 == pytest.approx(0.0, abs=SLACK_MM)
    assert t1 * 20 == pytest.approx(18.8, abs=SLACK_MM)


@pytest.mark.parametrize(("setting", "step"), [("clearance", 0.005), ("end_clearance", 0.005)])
def test_the_settings_said_to_reach_the_face_do(bore, setting, step):
    """At the setting the plan names, the face is planned with 5 points 0.1 mm apart
    (its window holds no more, even when 8 are asked for); a little beyond, it is not."""
    reached = getattr(plan_study(bore).unreachable[0], setting)
    plan = plan_study(_with_plan(bore, **{setting: reached}), points=8)
    face = plan.feature("face_z20")
    assert not plan.unreachable
    x = np.sort(16.0 - 3.0 * np.array(face.fractions))
    assert np.all(np.diff(x) >= 0.1 - 1e-9) and x[-1] - x[0] < 0.41  # no room for a 6th
    assert {f.feature: f.designed.n for f in plan.features} == {
        "bore_32": 8, "face_z20": 5, "bore_26": 8,
    }  # fmt: skip
    plan = plan_study(_with_plan(bore, **{setting: reached + step}))
    assert [u.feature for u in plan.unreachable] == ["face_z20"]


def test_the_settings_the_issue_found_plan_the_face(bore):
    """clearance 0.3 and end clearance 0.1: the face's window is x in [13 + sqrt(0.21),
    14.2], 0.742 mm; by the ratio it gets the line's least 5 points."""
    plan = plan_study(_with_plan(bore, clearance=0.3, end_clearance=0.1))
    t0, t1 = plan.feature("face_z20").window
    assert 3.0 * (t1 - t0) == pytest.approx(14.2 - 13.0 - math.sqrt(0.21), abs=1e-3)
    assert not plan.unreachable and plan.feature("face_z20").designed.n >= 5


def test_a_window_too_short_for_the_spacing_names_the_spacing_that_fits(bore):
    """clearance 0.5: the face's window is x in [13 + sqrt(0.44), 14.5 - 0.5], 0.337 mm,
    room for 4 points at 0.1 mm; 5 fit at a spacing of 0.337 / 4 = 0.084 (rounded
    down to 0.001), and the plan then probes the face with 5 points that far apart."""
    u = plan_study(_with_plan(bore, clearance=0.5)).unreachable[0]
    width = 14.0 - 13.0 - math.sqrt(0.44)
    assert u.reason == (
        f"its usable window is {width:.3f} mm long: room for 4 points at the 0.1 mm "
        "spacing, the fit needs 5"
    )
    assert u.spacing == pytest.approx(math.floor(width / 4 * 1000) / 1000, abs=1e-3)
    assert u.remedy.endswith(f"or [plan] spacing = {u.spacing:g} (now 0.1)")
    plan = plan_study(_with_plan(bore, clearance=0.5, spacing=u.spacing))
    face = plan.feature("face_z20")
    assert face.designed.n == 5
    assert np.all(np.diff(np.sort(3.0 * np.array(face.fractions))) >= u.spacing - 1e-9)


def test_strict_refuses_naming_the_file_the_feature_and_the_setting(bore):
    u = plan_study(bore).unreachable[0]
    with pytest.raises(InputError) as exc:
        plan_study(bore, strict=True)
    assert exc.value.file == str(BORE) and exc.value.feature == "face_z20"
    assert str(exc.value) == (
        f"{BORE}, feature 'face_z20': the plan would leave 1 feature(s) not measured "
        f"(strict): feature 'face_z20': {FACE_REASON}; {u.remedy}"
    )
    assert plan_study(_with_plan(bore, clearance=u.clearance), strict=True).unreachable == ()


def test_the_plan_files_mark_the_face_not_measured(bore):
    import json

    plan = plan_study(bore)
    body = json.loads(plan_json(plan))
    u = plan.unreachable[0]
    assert body["unreachable"] == [
        {"feature": "face_z20", "reason": FACE_REASON, "clearance": u.clearance,
         "end_clearance": u.end_clearance, "spacing": None},
    ]  # fmt: skip
    assert "face_z20" not in {p["feature"] for p in body["points"]}
    assert "(not measured: face_z20, the probe cannot reach it, see plan.json)" in (
        plan_program(plan).splitlines()
    )
    reached = json.loads(plan_json(plan_study(_with_plan(bore, clearance=0.3))))
    assert "unreachable" not in reached  # a plan that reaches everything: as before


def test_more_points_on_an_unreachable_feature_are_refused(bore):
    with pytest.raises(InputError, match="'face_z20'.*clearance = 0.437"):
        plan_more(bore, {"face_z20": 2}, {})
    plan = plan_more(bore, {"bore_26": 2}, {})
    assert [p.feature for p in plan.points] == ["bore_26"] * 2


def test_a_part_probed_by_the_plan_decides_the_face_not_measured(bore, tmp_path):
    """The points of the default plan, probed on a part whose bores are off by 12 and -6
    um and whose face is off by -10 um: the fit and the decisions cover the two bores,
    the face is "not measured" (no verdict, gain 0) in the table, its rows and repr."""
    plan = plan_study(bore)
    truth = {"bore_32": np.array([0.012, 0.0]), "face_z20": np.array([-0.01, 0.0]),
             "bore_26": np.array([-0.006, 0.0])}  # fmt: skip
    sim = simulate_probe(
        bore.profile, truth, ball_radius=1.0, transform=bore.transform, noise_sd=0.0015,
        points={f.feature: np.array(f.fractions) for f in plan.features}, rng=7,
    )  # fmt: skip
    path = tmp_path / "probe.csv"
    path.write_text(probe_csv_text(sim, x_mode=bore.probe.x_mode))
    study = replace(bore, probe_files=(path,))
    fit = fit_study(study, load_probe_data(study))
    assert fit.unmeasured == ("face_z20",)
    table = decide_study(study, fit)
    assert table.unmeasured == ("face_z20",) and "face_z20" not in table.verdicts
    assert table.gains.keys() == {"bore_32", "bore_26"}
    rows = {r["feature"]: r for r in table.rows()}
    assert rows["face_z20"]["verdict"] == "not measured" and rows["face_z20"]["gain"] == 0.0
    assert (
        rows["face_z20"]["estimate_mm"] is None
        and rows["face_z20"].keys() == rows["bore_32"].keys()
    )
    assert rows["bore_32"]["estimate_mm"] == pytest.approx(0.012, abs=0.003)
    assert "face_z20 not measured" in repr(table)
    assert list(table.to_dataframe()["feature"]) == ["bore_32", "bore_26", "face_z20"]


# --- the declared kind --------------------------------------------------------------------

#: a front face (z = 0) with an axial groove (x 12 to 15, 3 mm deep): faces, and the
#: groove's walls, whose normals cancel; as the study declares it, a bore (the region the
#: profile encloses with the axis is the groove: air)
FACE_GROOVE = [
    ("face_out", (20.0, 0.0), (15.0, 0.0)), ("wall_out", (15.0, 0.0), (15.0, -3.0)),
    ("bottom", (15.0, -3.0), (12.0, -3.0)), ("wall_in", (12.0, -3.0), (12.0, 0.0)),
    ("face_in", (12.0, 0.0), (5.0, 0.0)),
]  # fmt: skip
#: the contrast: a front face with a ring 3 mm proud of it (x 12 to 15), a shaft (its
#: face inside the ring too short to probe: the plan's moves go round the ring radially)
FACE_RIB = [
    ("face_in", (10.0, 0.0), (12.0, 0.0)), ("wall_in", (12.0, 0.0), (12.0, 3.0)),
    ("top", (12.0, 3.0), (15.0, 3.0)), ("wall_out", (15.0, 3.0), (15.0, 0.0)),
    ("face_out", (15.0, 0.0), (20.0, 0.0)),
]  # fmt: skip


def _face_study(tmp_path, lines, kind):
    feats = "".join(
        f'[[profile.feature]]\nid = "{fid}"\ntype = "line"\nstart = [{a[0]}, {a[1]}]\n'
        f"end = [{b[0]}, {b[1]}]\ntolerance = [-0.02, 0.02]\n"
        f'tolerance_on = "{"length" if a[1] == b[1] else "diameter"}"\n\n'
        for fid, a, b in lines
    )
    text = (
        f'[study]\nname = "{kind} faces"\nprobe_files = []\n\n[profile]\nkind = "{kind}"\n'
        f'x_mode = "radius"\n\n{feats}[probe]\nball_radius = 1.0\nrepeatability = 0.0015\n'
        "tool = 9\nfeed = 200.0\n"
    )
    path = tmp_path / f"{kind}.toml"
    path.write_text(text)
    return load_study(path)


@pytest.mark.parametrize(
    ("lines", "kind", "home_x"),
    [(FACE_GROOVE, "internal", 5.0 - 2.5), (FACE_RIB, "external", 20.0 + 2.5)],
)
def test_the_plan_follows_the_declared_kind_where_the_normals_cannot_tell(
    tmp_path, lines, kind, home_x
):
    """Both profiles face the front (every face's normal +z) and their walls' normals
    cancel, so the length-weighted radial normal is 0 for both: no guess from the
    normals tells them apart. The plan takes the study's kind: its retract line and
    home lie inside the smallest radius of the bore by ball + stock + clearance (2.5
    mm), outside the largest radius of the shaft by as much."""
    study = _face_study(tmp_path, lines, kind)
    assert profile_kind(study.profile) == kind
    radial = sum(
        f.length * float(np.asarray(f.outward_normal(np.array([f.p0])))[0, 0])
        for f in study.profile
    )
    assert radial == 0.0
    assert all(
        float(np.asarray(f.outward_normal(np.array([f.p0])))[0, 1]) == 1.0
        for f in study.profile
        if f.p0[1] == f.p1[1]
    )
    plan = plan_study(study)
    assert plan.home[0] == pytest.approx(home_x, abs=1e-12)
    assert plan.home[1] == pytest.approx(max(f.p0[1] for f in study.profile) + 2.5, abs=1e-12)
    assert "face_out" in {f.feature for f in plan.features}
