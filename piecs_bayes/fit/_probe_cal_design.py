r"""A probe calibration's data as a model sees them, and which models they can fit.

[`CalibrationDesign`][] arranges the recorded ball centres on a certified artefact
(sphere, ring, diameter, optionally a face pair) for the model of
$r(\theta) = r_0 + \sum_k a_k \cos k\theta + b_k \sin k\theta$ with a free centre: per
point its approach angle, group sign, axis and certified size, and the linearised rows
of any model. A model is named by its *spec*: a tuple of orders in (2, 3) (``()``: one
radius) or `PER_AXIS` (``"a2"``: r0 + a2 cos 2 theta, one radius per axis);
[`model_terms`][] lists its coefficients. [`check_orders`][] refuses a model the
directions cannot separate (rank, `COND_LIMIT`) or that leaves no dof.
"""

from __future__ import annotations

import math

import numpy as np

from .. import _config
from ..errors import InputError
from ..io import PER_AXIS, CalibrationArtefact, approach_angle, coefficient_names

#: the condition number (unit-scaled design over the distinct directions) beyond
#: which orders are refused: a coefficient's uncertainty would be amplified more than
#: this many times over what the same points evenly spread give
COND_LIMIT = 100.0
#: an approach of a ring, diameter or face within this angle of its axis (rad)
_AXIS_TOL = math.radians(2.0)


def model_terms(spec) -> tuple[str, ...]:
    """The coefficients of model `spec` after r0: ``("a2", "b2", "a3", "b3")`` for
    orders (2, 3), ``("a2",)`` for `PER_AXIS`; `InputError` for another spec."""
    if spec == PER_AXIS:
        return (PER_AXIS,)
    if (
        isinstance(spec, str)
        or any(isinstance(k, bool) or k not in (2, 3) for k in spec)
        or len(set(spec)) != len(spec)
    ):
        raise InputError(f"orders {spec!r}; expected \"auto\", \"{PER_AXIS}\" or distinct "
                         "orders out of (2, 3)", value=spec)  # fmt: skip
    return coefficient_names(tuple(spec))[1:]


def model_label(spec) -> str:
    """How messages name model `spec`."""
    if spec == PER_AXIS:
        return "r0 + a2 cos 2 theta (one radius per axis)"
    return f"orders {','.join(map(str, spec))}" if spec else "one radius"


def term_basis(theta, terms) -> np.ndarray:
    """``(n, 1 + len(terms))``: 1 and cos k theta (``a<k>``) or sin k theta (``b<k>``)."""
    t = np.asarray(theta, dtype=float).reshape(-1)
    cols = [np.ones_like(t)]
    for name in terms:
        k = int(name[1:])
        cols.append(np.cos(k * t) if name[0] == "a" else np.sin(k * t))
    return np.stack(cols, axis=1)


class CalibrationDesign:
    """The data arranged for the model: per point its centre, approach, angle, the
    group's sign (+1 outside, -1 inside), whether it is a sphere's point, the axis of a
    line point, the index of its certified size; the sizes with their u; the free
    centre coordinates. `InputError` for data that do not fit the artefact."""

    def __init__(self, artefact: CalibrationArtefact, centres, approach, face=None):
        p, a = _checked_points(centres, approach)
        n = len(p)
        self.centres, self.approach, self.theta = p, a, approach_angle(a)
        self.centre0 = np.asarray(artefact.centre, dtype=float)
        self.sphere = np.full(n, artefact.kind == "sphere")
        self.sign = np.full(n, -1.0 if artefact.kind == "ring" else 1.0)
        self.axis = np.zeros((n, 2))
        self.size_index = np.zeros(n, dtype=int)
        sizes, size_u = [artefact.diameter / 2.0], [artefact.radius_u]
        self.size_names = ["radius"]
        self.free = (0, 1)
        if artefact.kind != "sphere":
            on_face = (np.abs(a[:, 1]) > np.abs(a[:, 0])) if face is None else np.asarray(face)
            on_face = on_face.astype(bool).reshape(n)
            if artefact.face_width is None and on_face.any():
                i = int(np.flatnonzero(on_face)[0])
                raise InputError(f"point {i + 1}: approach {a[i].tolist()} is along Z, but the "
                                 f"{artefact.kind} has no face pair ([artefact.face])")  # fmt: skip
            self._line_axes(on_face, artefact.kind)
            self.free = (0,)
            if artefact.face_width is not None:
                self.sign[on_face] = 1.0
                self.size_index[on_face] = 1
                sizes.append(artefact.face_width / 2.0)
                size_u.append(artefact.face_half_width_u)
                self.size_names.append("half_width")
                self.free = (0, 1)
        self.sizes, self.size_u = np.asarray(sizes), np.asarray(size_u)

    def _line_axes(self, on_face, kind) -> None:
        a = self.approach
        for i in range(len(a)):
            j = 1 if on_face[i] else 0
            if abs(a[i, 1 - j]) > math.sin(_AXIS_TOL):
                what = "a face pair along Z" if j else f"a {kind} along X"
                raise InputError(
                    f"point {i + 1}: approach {a[i].round(4).tolist()} is not along an "
                    f"axis: {what} is probed within 2 degrees of it"
                )
            self.axis[i, j] = math.copysign(1.0, a[i, j])

    def __len__(self) -> int:
        return len(self.centres)

    @property
    def embed(self) -> np.ndarray:
        """``(2, nc)``: the free centre coordinates into (x, z)."""
        return np.eye(2)[:, list(self.free)]

    def args(self, terms) -> dict:
        """The arrays of the residual function for the model of `terms`."""
        return _config.on_device({
            "p": self.centres, "basis": term_basis(self.theta, terms), "c0": self.centre0,
            "E": self.embed, "sphere": self.sphere, "s": self.sign, "u": self.axis,
            "idx": self.size_index,
        })  # fmt: skip

    def distinct(self) -> np.ndarray:
        """Indices of one point per distinct (direction, size) pair."""
        key = np.c_[np.round(np.degrees(self.theta), 3) % 360.0, self.size_index]
        return np.unique(key, axis=0, return_index=True)[1]

    def rows(self, terms, i=None) -> np.ndarray:
        """The linearised design (d residual / d (free centre, r0, terms)) at the
        nominal centre of points `i` (default: all)."""
        i = np.arange(len(self)) if i is None else i
        dc = np.where(self.sphere[i, None], self.approach[i], self.sign[i, None] * self.axis[i])
        return np.c_[dc[:, list(self.free)], -self.sign[i, None] * term_basis(self.theta[i], terms)]

    def size_onehot(self) -> np.ndarray:
        """``(n, sizes)``: which certified size each point is measured against."""
        return (self.size_index[:, None] == np.arange(self.sizes.size)[None]).astype(float)

    def nominal_data(self) -> np.ndarray:
        """``(n,)``: minus the residuals at the nominal centre with r = 0, the data of
        the linearised model (exact for a ring, a diameter or faces)."""
        d = self.centres - self.centre0
        dist = np.where(self.sphere, np.hypot(d[:, 0], d[:, 1]),
                        -self.sign * np.sum(self.axis * d, axis=1))  # fmt: skip
        return -(dist - self.sizes[self.size_index])

    def linear_start(self, terms) -> np.ndarray:
        """The least-squares solution of the model linearised at the nominal centre."""
        return np.linalg.lstsq(self.rows(terms), self.nominal_data(), rcond=None)[0]

    def angles_text(self) -> str:
        deg = np.unique(np.round(np.degrees(self.theta) % 360.0, 1))
        shown = ", ".join(f"{d:g}" for d in deg[:12]) + (", ..." if deg.size > 12 else "")
        return f"{shown} degrees{' only' if deg.size <= 12 else ''} ({deg.size} distinct)"


