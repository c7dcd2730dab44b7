"""The probing measurement model shared by the Bayesian fit and GUM propagation.

A trigger's residual is the signed distance of its ball centre, moved to the
part frame by the machine transform with the error sources applied, from the
deviated feature, minus the (corrected) ball radius. The sources:

| source | effect |
|---|---|
| ``x_centre``, ``z_offset``, ``scale_x``, ``scale_z``, ``rotation`` | added to the transform |
| ``thermal`` | a common expansion error, added to both axis scales |
| ``ball_radius`` | added to the calibrated ball radius |
| ``pretravel`` | the trigger comes late along the approach direction (into the material) |
"""

from __future__ import annotations

import jax.numpy as jnp

from ..geometry import machine_to_part

__all__ = ["SOURCE_EFFECTS", "SOURCE_UNITS", "probe_residuals"]

#: Sources that act in the measurement model (``repeatability`` is the noise itself).
SOURCE_EFFECTS = (
    "ball_radius",
    "pretravel",
    "x_centre",
    "z_offset",
    "scale_x",
    "scale_z",
    "rotation",
    "thermal",
)
#: Unit of each source's value (and of ``repeatability``, the probe sigma) in tables;
#: "1": a ratio (an axis scale or expansion error, e.g. 1e-5 = 10 um/m).
SOURCE_UNITS = {
    "ball_radius": "mm",
    "pretravel": "mm",
    "x_centre": "mm",
    "z_offset": "mm",
    "scale_x": "1",
    "scale_z": "1",
    "rotation": "rad",
    "thermal": "1",
    "repeatability": "mm",
}
_TRANSFORM_INDEX = {"x_centre": 0, "z_offset": 1, "scale_x": 2, "scale_z": 3, "rotation": 4}


def probe_residuals(groups, devs, points, deltas, *, transform, ball_radius, approach=None):
    """Residuals of every trigger, feature by feature.

    **Arguments:**

    - `groups`: ``(feature, indices)`` pairs: the triggers of each feature.
    - `devs`: the deviation of each feature in `groups` (same order).
    - `points`: ``(n, 2)`` ball centres, machine frame, radius X.
    - `deltas`: ``{source: value}`` for sources in ``SOURCE_EFFECTS`` (traced values).
    - `transform`: the study's transform as its 5-vector.
    - `approach`: ``(n, 2)`` unit approach directions, or None (the pretravel
      then acts against the outward normal).

    **Returns:** the residuals, concatenated in `groups` order.
    """
    t = transform
    for name, v in deltas.items():
        if name in _TRANSFORM_INDEX:
            t = t.at[_TRANSFORM_INDEX[name]].add(v)
        elif name == "thermal":
            t = t.at[2].add(v).at[3].add(v)
    rb = ball_radius + deltas.get("ball_radius", 0.0)
    part = machine_to_part(points, t)
    out = []
    for (f, idx), d in zip(groups, devs, strict=True):
        q = part[idx]
        if "pretravel" in deltas:
            a = approach[idx] if approach is not None else -f.outward_normal(q, d)
            q = q - deltas["pretravel"] * a
        out.append(f.signed_distance(q, d) - rb)
    return jnp.concatenate(out)
