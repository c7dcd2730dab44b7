"""Geometry identities with known answers."""

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from piecs_bayes.geometry import (
    Arc,
    Line,
    MachineTransform,
    Profile,
    ProfileError,
    ball_correction,
    intersect_circle_circle,
    intersect_line_circle,
    intersect_line_line,
    machine_to_part,
    make_feature,
    part_to_machine,
    profile_side,
)
from piecs_bayes.simulate import demo_profile

LINE = Line("d", (12.0, 0.0), (12.0, -30.0), side=-1)
TAPER = Line("t", (12.0, -30.0), (15.0, -45.0), side=-1)
FILLET = Arc("f", (15.0, -57.0), (18.0, -60.0), (18.0, -57.0), ccw=False, side=-1)


def test_outward_normals_of_an_external_profile_point_away_from_material():
    prof = demo_profile()
    assert np.allclose(prof["dia_24"].normal, [1.0, 0.0])  # +x on a diameter
    assert np.allclose(prof["face_end"].normal, [0.0, 1.0])  # +z on the end face
    assert np.allclose(prof["shoulder"].normal, [0.0, 1.0])
    assert prof["fillet"].sense == -1  # inside corner: concave
    assert prof.junctions == ("sharp", "sharp", "sharp", "tangent", "tangent", "sharp")
    assert prof.turn_angles_deg[0] == pytest.approx(90.0)
    assert prof.turn_angles_deg[1] == pytest.approx(-math.degrees(math.atan2(3, 15)))


@pytest.mark.parametrize("feature", [LINE, TAPER, FILLET])
@pytest.mark.parametrize("dev_scale", [0.0, 1.0])
def test_points_built_on_a_feature_have_zero_distance(feature, dev_scale):
    dev = dev_scale * jnp.array([0.013, -0.002, 0.004][: feature.nparams])
    pts = feature.point_at(jnp.linspace(0, 1, 11), dev)
    assert np.max(np.abs(feature.signed_distance(pts, dev))) < 1e-12
    # offset outward by d: signed distance d; closest point is the foot
    off = pts + 0.25 * feature.outward_normal(pts, dev)
    assert np.allclose(feature.signed_distance(off, dev), 0.25, atol=1e-12)
    assert np.allclose(feature.closest_point(off, dev), pts, atol=1e-12)


_ARCS = [  # both senses of travel, material on either side, a sweep across +-pi
    Arc("cw", (15.0, -57.0), (18.0, -60.0), (18.0, -57.0), ccw=False, side=-1),
    Arc("ccw", (18.0, -60.0), (15.0, -57.0), (18.0, -57.0), ccw=True, side=1),
    Arc("big", (10.0, -5.0), (10.0, 5.0), (10.0, 0.0), ccw=False, side=1),
    Arc("wrap", (10.0, 5.0), (10.0, -5.0), (10.0, 0.0), ccw=False, side=-1),
]


