"""Where a probe ball first touches a profile (`geometry.first_contact`, exact) and the
probe window's rule checked against it (issue 42, item 2): lines and arcs, convex and
concave, shafts and bores, three balls; closed forms where the geometry gives one."""

from __future__ import annotations

import math

import numpy as np
import pytest

from piecs_bayes.geometry import (
    Arc,
    Line,
    Profile,
    ball_centres,
    first_contact,
    make_feature,
    nearest_point,
    probe_window,
    profile_kind,
    profile_side,
)


def _profile(kind: str, specs) -> Profile:
    side = profile_side(specs, internal=kind == "internal")
    return Profile(tuple(make_feature(s, side) for s in specs))


def _line(fid, p0, p1):
    return {"id": fid, "p0": p0, "p1": p1}


def _arc(fid, p0, p1, center, ccw):
    return {"id": fid, "p0": p0, "p1": p1, "center": center, "ccw": ccw}


#: (x radius, z) mm. Corners: the kind of each junction, in order, as drawn.
PROFILES = {
    "shaft_lines": (
        "external",
        [  # sharp: convex, concave, convex, concave (obtuse), convex
            _line("face", (4.0, 0.0), (10.0, 0.0)),
            _line("dia_20", (10.0, 0.0), (10.0, -15.0)),
            _line("shoulder", (10.0, -15.0), (14.0, -15.0)),
            _line("dia_28", (14.0, -15.0), (14.0, -30.0)),
            _line("taper", (14.0, -30.0), (18.0, -36.0)),
            _line("dia_36", (18.0, -36.0), (18.0, -50.0)),
        ],
    ),
    "bore_lines": (
        "internal",
        [  # sharp: convex, concave, convex, concave (obtuse), convex
            _line("face", (20.0, 0.0), (16.0, 0.0)),
            _line("bore_32", (16.0, 0.0), (16.0, -20.0)),
            _line("face_z20", (16.0, -20.0), (13.0, -20.0)),
            _line("bore_26", (13.0, -20.0), (13.0, -40.0)),
            _line("cone", (13.0, -40.0), (11.0, -42.0)),
            _line("bore_22", (11.0, -42.0), (11.0, -55.0)),
        ],
    ),
    "shaft_arcs": (
        "external",
        [  # a convex corner round R2, a concave fillet R3
            _line("face", (4.0, 0.0), (8.0, 0.0)),
            _arc("round", (8.0, 0.0), (10.0, -2.0), (8.0, -2.0), True),
            _line("dia_20", (10.0, -2.0), (10.0, -15.0)),
            _arc("fillet", (10.0, -15.0), (13.0, -18.0), (13.0, -15.0), False),
            _line("shoulder", (13.0, -18.0), (20.0, -18.0)),
            _line("dia_40", (20.0, -18.0), (20.0, -30.0)),
        ],
    ),
    "bore_arcs": (
        "internal",
        [  # a convex edge round R1.5 at the mouth, a concave fillet R2
            _line("face", (22.0, 0.0), (18.0, 0.0)),
            _arc("round", (18.0, 0.0), (16.5, -1.5), (18.0, -1.5), False),
            _line("bore_33", (16.5, -1.5), (16.5, -20.0)),
            _arc("fillet", (16.5, -20.0), (14.5, -22.0), (14.5, -20.0), True),
            _line("face_z22", (14.5, -22.0), (12.0, -22.0)),
            _line("bore_24", (12.0, -22.0), (12.0, -40.0)),
        ],
    ),
}

#: (ball radius, end clearance, stand-off) mm
BALLS = [(1.0, 0.2, 1.5), (0.5, 0.05, 0.6), (2.0, 0.3, 0.0)]


