"""Intersections of lines and circles, choosing the branch nearest a reference point.

Lines are ``(point, direction)``, circles ``(centre, radius)``; all inputs are
``(x, z)`` arrays. The functions are pure and differentiable; where there is no
intersection (parallel lines, disjoint circles) they return NaN, which callers
turn into an :class:`~piecs_bayes.errors.AnalysisError` naming the junction.
"""

from __future__ import annotations

import jax.numpy as jnp


def _cross(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def intersect_line_line(p, u, q, v):
    """Intersection of lines ``p + t u`` and ``q + s v`` (NaN if parallel)."""
    p, u, q, v = map(jnp.asarray, (p, u, q, v))
    den = _cross(u, v)
    t = _cross(q - p, v) / jnp.where(den == 0, jnp.nan, den)
    return p + t[..., None] * u


def _pick(a, b, ref):
    da = jnp.sum((a - ref) ** 2, axis=-1)
    db = jnp.sum((b - ref) ** 2, axis=-1)
    return jnp.where((da <= db)[..., None], a, b)


def intersect_line_circle(p, u, c, r, ref):
    """Intersection of line ``p + t u`` with circle ``(c, r)`` nearest ``ref``
    (NaN if the line misses the circle)."""
    p, u, c, r, ref = map(jnp.asarray, (p, u, c, r, ref))
    u = u / jnp.sqrt(jnp.sum(u**2, axis=-1, keepdims=True))
    w = p - c
    b = jnp.sum(w * u, axis=-1)
    disc = b**2 - (jnp.sum(w**2, axis=-1) - r**2)
    root = jnp.sqrt(jnp.where(disc < 0, jnp.nan, disc))
    a1 = p + (-b - root)[..., None] * u
    a2 = p + (-b + root)[..., None] * u
    return _pick(a1, a2, ref)


def intersect_circle_circle(c1, r1, c2, r2, ref):
    """Intersection of circles ``(c1, r1)`` and ``(c2, r2)`` nearest ``ref``
    (NaN if they do not meet)."""
    c1, r1, c2, r2, ref = map(jnp.asarray, (c1, r1, c2, r2, ref))
    d_vec = c2 - c1
    d = jnp.sqrt(jnp.sum(d_vec**2, axis=-1))
    a = (d**2 + r1**2 - r2**2) / (2 * d)
    h2 = r1**2 - a**2
    h = jnp.sqrt(jnp.where(h2 < 0, jnp.nan, h2))
    e = d_vec / d[..., None]
    base = c1 + a[..., None] * e
    perp = jnp.stack([-e[..., 1], e[..., 0]], axis=-1)
    return _pick(base + h[..., None] * perp, base - h[..., None] * perp, ref)
