"""PIECS mirroring and re-intersection: fitted deviations -> adjusted tool path.

The compensated feature is the nominal one with its fitted deviation mirrored times a
gain, `dev_c = -gain * dev` ([`compensated_deviations`][]); [`adjusted_geometry`][]
rebuilds the path's vertices (and the arcs' centres and radii) from the compensated
features one junction at a time (NISTIR 5797 re-intersection, tangency kept where an
arc meets a neighbour tangentially); [`adjusted_path`][] returns them as an
[`AdjustedPath`][] (part frame, mm, X a radius), refusing with `AnalysisError`
compensated features that do not meet and, with `max_correction`, a vertex that moves
farther. Everything is a pure JAX function of the deviations, so the Jacobians of every
vertex with respect to every fitted parameter come from `jax.jacfwd`.

The junction rules: docs/models/mirroring.md.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import AnalysisError
from ..geometry import (
    Arc,
    Line,
    Profile,
    intersect_circle_circle,
    intersect_line_circle,
    intersect_line_line,
)
from ..io import rows_to_dataframe


def compensated_deviations(profile: Profile, deviations, gain=1.0):
    """Mirror fitted deviations: ``-gain * dev`` per feature (a tuple in profile order).

    ``deviations`` is a sequence (profile order) or a dict by feature id of
    deviation vectors; a missing feature (not measured) is left as drawn.
    ``gain`` is a scalar or a dict by feature id.
    """
    out = []
    for i, f in enumerate(profile.features):
        if isinstance(deviations, dict):
            d = deviations.get(f.id)
        else:
            d = deviations[i]
        d = jnp.zeros(f.nparams) if d is None else jnp.asarray(d, dtype=float)
        g = gain.get(f.id, 1.0) if isinstance(gain, dict) else gain
        out.append(-g * d)
    return tuple(out)


def _curve(f, dev):
    if isinstance(f, Line):
        point, direction, normal = f.actual(dev)
        return ("line", point, direction, normal)
    c, r = f.actual(dev)
    return ("circle", c, r)


def _tangent_offset_kind(arc: Arc, nb) -> tuple[str, float]:
    """How arc ``arc`` touches neighbour ``nb`` nominally: for a line, the side
    (+1/-1 along its normal) of the arc centre; for an arc, external or internal."""
    c = np.array(arc.center)
    if isinstance(nb, Line):
        d = (np.array(nb.p1) - np.array(nb.p0)) / nb.length
        normal = nb.side * np.array([d[1], -d[0]])  # nominal outward normal, NumPy (static)
        s = float(np.dot(c - np.array(nb.p0), normal))
        return "line", 1.0 if s > 0 else -1.0
    d = float(np.linalg.norm(c - np.array(nb.center)))
    ext, inn = nb.radius + arc.radius, abs(nb.radius - arc.radius)
    if abs(d - ext) <= abs(d - inn):
        return "ext", 1.0
    return ("int_big_nb", 1.0) if nb.radius > arc.radius else ("int_small_nb", 1.0)


def _offset_curve(curve, kind, sign, r):
    """Locus of centres of circles of radius ``r`` tangent to ``curve`` (same side as nominal)."""
    if curve[0] == "line":
        _, p, u, n = curve
        return ("line", p + sign * r * n, u, n)
    _, c, rn = curve
    rho = {"ext": rn + r, "int_big_nb": rn - r, "int_small_nb": r - rn}[kind]
    return ("circle", c, rho)


def _meet(a, b, ref):
    if a[0] == "line" and b[0] == "line":
        return intersect_line_line(a[1], a[2], b[1], b[2])
    if a[0] == "line":
        return intersect_line_circle(a[1], a[2], b[1], b[2], ref)
    if b[0] == "line":
        return intersect_line_circle(b[1], b[2], a[1], a[2], ref)
    return intersect_circle_circle(a[1], a[2], b[1], b[2], ref)


def _project(curve, p):
    if curve[0] == "line":
        _, q, _, n = curve
        return p - jnp.dot(p - q, n) * n
    _, c, r = curve
    v = p - c
    return c + r * v / jnp.linalg.norm(v)


def adjusted_geometry(profile: Profile, dev_c):
    """Vertices, arc centres and arc radii of the compensated profile.

    **Arguments:**

    - `profile`: the nominal profile (static structure).
    - `dev_c`: compensated deviations, one vector per feature (profile order),
      e.g. from :func:`compensated_deviations`.

    **Returns:** ``(vertices, centres, radii)``: ``(n+1, 2)`` path vertices
    (start, junctions, end), ``(n, 2)`` centres (NaN for lines) and ``(n,)``
    radii (NaN for lines). NaN vertices mean two curves that do not meet.
    """
    feats = profile.features
    nf = len(feats)
    curves = [_curve(f, d) for f, d in zip(feats, dev_c, strict=True)]
    tangent = list(profile.junctions)
    # 1. Re-place arcs at tangent junctions (in profile order; uses the already
    #    adjusted previous neighbour and the compensated next one).
    for i, f in enumerate(feats):
        if not isinstance(f, Arc):
            continue
        prev_t = i > 0 and tangent[i - 1] == "tangent"
        next_t = i < nf - 1 and tangent[i] == "tangent"
        if not (prev_t or next_t):
            continue
        _, c, r = curves[i]
        loci = []
        for j, is_t in ((i - 1, prev_t), (i + 1, next_t)):
            if is_t:
                kind, sign = _tangent_offset_kind(f, feats[j])
                loci.append(_offset_curve(curves[j], kind, sign, r))
        if len(loci) == 2:
            c = _meet(loci[0], loci[1], jnp.array(f.center))
        else:
            c = _project(loci[0], c)
        curves[i] = ("circle", c, r)
    # 2. Vertices.
    nominal_v = profile.vertices
    verts = [_project(curves[0], jnp.asarray(nominal_v[0]))]
    for j in range(nf - 1):
        a, b = curves[j], curves[j + 1]
        ref = jnp.asarray(nominal_v[j + 1])
        if tangent[j] == "tangent":
            if a[0] == "line" and b[0] == "line":
                v = 0.5 * (_project(a, ref) + _project(b, ref))
            elif b[0] == "circle" and a[0] == "line":
                v = _project(a, b[1])
            elif a[0] == "circle" and b[0] == "line":
                v = _project(b, a[1])
            else:  # arc-arc: the point of the later arc nearest the earlier centre's ray
                v = _project(b, _project(a, ref))
        else:
            v = _meet(a, b, ref)
        verts.append(v)
    verts.append(_project(curves[-1], jnp.asarray(nominal_v[-1])))
    nan2 = jnp.full(2, jnp.nan)
    centres = jnp.stack([c[1] if c[0] == "circle" else nan2 for c in curves])
    radii = jnp.stack(
        [jnp.asarray(c[2], dtype=float) if c[0] == "circle" else jnp.nan for c in curves]
    )
    return jnp.stack(verts), centres, radii


@dataclass(frozen=True, eq=False)
class AdjustedPath:
    """The compensated finish-cut contour.

    ``profile`` is a :class:`Profile` with the nominal feature ids and the
    compensated geometry (what a program rewrite consumes); ``vertices`` the
    ``(n+1, 2)`` path vertices; ``shift`` the vertex moves from nominal (mm);
    ``correction`` per feature the largest normal distance (mm) between the
    nominal and the compensated curve;
    ``dev_c`` the compensated deviations used.
    """

    nominal: Profile
    profile: Profile
    vertices: np.ndarray
    shift: np.ndarray
    correction: np.ndarray
    dev_c: tuple
    gain: object

    @property
    def max_shift(self) -> float:
        return float(np.max(np.linalg.norm(self.shift, axis=1)))

    def rows(self) -> list[dict]:
        """One row per vertex (toolpath.csv): the features it joins, the junction, its
        nominal and adjusted position and move (part frame, mm, X as a radius)."""
        ids, junctions = self.nominal.ids, self.nominal.junctions
        rows = []
        for j, (v, nv) in enumerate(zip(self.vertices, self.nominal.vertices, strict=True)):
            before = ids[j - 1] if j > 0 else ""
            after = ids[j] if j < len(ids) else ""
            rows.append(
                {
                    "vertex": j,
                    "between": f"{before}|{after}".strip("|"),
                    "junction": junctions[j - 1] if 0 < j < len(ids) else "end",
                    "nominal_x_radius_mm": float(nv[0]),
                    "nominal_z_mm": float(nv[1]),
                    "x_radius_mm": float(v[0]),
                    "z_mm": float(v[1]),
                    "dx_radius_mm": float(v[0] - nv[0]),
                    "dz_mm": float(v[1] - nv[1]),
                }
            )
        return rows

    def to_dataframe(self):
        """The vertices as a `pandas.DataFrame`: `rows()`, the columns of toolpath.csv."""
        return rows_to_dataframe(self.rows())

    def __repr__(self) -> str:
        return (
            f"AdjustedPath({len(self.profile)} features, {len(self.vertices)} vertices, "
            f"largest correction {float(np.max(self.correction)) * 1000:.1f} um)"
        )


JOIN_TOLERANCE = 1e-4
"""mm: how far apart in radius a compensated arc's rebuilt end vertices may lie. A
join of an arc with a tangent neighbour is ill-conditioned (the intersection's
discriminant is near zero): its vertex comes a few nm off the circle, and the centre is
moved onto the vertices' perpendicular bisector (the vertices, shared with the
neighbours, stay where they are)."""


def _equidistant_centre(fid: str, p0, p1, centre):
    """`centre` projected onto the perpendicular bisector of `p0`-`p1`, or an
    `AnalysisError` when the vertices' distances differ by more than `JOIN_TOLERANCE`."""
    c, a, b = np.asarray(centre), np.asarray(p0), np.asarray(p1)
    d0, d1 = float(np.hypot(*(a - c))), float(np.hypot(*(b - c)))
    if abs(d0 - d1) > JOIN_TOLERANCE:
        raise AnalysisError(
            f"compensated arc {fid!r}: its end vertices lie {abs(d0 - d1) * 1e3:.3f} um apart "
            f"in radius ({d0:.6f} and {d1:.6f} mm): the neighbours' corrections do not meet it"
        )
    t = (b - a) / float(np.hypot(*(b - a)))
    return tuple(map(float, c - float((c - 0.5 * (a + b)) @ t) * t))