def test_the_profiles_are_what_their_comments_say():
    """The kinds as declared, the arcs' convexity and the corners' turn as drawn (a
    convex corner turns toward the material, so its sign is the opposite of a concave
    one's)."""
    for name, (kind, specs) in PROFILES.items():
        prof = _profile(kind, specs)
        assert profile_kind(prof) == kind, name
        arcs = {f.id: f.convex for f in prof.features if isinstance(f, Arc)}
        assert arcs == ({"round": True, "fillet": False} if "arcs" in name else {}), name
    lines = _profile(*PROFILES["shaft_lines"])
    signs = np.sign(lines.turn_angles_deg)
    assert list(signs) == [signs[0], -signs[0], signs[0], -signs[0], signs[0]]
    bore = _profile(*PROFILES["bore_lines"])
    assert list(np.sign(bore.turn_angles_deg)) == [-s for s in signs]  # mirrored material


# --- the exact contact, against closed forms ---------------------------------------------


def test_a_ball_falling_on_a_segment_touches_its_foot_or_its_nearer_end():
    seg = Line("s", (0.0, 0.0), (0.0, 10.0), side=1)  # x = 0, z from 0 to 10
    c = first_contact([seg], 1.0, (5.0, 4.0), (-1.0, 0.0))
    assert (c.distance, c.feature, c.point, c.centre) == (4.0, "s", (0.0, 4.0), (1.0, 4.0))
    # beside the end: the ball's rim meets the end point (0, 10): (5 - s)^2 + 0.6^2 = 1
    c = first_contact([seg], 1.0, (5.0, 10.6), (-1.0, 0.0))
    assert c.point == (0.0, 10.0) and c.distance == pytest.approx(5.0 - 0.8, abs=1e-12)
    assert first_contact([seg], 1.0, (5.0, 11.1), (-1.0, 0.0)) is None  # passes the end
    assert first_contact([seg], 1.0, (5.0, 4.0), (-1.0, 0.0), length=3.9) is None
    c = first_contact([seg], 1.0, (0.5, 4.0), (1.0, 0.0))  # already overlapping
    assert (c.distance, c.point) == (0.0, (0.0, 4.0))
    # at 30 degrees to the segment: contact where the distance to its line is r
    d = (-math.cos(math.radians(30)), math.sin(math.radians(30)))
    c = first_contact([seg], 1.0, (5.0, 2.0), d)
    s = 4.0 / math.cos(math.radians(30))
    assert c.distance == pytest.approx(s, abs=1e-12)
    assert c.point == pytest.approx((0.0, 2.0 + s * 0.5), abs=1e-12)


def test_a_ball_meets_an_arc_from_outside_inside_or_at_an_end():
    # a quarter circle R3 about the origin from +z (x=0, z=3) to +x (x=3, z=0)
    arc = Arc("a", (0.0, 3.0), (3.0, 0.0), (0.0, 0.0), ccw=True, side=1)
    u = (math.sin(0.6), math.cos(0.6))  # a direction inside the sweep
    c = first_contact([arc], 1.0, (10 * u[0], 10 * u[1]), (-u[0], -u[1]))  # from outside
    assert c.distance == pytest.approx(10 - 4, abs=1e-12)
    assert c.point == pytest.approx((3 * u[0], 3 * u[1]), abs=1e-12)
    c = first_contact([arc], 1.0, (0.0, 0.0), u)  # from the centre: |c| = R - r
    assert c.distance == pytest.approx(2.0, abs=1e-12)
    assert c.point == pytest.approx((3 * u[0], 3 * u[1]), abs=1e-12)
    # from the centre toward -x, outside the sweep: the ball's rim meets the end at
    # (0, 3) only if it passes within r of it; along -x it never does (distance 3)
    assert first_contact([arc], 1.0, (0.0, 0.0), (-1.0, 0.0)) is None
    # along z at x = -0.5: the rim meets the end (0, 3) when (z - 3)^2 + 0.25 = 1
    c = first_contact([arc], 1.0, (-0.5, -5.0), (0.0, 1.0))
    assert c.point == (0.0, 3.0) and c.distance == pytest.approx(8.0 - math.sqrt(0.75))
    # a ball larger than the arc's circle, from outside: |c| = R + r
    c = first_contact([arc], 4.0, (0.0, 20.0), (0.0, -1.0))
    assert c.distance == pytest.approx(13.0) and c.point == pytest.approx((0.0, 3.0))


