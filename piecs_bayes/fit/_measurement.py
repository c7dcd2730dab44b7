r"""The probing measurement model shared by the Bayesian fit and GUM propagation.

[`probe_residuals`][] gives every trigger's residual: the signed distance of its ball
centre (machine frame, mm, radius X), moved to the part frame by the machine transform
with the error sources applied, from the deviated feature, minus the (corrected) ball
radius. `SOURCE_EFFECTS` names the sources (`x_centre`, `z_offset`, `scale_x`,
`scale_z`, `rotation`, `thermal`, `ball_radius`, `pretravel`) and `SOURCE_UNITS` their
units. A probe calibration's covariance enters as [`RadiusComponents`][]: independent
unit components (`probe_cal_1`, ...), each moving the radius at the approach angle,
correlated over every point through the calibration's coefficients
(`is_calibration_source`, `CALIBRATION_SOURCE`).

Each source's effect: docs/models/bayes_fit.md, "The measurement model".
"""

from __future__ import annotations

from dataclasses import dataclass

import jax.numpy as jnp

from ..geometry import machine_to_part

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
#: The name of the probe calibration in budgets; its components are ``probe_cal_<j>``.
CALIBRATION_SOURCE = "probe calibration"
_CAL_PREFIX = "probe_cal_"


@dataclass(frozen=True)
class RadiusComponents:
    """A probe calibration's covariance as independent components of the radius.

    `orders`: the Fourier orders of r(theta); `vectors`: ``(p, m)`` as nested tuples,
    column j the coefficients moved by one unit of component j; `sds`: each
    component's standard deviation (mm). Hashable: compiled models are cached by it.
    """

    orders: tuple[int, ...]
    vectors: tuple[tuple[float, ...], ...]
    sds: tuple[float, ...]

    @classmethod
    def from_calibration(cls, cal) -> RadiusComponents:
        """From an `io.ProbeCalibration` (its covariance's eigen-decomposition)."""
        sds, v = cal.components()
        return cls(
            tuple(int(k) for k in cal.orders),
            tuple(tuple(float(x) for x in row) for row in v),
            tuple(float(x) for x in sds),
        )

    @property
    def names(self) -> tuple[str, ...]:
        """The component sources, ``probe_cal_1`` ... (one per `sds`)."""
        return tuple(f"{_CAL_PREFIX}{j + 1}" for j in range(len(self.sds)))

    @property
    def source_sd(self) -> dict[str, float]:
        return dict(zip(self.names, self.sds, strict=True))

    def effects(self, approach):
        """``(n, m)``: each component's effect on the radius per unit at the unit
        approach directions `approach` ``(n, 2)`` (traceable)."""
        theta = jnp.arctan2(approach[:, 1], approach[:, 0])
        cols = [jnp.ones_like(theta)]
        for k in self.orders:
            cols += [jnp.cos(k * theta), jnp.sin(k * theta)]
        return jnp.stack(cols, axis=1) @ jnp.asarray(self.vectors)


def is_calibration_source(name: str) -> bool:
    """Whether `name` is one of a probe calibration's components."""
    return name.startswith(_CAL_PREFIX) and name[len(_CAL_PREFIX) :].isdigit()


def source_unit(name: str) -> str:
    """The unit of a source's value (`SOURCE_UNITS`; a calibration component: mm)."""
    return "mm" if is_calibration_source(name) else SOURCE_UNITS[name]


_TRANSFORM_INDEX = {"x_centre": 0, "z_offset": 1, "scale_x": 2, "scale_z": 3, "rotation": 4}


def probe_residuals(
    groups, devs, points, deltas, *, transform, ball_radius, approach=None, radius=None
):
    """Residuals of every trigger, feature by feature.

    **Arguments:**

    - `groups`: ``(feature, indices)`` pairs: the triggers of each feature.
    - `devs`: the deviation of each feature in `groups` (same order).
    - `points`: ``(n, 2)`` ball centres, machine frame, radius X.
    - `deltas`: ``{source: value}`` for sources in ``SOURCE_EFFECTS`` (traced values).
    - `transform`: the study's transform as its 5-vector.
    - `approach`: ``(n, 2)`` unit approach directions, or None (the pretravel
      and the calibration then act against the outward normal).
    - `radius`: the probe calibration's `RadiusComponents` when `deltas` holds
      its components (``probe_cal_<j>``).

    **Returns:** the residuals, concatenated in `groups` order.
    """
    t = transform
    for name, v in deltas.items():
        if name in _TRANSFORM_INDEX:
            t = t.at[_TRANSFORM_INDEX[name]].add(v)
        elif name == "thermal":
            t = t.at[2].add(v).at[3].add(v)
    rb = ball_radius + deltas.get("ball_radius", 0.0)
    cal = (
        []
        if radius is None
        else [(j, deltas[n]) for j, n in enumerate(radius.names) if n in deltas]
    )
    part = machine_to_part(points, t)
    out = []
    for (f, idx), d in zip(groups, devs, strict=True):
        q = part[idx]
        if "pretravel" in deltas or cal:
            a = approach[idx] if approach is not None else -f.outward_normal(q, d)
        if "pretravel" in deltas:
            q = q - deltas["pretravel"] * a
        r = rb
        if cal:
            e = radius.effects(a)
            r = rb + sum(e[:, j] * v for j, v in cal)
        out.append(f.signed_distance(q, d) - r)
    return jnp.concatenate(out)
