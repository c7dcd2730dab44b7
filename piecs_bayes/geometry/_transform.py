"""Machine-to-part transform and stylus ball correction.

Machine coordinates are the probe's ball-centre positions as the machine reports
them (radius X, after any diameter-mode halving at the file boundary). The part
frame is the drawing's. The transform, with its parameters all small except the
offsets::

    u = (x_m - x_centre, z_m - z_offset)          # centre-line and work offset
    s = ((1 + scale_x) u_x, (1 + scale_z) u_z)    # axis scale errors
    p = rotate(s, rotation)                        # small squareness / rotation

and its exact inverse. Scale errors and rotation are also uncertainty sources.
"""

from __future__ import annotations

from dataclasses import dataclass

import jax
import jax.numpy as jnp
import numpy as np

from ._curves import rotate


@dataclass(frozen=True)
class MachineTransform:
    """Parameters of the machine -> part transform (mm, and dimensionless / rad)."""

    x_centre: float = 0.0
    z_offset: float = 0.0
    scale_x: float = 0.0
    scale_z: float = 0.0
    rotation: float = 0.0

    def as_array(self):
        """The 5-vector `(x_centre, z_offset, scale_x, scale_z, rotation)` as a JAX array
        (numbers are transferred: no program is compiled to build it)."""
        values = (self.x_centre, self.z_offset, self.scale_x, self.scale_z, self.rotation)
        if all(isinstance(v, int | float | np.number) for v in values):
            return jax.device_put(np.array(values, dtype=float))
        return jnp.array(values)

    def as_numpy(self) -> np.ndarray:
        """The 5-vector of `as_array` as a NumPy array (no JAX operation)."""
        return np.array([self.x_centre, self.z_offset, self.scale_x, self.scale_z, self.rotation])


def machine_to_part(points, params):
    """Map machine ``(x, z)`` points to the part frame.

    ``params`` is a :class:`MachineTransform` or its 5-vector
    ``(x_centre, z_offset, scale_x, scale_z, rotation)`` (differentiable).
    """
    if isinstance(params, MachineTransform) and not isinstance(points, jax.core.Tracer):
        return _machine_to_part_np(np.asarray(points, dtype=float), params)
    t = params.as_array() if isinstance(params, MachineTransform) else params
    return _machine_to_part(points, t)


def _machine_to_part_np(pts: np.ndarray, tr: MachineTransform) -> np.ndarray:
    """`machine_to_part` of concrete points in NumPy (no JAX dispatch: loading data)."""
    u = (pts - [tr.x_centre, tr.z_offset]) * [1.0 + tr.scale_x, 1.0 + tr.scale_z]
    c, s = np.cos(tr.rotation), np.sin(tr.rotation)
    x, z = u[..., 0], u[..., 1]
    return np.stack([c * x + s * z, -s * x + c * z], axis=-1)


@jax.jit  # one compiled call, not ~10 eager operations (loading a study, the CLI)
def _machine_to_part(points, t):
    t = jnp.asarray(t, dtype=float)
    u = jnp.asarray(points, dtype=float) - jnp.stack([t[0], t[1]])
    s = u * jnp.stack([1.0 + t[2], 1.0 + t[3]])
    return rotate(s, t[4])


def part_to_machine(points, params):
    """Exact inverse of :func:`machine_to_part`. Concrete NumPy points and a
    `MachineTransform` or NumPy parameters (``(..., 5)``, one transform per leading
    index of ``points``: ``(..., n, 2)``) are mapped in NumPy, to a NumPy array."""
    if isinstance(params, MachineTransform):
        params = params.as_numpy()
    if isinstance(points, np.ndarray) and isinstance(params, np.ndarray):
        return _part_to_machine_np(points.astype(float), params.astype(float))
    return _part_to_machine(points, params)


def _part_to_machine_np(pts: np.ndarray, t: np.ndarray) -> np.ndarray:
    """`part_to_machine` of concrete points in NumPy (no JAX dispatch: simulated probing)."""
    t = t[..., None, :] if t.ndim > 1 else t
    c, s = np.cos(-t[..., 4]), np.sin(-t[..., 4])
    x, z = pts[..., 0], pts[..., 1]
    u = np.stack([c * x + s * z, -s * x + c * z], axis=-1)
    return u / np.stack([1.0 + t[..., 2], 1.0 + t[..., 3]], axis=-1) + np.stack(
        [t[..., 0], t[..., 1]], axis=-1
    )


@jax.jit  # one compiled call, not ~10 eager operations (28 ms a call: simulated probing)
def _part_to_machine(points, t):
    t = jnp.asarray(t, dtype=float)
    s = rotate(jnp.asarray(points, dtype=float), -t[4])
    u = s / jnp.stack([1.0 + t[2], 1.0 + t[3]])
    return u + jnp.stack([t[0], t[1]])


def ball_correction(centres, feature, radius, dev=None):
    """Surface contact points of a ball of ``radius`` whose centres touched ``feature``.

    The ball touches from outside the material, so the contact point lies one
    ball radius back from the centre along the feature's outward normal at the
    nearest point (of the deviated feature when ``dev`` is given).
    """
    centres = jnp.asarray(centres)
    n = feature.outward_normal(centres, dev)
    return centres - radius * n