def test_nearest_points_are_exact():
    arc = Arc("a", (0.0, 3.0), (3.0, 0.0), (0.0, 0.0), ccw=True, side=1)
    assert nearest_point(arc, (4.0, 4.0)) == pytest.approx((3 / math.sqrt(2), 3 / math.sqrt(2)))
    assert nearest_point(arc, (-1.0, 5.0)) == (0.0, 3.0)
    seg = Line("s", (0.0, 0.0), (0.0, 10.0), side=1)
    assert nearest_point(seg, (2.0, 12.0)) == (0.0, 10.0)


# --- the window rule against the exact contact --------------------------------------------


def _clip_above(f, q, n, eps=1e-9) -> list:
    """The parts of feature `f` more than `eps` above the tangent at `q` (normal `n`)."""
    if isinstance(f, Line):
        h0, h1 = (float(np.dot(np.subtract(p, q), n)) for p in (f.p0, f.p1))
        if h0 <= eps and h1 <= eps:
            return []
        if h0 > eps and h1 > eps:
            return [f]
        cut = tuple(np.add(f.p0, (eps - h0) / (h1 - h0) * np.subtract(f.p1, f.p0)))
        part = (cut, f.p1) if h1 > eps else (f.p0, cut)
        return [Line(f.id, *part, side=f.side)] if math.dist(*part) > 1e-12 else []
    a0 = math.atan2(f.p0[0] - f.center[0], f.p0[1] - f.center[1])
    k = (eps - float(np.dot(np.subtract(f.center, q), n))) / f.radius
    alpha, cuts = math.atan2(n[0], n[1]), [0.0, 1.0]
    if abs(k) <= 1.0:
        for phi in (alpha + math.acos(k), alpha - math.acos(k)):
            t = ((phi - a0) * math.copysign(1.0, f.sweep)) % (2 * math.pi) / abs(f.sweep)
            cuts += [t] if 0.0 < t < 1.0 else []
    cuts, out = sorted(cuts), []
    for ta, tb in zip(cuts[:-1], cuts[1:], strict=True):
        mid = np.asarray(f.point_at(0.5 * (ta + tb)))
        if tb - ta > 1e-12 and float(np.dot(mid - q, n)) > eps:
            pa, pb = (tuple(map(float, f.point_at(t))) for t in (ta, tb))
            out.append(Arc(f.id, pa, pb, f.center, f.ccw, side=f.side))
    return out


def _to_segment(p, a, b) -> float:
    """Distance from point `p` to the segment `a`-`b` (exact)."""
    p, a, b = (np.asarray(v, dtype=float) for v in (p, a, b))
    d = b - a
    u = 0.0 if not d.any() else min(max(float((p - a) @ d / (d @ d)), 0.0), 1.0)
    return float(np.linalg.norm(p - a - u * d))


def _exactly_usable(prof, i, t, r, ec, h, overtravel=0.5) -> bool:
    """The window's rule stated with the exact contact: the contact point keeps its end
    margins; the ball at the stand-off overlaps no feature by stock + clearance; moving
    along the approach the ball first touches its feature at the contact point; and,
    grown by the end clearance, it meets neither a part of another feature above the
    tangent at the contact nor a junction point of its own feature before it gets
    there."""
    f, last = prof.features[i], len(prof.features) - 1
    along = t * f.length
    if along < ec + (r if i == 0 else 0.0) or f.length - along < ec + (r if i == last else 0.0):
        return False
    q, n, c = (v[0] for v in ball_centres(f, [t], r))
    s = c + h * n
    if h > 0 and min(math.dist(s, nearest_point(g, s)) for g in prof) < r + h - 1e-9:
        return False
    hit = first_contact(prof, r, s, -n, length=h + overtravel)
    if hit is None or hit.feature != f.id or math.dist(hit.point, q) > 1e-6:
        return False
    edges = [e for e, j in ((f.p0, i - 1), (f.p1, i)) if 0 <= j < last]  # junctions
    if any(_to_segment(e, s, c) < r + ec - 1e-9 for e in edges):
        return False
    above = [p for j, g in enumerate(prof) if j != i for p in _clip_above(g, q, n)]
    if any(math.dist(c, nearest_point(p, c)) < r + ec - 1e-9 for p in above):
        return False  # the grown ball at contact
    meets = first_contact(above, r + ec, s, -n, length=h) if h > 0 else None
    return meets is None or meets.distance >= h - 1e-9  # and on its way there