def _checked_points(centres, approach):
    p = np.asarray(centres, dtype=float).reshape(-1, 2)
    a = np.asarray(approach, dtype=float).reshape(-1, 2)
    if p.shape != a.shape or not (np.all(np.isfinite(p)) and np.all(np.isfinite(a))):
        raise InputError(f"centres {p.shape} and approach {a.shape}: expected two finite "
                         "(n, 2) arrays of the same shape")  # fmt: skip
    norm = np.hypot(a[:, 0], a[:, 1])
    if np.any(norm < 1e-9):
        i = int(np.argmin(norm))
        raise InputError(f"point {i + 1}: the approach direction is zero", value=a[i].tolist())
    return p, a / norm[:, None]


def check_orders(design: CalibrationDesign, spec, *, sigma_known: bool = False) -> float:
    """The condition number of the nominal design of model `spec` over the distinct
    directions; `InputError` when the directions cannot separate it (rank,
    `COND_LIMIT`) or it leaves no dof."""
    terms = model_terms(spec)
    x = design.rows(terms, design.distinct())
    p = x.shape[1]
    x = x / np.maximum(np.linalg.norm(x, axis=0), 1e-300)
    sv = np.linalg.svd(x, compute_uv=False)
    rank = int(np.sum(sv > 1e-9 * sv[0]))
    cond = math.inf if rank < p else float(sv[0] / sv[-1])
    label = model_label(spec) if spec == PER_AXIS or not spec else f"order {max(spec)}"
    if rank < p or cond > COND_LIMIT:
        why = f"rank {rank} of {p}" if rank < p else f"condition number {cond:.3g} > {COND_LIMIT:g}"
        raise InputError(f"{label} needs {_hint(design, spec, p)}; the data have "
                         f"{design.angles_text()} ({why})")  # fmt: skip
    dof = len(design) - p
    if dof < (0 if sigma_known else 1):
        raise InputError(f"{label}: {len(design)} points for {p} unknowns leave no degree of "
                         "freedom to estimate the probe's sigma: probe more points "
                         "(or repeat directions)")  # fmt: skip
    return cond


def _hint(design: CalibrationDesign, spec, p: int) -> str:
    """What would separate model `spec` (`check_orders`' message)."""
    if spec == PER_AXIS and not design.sphere.all():
        return ("approaches along X and along Z: a ring or diameter with a face pair "
                "([artefact.face])")  # fmt: skip
    if design.sphere.all():
        k = 2 if spec == PER_AXIS else max(spec, default=1)
        many = max(p + 1, 2 * k + 2)
        step = 360.0 / many
        return (f"approach directions spread over at least {p} distinct angles around the "
                f"circle, e.g. every {step:g} degrees "
                f"({', '.join(f'{k * step:g}' for k in range(many))})")  # fmt: skip
    return ("a sphere probed around the circle (a ring, diameter or face is probed along the "
            "axes only: 0, 90, 180, 270 degrees at most; one radius per axis, r0 + a2 cos 2 "
            "theta, from a ring or diameter with a face pair: orders = \"a2\")")  # fmt: skip