def adjusted_path(profile: Profile, deviations, *, gain=1.0, max_correction: float | None = None):
    """Mirror the fitted deviations and rebuild the contour.

    **Arguments:**

    - `profile`: nominal profile.
    - `deviations`: fitted deviation per feature (dict by id or sequence).
    - `gain`: feedback gain in [0, 1], scalar or per feature id.
    - `max_correction`: refuse (``AnalysisError``) a vertex moving farther (mm).

    **Returns:** an :class:`AdjustedPath`.
    """
    dev_c = compensated_deviations(profile, deviations, gain)
    verts, centres, radii = jax.device_get(adjusted_geometry(profile, dev_c))
    verts = np.asarray(verts)
    nominal_v = profile.vertices
    for j, v in enumerate(verts):
        if not np.all(np.isfinite(v)):
            where = (
                f"between {profile.features[j - 1].id!r} and {profile.features[j].id!r}"
                if 0 < j < len(profile)
                else "at an end of the profile"
            )
            raise AnalysisError(f"compensated features do not meet {where}: no vertex can be built")
    shift = verts - nominal_v
    feats = []
    for i, f in enumerate(profile.features):
        p0, p1 = tuple(map(float, verts[i])), tuple(map(float, verts[i + 1]))
        if isinstance(f, Arc):
            c = _equidistant_centre(f.id, p0, p1, centres[i])
            feats.append(Arc(f.id, p0, p1, c, f.ccw, f.side, f.tolerance))
        else:
            feats.append(Line(f.id, p0, p1, f.side, f.tolerance))
    # Size of the correction: normal distance from the nominal curve to the
    # compensated one, at the nominal end points and mid-point of each feature.
    correction = np.array(
        [
            np.max(np.abs(g.drawn_distance(f.drawn_at(np.array([0.0, 0.5, 1.0]))[0], zero)))
            for f, g in zip(profile.features, feats, strict=True)
            for zero in [np.zeros(g.nparams)]  # NumPy: no JAX operation per feature
        ]
    )
    if max_correction is not None:
        i = int(np.argmax(correction))
        if correction[i] > max_correction:
            raise AnalysisError(
                f"feature {profile.features[i].id!r} would be corrected by {correction[i]:.4f} mm, "
                f"more than the configured maximum correction {max_correction:g} mm; "
                "check the fit or raise compensation.max_correction"
            )
    adjusted = Profile(tuple(feats), tangent_tol_deg=profile.tangent_tol_deg)
    return AdjustedPath(
        profile, adjusted, verts, shift, correction, tuple(np.asarray(d) for d in dev_c), gain
    )