#: mm: the window rule's distances carry this much slack (2 chord errors: the chords of a
#: concave arc lie inside it), so an edge is where a distance reaches its bound to this
SLACK_MM = 2.5e-4


#: mm along a feature: the window's edges agree with the exact rule to this (its
#: distances carry 0.2 um of slack and arcs are polylines within 0.1 um)
EDGE_MM = 2e-3


@pytest.mark.parametrize("name", sorted(PROFILES))
@pytest.mark.parametrize(("r", "ec", "h"), BALLS)
def test_the_window_is_where_the_ball_touches_its_feature_first(name, r, ec, h):
    """Every feature of each profile: inside the window the exact rule holds throughout,
    just outside its edges it fails (or the edge is the feature's end); no window where
    the exact rule holds nowhere."""
    prof = _profile(*PROFILES[name])
    for i, f in enumerate(prof.features):
        w = probe_window(prof, i, r, ec, h)
        ok = lambda t, i=i: _exactly_usable(prof, i, t, r, ec, h)  # noqa: E731
        if w is None:
            assert not any(ok(t) for t in np.linspace(0, 1, 401)), (name, f.id)
            continue
        dt = EDGE_MM / f.length
        assert all(ok(t) for t in np.linspace(w[0] + dt, w[1] - dt, 41)), (name, f.id, w)
        assert w[0] < dt or not ok(w[0] - dt), (name, f.id, w)
        assert w[1] > 1 - dt or not ok(w[1] + dt), (name, f.id, w)


def test_the_issue_s_stepped_bore_face_in_closed_form():
    """The Ø32 to Ø26 step face, a 1 mm ball, 0.5 mm of stock: its window runs from where
    the ball clears the convex edge at x = 13 by the end clearance e, x = 13 +
    sqrt(2 e + e^2) (moving along the face's normal the ball cannot touch the edge
    first: the former rule kept 1 + e), to where the stand-off, stock + clearance out,
    keeps that from the Ø32 bore: x <= 16 - 1 - (0.5 + clearance). With the defaults
    (e 0.2, clearance 1) there is none: 13.663 > 13.5."""
    prof = _profile(*PROFILES["bore_lines"])
    i = prof.index("face_z20")
    assert probe_window(prof, i, 1.0, 0.2, 1.5) is None
    for ec, clearance in [(0.1, 0.3), (0.2, 0.5), (0.0, 0.9)]:
        t0, t1 = probe_window(prof, i, 1.0, ec, 0.5 + clearance)
        lo, hi = sorted(16.0 - 3.0 * t for t in (t0, t1))
        assert math.hypot(lo - 13.0, 1.0) - (1.0 + ec) == pytest.approx(0.0, abs=SLACK_MM)
        assert lo == pytest.approx(13.0 + math.sqrt(2 * ec + ec**2), abs=3 * SLACK_MM)
        assert hi == pytest.approx(16.0 - 1.0 - 0.5 - clearance, abs=SLACK_MM)
    # no stand-off: the concave corner's side keeps the ball end_clearance from the bore
    t0, t1 = probe_window(prof, i, 1.0, 0.2)
    lo, hi = sorted(16.0 - 3.0 * t for t in (t0, t1))
    assert (lo, hi) == pytest.approx((13.0 + math.sqrt(0.44), 14.8), abs=3 * SLACK_MM)