@pytest.mark.parametrize(
    "feature", [LINE, TAPER, Line("r", (0.0, 0.0), (-3.0, 4.0), side=1), *_ARCS]
)
def test_drawn_points_and_normals_are_the_models(feature):
    """`drawn_at` (NumPy, for figures) gives `point_at` and `outward_normal` of the
    feature as drawn."""
    t = np.linspace(0.0, 1.0, 17)
    q, n = feature.drawn_at(t)
    assert isinstance(q, np.ndarray) and q.shape == n.shape == (17, 2)
    np.testing.assert_allclose(q, feature.point_at(jnp.asarray(t)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(n, feature.outward_normal(jnp.asarray(q)), rtol=0, atol=1e-12)
    np.testing.assert_allclose(q[[0, -1]], [feature.p0, feature.p1], rtol=0, atol=1e-12)
    off = q + 0.2 * n + 0.05 * np.roll(n, 1, axis=-1)  # and off the curve
    np.testing.assert_allclose(
        feature.drawn_normal(off), feature.outward_normal(jnp.asarray(off)), rtol=0, atol=1e-12
    )
    # and the distance of points near it from the feature deviated, as `signed_distance`
    dev = np.array([0.013, -0.002, 0.004][: feature.nparams])
    near = q + np.linspace(-0.3, 0.3, 17)[:, None] * n + 0.1 * np.roll(n, 1, axis=-1)
    d = feature.drawn_distance(near, dev)
    assert isinstance(d, np.ndarray) and d.shape == (17,)
    want = feature.signed_distance(jnp.asarray(near), jnp.asarray(dev))
    np.testing.assert_allclose(d, want, rtol=0, atol=1e-12)
    # and the deviated feature's points and normals, as `point_at(t, dev)` gives them,
    # for one deviation and for a batch of them (leading axes)
    q_dev, n_dev = feature.drawn_at(t, dev)
    np.testing.assert_allclose(q_dev, feature.point_at(jnp.asarray(t), dev), rtol=0, atol=1e-12)
    np.testing.assert_allclose(
        n_dev, feature.outward_normal(jnp.asarray(q_dev), dev), rtol=0, atol=1e-12
    )
    devs = np.stack([dev, -dev, np.zeros_like(dev)])
    q_many, n_many = feature.drawn_at(t, devs)
    assert q_many.shape == n_many.shape == (3, 17, 2)
    for j, d in enumerate(devs):
        np.testing.assert_allclose(q_many[j], feature.point_at(jnp.asarray(t), d), atol=1e-12)
        np.testing.assert_allclose(n_many[j], feature.drawn_at(t, d)[1], rtol=0, atol=0)
    np.testing.assert_allclose(q_many[2], q, rtol=0, atol=1e-12)


def test_line_deviation_parameters_mean_what_they_say():
    # offset 0.01 along +x at the mid-point (z=-15), rotation 0.001 rad CCW about it
    point, direction, _ = LINE.actual(jnp.array([0.01, 0.001]))

    def x_at(z):
        return float(
            intersect_line_line(point, direction, jnp.array([0.0, z]), jnp.array([1.0, 0.0]))[0]
        )

    assert x_at(-15.0) == pytest.approx(12.01, abs=1e-12)
    # travelling -z (drawing: leftwards), a CCW turn bends the line down (-x)
    assert x_at(0.0) == pytest.approx(12.01 + 15.0 * math.tan(0.001), abs=1e-12)
    assert x_at(-30.0) == pytest.approx(12.01 - 15.0 * math.tan(0.001), abs=1e-12)


def test_arc_radius_change_moves_a_concave_surface_into_the_material():
    dev = jnp.array([0.0, 0.0, 0.01])
    mid = FILLET.point_at(jnp.array(0.5))
    # concave: outward normal points to the centre; a bigger radius cuts deeper
    assert float(FILLET.signed_distance(mid, dev)) == pytest.approx(0.01, abs=1e-12)


def test_line_line_intersection():
    p = intersect_line_line(
        jnp.array([0.0, 0.0]), jnp.array([1.0, 1.0]), jnp.array([0.0, 2.0]), jnp.array([1.0, -1.0])
    )
    assert np.allclose(p, [1.0, 1.0], atol=1e-15)
    par = intersect_line_line(
        jnp.zeros(2), jnp.array([1.0, 0.0]), jnp.array([0.0, 1.0]), jnp.array([2.0, 0.0])
    )
    assert np.all(np.isnan(par))


def test_line_circle_intersection_picks_the_branch_nearest_the_reference():
    c, r = jnp.array([0.0, 0.0]), 5.0
    p, u = jnp.array([3.0, -10.0]), jnp.array([0.0, 1.0])  # x=3 line: meets at z=+-4
    assert np.allclose(intersect_line_circle(p, u, c, r, jnp.array([3.0, 3.0])), [3.0, 4.0])
    assert np.allclose(intersect_line_circle(p, u, c, r, jnp.array([3.0, -3.0])), [3.0, -4.0])
    assert np.all(np.isnan(intersect_line_circle(jnp.array([6.0, 0.0]), u, c, r, p)))


def test_circle_circle_intersection():
    # (0,0) r=5 and (8,0) r=5 meet at (4, +-3)
    a = intersect_circle_circle(
        jnp.zeros(2), 5.0, jnp.array([8.0, 0.0]), 5.0, jnp.array([4.0, 2.0])
    )
    b = intersect_circle_circle(
        jnp.zeros(2), 5.0, jnp.array([8.0, 0.0]), 5.0, jnp.array([4.0, -2.0])
    )
    assert np.allclose(a, [4.0, 3.0], atol=1e-14) and np.allclose(b, [4.0, -3.0], atol=1e-14)
    assert np.all(
        np.isnan(
            intersect_circle_circle(jnp.zeros(2), 1.0, jnp.array([8.0, 0.0]), 1.0, jnp.zeros(2))
        )
    )


def test_intersections_are_differentiable():
    def f(x):
        return intersect_line_line(
            jnp.array([x, 0.0]), jnp.array([0.0, 1.0]), jnp.zeros(2), jnp.array([1.0, 1.0])
        )

    assert np.allclose(jax.jacfwd(f)(2.0), [1.0, 1.0])


def test_machine_part_transform_and_inverse():
    t = MachineTransform(
        x_centre=0.003, z_offset=-312.5, scale_x=12e-6, scale_z=-8e-6, rotation=2e-5
    )
    pts = jnp.array([[26.0, -315.0], [44.0, -400.0], [0.0, 0.0]])
    back = part_to_machine(machine_to_part(pts, t), t)
    assert np.max(np.abs(back - pts)) < 1e-12
    plain = machine_to_part(pts, MachineTransform(x_centre=1.0, z_offset=-300.0))
    assert np.allclose(plain, pts - jnp.array([1.0, -300.0]), atol=1e-14)
    scaled = machine_to_part(jnp.array([[10.0, 0.0]]), MachineTransform(scale_x=1e-5))
    assert float(scaled[0, 0]) == pytest.approx(10.0001, abs=1e-12)
    # concrete NumPy points map in NumPy, one transform or one per leading index
    part = np.asarray(machine_to_part(pts, t))
    np.testing.assert_allclose(part_to_machine(part, t), pts, rtol=0, atol=1e-12)
    assert isinstance(part_to_machine(part, t), np.ndarray)
    ts = np.stack([t.as_numpy(), np.zeros(5), np.array([1.0, -300.0, 1e-5, 2e-5, -3e-5])])
    many = part_to_machine(np.stack([part] * 3), ts)
    assert many.shape == (3, 3, 2)
    for j in range(3):
        np.testing.assert_allclose(many[j], part_to_machine(jnp.asarray(part), ts[j]), atol=1e-12)


def test_ball_correction_lands_on_the_surface():
    for feat in (LINE, TAPER, FILLET):
        surf = feat.point_at(jnp.linspace(0.1, 0.9, 5))
        centres = surf + 1.5 * feat.outward_normal(surf)
        assert np.allclose(ball_correction(centres, feat, 1.5), surf, atol=1e-12)


def test_profile_side_flips_for_internal_profiles_and_reversed_travel():
    specs = [dict(id="a", p0=(10.0, 0.0), p1=(10.0, -30.0))]
    assert profile_side(specs) == -1
    assert profile_side(specs, internal=True) == 1
    assert profile_side([dict(id="a", p0=(10.0, -30.0), p1=(10.0, 0.0))]) == 1


def test_profile_rejects_gaps_and_duplicate_ids():
    a = make_feature(dict(id="a", p0=(10.0, 0.0), p1=(10.0, -30.0)), -1)
    b = make_feature(dict(id="b", p0=(10.5, -30.0), p1=(15.0, -30.0)), -1)
    with pytest.raises(
        ProfileError, match=r"not connected: 'a' ends at \(x=10, z=-30\) but 'b' starts at \(x=10.5"
    ):
        Profile((a, b))
    with pytest.raises(ProfileError, match="used twice"):
        Profile((a, a))