def test_a_concave_fillet_s_window_in_closed_form():
    """The bore's fillet R2 (a concave arc, tangent to the Ø33 bore and the Z-22 face):
    its ball (radius r) sits on the circle R - r about the centre; the nearest point of
    a neighbour above the tangent is the tangent point J, |c - J|^2 = (R - r)^2 + R^2 -
    2 R (R - r) cos(phi) at an angle phi from J, which must reach (r + ec)^2; the
    stand-off point, R - r - h from the centre, likewise reaches (r + h)^2 from J; and
    the contact keeps ec along the arc from J. At the window's start the tightest of
    the three is at its bound, and the window is symmetric."""
    prof = _profile(*PROFILES["bore_arcs"])
    i = prof.index("fillet")
    big = 2.0
    for r, ec, h in [(1.0, 0.2, 0.5), (0.5, 0.05, 0.6), (0.25, 0.1, 1.0)]:

        def gap(rho, reach, phi):
            return math.sqrt(rho**2 + big**2 - 2 * big * rho * math.cos(phi)) - reach

        t0, t1 = probe_window(prof, i, r, ec, h)
        phi = t0 * math.pi / 2
        gaps = [gap(big - r, r + ec, phi), gap(big - r - h, r + h, phi), phi * big - ec]
        assert min(gaps) == pytest.approx(0.0, abs=SLACK_MM), (r, ec, h, gaps)
        assert t1 == pytest.approx(1 - t0, abs=1e-6)
        wider = t0 * math.pi / 2 - 1e-3  # a milliradian earlier, one bound is broken
        assert min(gap(big - r, r + ec, wider), gap(big - r - h, r + h, wider),
                   wider * big - ec) < -SLACK_MM  # fmt: skip


def test_a_convex_round_keeps_its_ball_clear_of_the_tangent_points():
    """The shaft's corner round R2 (convex, tangent to the face and the Ø20): moving
    along the radius the ball cannot touch the neighbours first, which bend away; it
    keeps the end clearance e from the tangent point J (where a deviated neighbour
    steps): its centre, R + r from the arc's centre at an angle phi from J, is
    sqrt((R + r)^2 + R^2 - 2 R (R + r) cos(phi)) from J, which reaches r + e; and the
    contact keeps e along the arc. The window is symmetric."""
    prof = _profile(*PROFILES["shaft_arcs"])
    i = prof.index("round")
    big = 2.0
    for r, ec in [(1.0, 0.2), (0.5, 0.05), (2.0, 0.3)]:
        t0, t1 = probe_window(prof, i, r, ec, 0.0)
        phi = t0 * math.pi / 2
        gap = math.sqrt((big + r) ** 2 + big**2 - 2 * big * (big + r) * math.cos(phi))
        assert min(gap - (r + ec), phi * big - ec) == pytest.approx(0.0, abs=SLACK_MM)
        assert t1 == pytest.approx(1 - t0, abs=1e-6), (r, ec)


def test_a_line_beside_a_concave_fillet_keeps_the_ball_clear_of_its_rise():
    """The Ø20 of the shaft toward its fillet R3 (tangent at z = -15): the fillet rises
    above the diameter's tangent line, so the ball at contact, r above the line at a
    distance a before the tangent point J, keeps r + ec from J: a^2 + r^2 = (r + ec)^2
    (the fillet's other points are farther: it curves away from the ball)."""
    prof = _profile(*PROFILES["shaft_arcs"])
    i = prof.index("dia_20")
    for r, ec in [(1.0, 0.2), (0.5, 0.05)]:
        _, t1 = probe_window(prof, i, r, ec, 0.0)
        a = (1 - t1) * 13.0
        assert math.hypot(a, r) - (r + ec) == pytest.approx(0.0, abs=SLACK_MM), (r, ec)
        assert a == pytest.approx(math.sqrt(2 * r * ec + ec**2), abs=2 * SLACK_MM)
