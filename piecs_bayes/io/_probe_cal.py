r"""A probe calibration: the effective ball radius by approach direction, and its file.

A touch-trigger probe triggers after a pretravel that depends on the direction of
approach, so the distance from a recorded ball centre to the surface (the **effective
radius**) is $r(\theta) = r_0 + \sum_k a_k \cos k\theta + b_k \sin k\theta$, orders in
`ALLOWED_ORDERS` (2, 3), $\theta$ = [`approach_angle`][] of the ball's unit travel
into the surface (part frame, radius X); one radius per axis (`PER_AXIS`) is order 2
with b2 held at zero. [`ProbeCalibration`][] is what `piecs-bayes calibrate-probe`
writes (``probe_cal.json``, `CALIBRATION_FORMAT`) and `[probe] calibration` reads
([`read_probe_calibration`][]): the coefficients, their covariance and dof;
`ProbeCalibration.radius` gives $r(\theta)$, `ProbeCalibration.components` the
covariance as independent components ([`lobe_basis`][]: the Fourier basis).

The model and its use by every fit: docs/uncertainty.md, section 5.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import InputError

#: The ``format`` key of a probe_cal.json this version reads and writes.
CALIBRATION_FORMAT = "piecs-bayes probe calibration 1"
#: The orders of r(theta) a calibration may hold (order 1 is the probe's offset).
ALLOWED_ORDERS = (2, 3)
#: The model of one radius per axis, r0 + a2 cos 2 theta (r0 + a2 along X, r0 - a2
#: along Z; b2 held at zero): what a ring or diameter with a face pair determines.
PER_AXIS = "a2"


def approach_angle(approach) -> np.ndarray:
    """The approach angle (rad, in (-pi, pi]) of unit directions `approach` ``(n, 2)``
    (x, z): ``atan2(a_z, a_x)``."""
    a = np.asarray(approach, dtype=float).reshape(-1, 2)
    return np.arctan2(a[:, 1], a[:, 0])


def coefficient_names(orders) -> tuple[str, ...]:
    """``("r0", "a2", "b2", "a3", "b3")`` for orders ``(2, 3)``."""
    return ("r0",) + tuple(f"{c}{k}" for k in orders for c in ("a", "b"))


def lobe_basis(theta, orders) -> np.ndarray:
    """``(n, 1 + 2 len(orders))``: 1, cos k theta, sin k theta for each order."""
    t = np.asarray(theta, dtype=float).reshape(-1)
    cols = [np.ones_like(t)]
    for k in orders:
        cols += [np.cos(k * t), np.sin(k * t)]
    return np.stack(cols, axis=1)


@dataclass(frozen=True)
class ProbeCalibration:
    """A probe's effective radius by approach direction with its uncertainty.

    - `orders`: the Fourier orders in r(theta) (``()``: one radius, K = 0).
    - `coefficients` ``(p,)`` in `coefficient_names(orders)` order (mm), `cov`
      ``(p, p)`` (mm^2), `dof` (Welch-Satterthwaite dof of the coefficients; inf when
      the certificate dominates), `residual_sd` (mm).
    - `probing_error`: the range of r(theta) over the calibration's directions (mm,
      ISO 10360-5 style: the range of radii on the artefact).
    - `artefact`: kind, certified size, expanded uncertainty and k, as the file gave.
    - `feed` (mm/min, None when unknown), `date` (ISO date), `probe` (the probe's
      name or tool number, as the calibration file gave), `units` ("mm").
    - `inputs`: ``[{"file", "sha256"}]``; `source`: the probe_cal.json read (or None).
    - `fixed`: coefficients the model holds at zero (not fitted, no uncertainty):
      ``("b2",)`` for one radius per axis, r0 + a2 cos 2 theta (`orders` (2,)).
    - `directions`: the calibration's distinct approach angles (degrees, sorted).
    - `orders_choice`: how ``orders = "auto"`` chose (`fit.fit_probe_calibration`):
      the target directions and each candidate's u of r there (a JSON object).
    """

    orders: tuple[int, ...]
    coefficients: np.ndarray
    cov: np.ndarray
    dof: float = math.inf
    residual_sd: float = math.nan
    probing_error: float = math.nan
    artefact: dict = field(default_factory=dict)
    feed: float | None = None
    date: str | None = None
    probe: str | None = None
    units: str = "mm"
    inputs: tuple = ()
    n_points: int = 0
    source: str | None = None
    fixed: tuple[str, ...] = ()
    directions: tuple[float, ...] = ()
    orders_choice: dict | None = field(default=None, repr=False)

    def __post_init__(self):
        names = coefficient_names(self.orders)
        c = np.asarray(self.coefficients, dtype=float).reshape(-1)
        cov = np.asarray(self.cov, dtype=float)
        if c.size != len(names) or cov.shape != (c.size, c.size):
            raise ValueError(
                f"coefficients {c.size} and cov {cov.shape} do not fit orders {self.orders}"
            )
        bad = [n for n in self.fixed if n not in names[1:]]
        if bad:
            raise ValueError(f"fixed coefficients {bad} are not among {names[1:]}")
        object.__setattr__(self, "coefficients", c)
        object.__setattr__(self, "cov", 0.5 * (cov + cov.T))
        object.__setattr__(self, "fixed", tuple(self.fixed))
        object.__setattr__(self, "directions", tuple(float(d) for d in self.directions))

    @property
    def names(self) -> tuple[str, ...]:
        return coefficient_names(self.orders)

    @property
    def r0(self) -> float:
        return float(self.coefficients[0])

    def radius(self, theta) -> np.ndarray:
        """r(theta) (mm) at approach angles `theta` (rad)."""
        return lobe_basis(theta, self.orders) @ self.coefficients

    def radius_u(self, theta) -> np.ndarray:
        """The standard uncertainty of r(theta) (mm) from the coefficients' covariance."""
        b = lobe_basis(theta, self.orders)
        return np.sqrt(np.maximum(np.einsum("ni,ij,nj->n", b, self.cov, b), 0.0))

    def components(self) -> tuple[np.ndarray, np.ndarray]:
        """The covariance as independent components: their standard deviations
        ``(m,)`` and the coefficients each moves per unit ``(p, m)`` (eigenvectors),
        so that the radius at theta moves by ``lobe_basis(theta) @ vectors`` per unit
        and ``cov = vectors diag(sd^2) vectors^T`` exactly. Components with no
        variance are left out."""
        lam, vec = np.linalg.eigh(self.cov)
        keep = lam > 1e-12 * max(float(lam.max()), 1e-300)
        return np.sqrt(lam[keep]), vec[:, keep]

    def age_days(self, today: _dt.date | None = None) -> float | None:
        """Days since the calibration's date (None when it has none)."""
        if not self.date:
            return None
        today = today or _dt.date.today()
        return float((today - _dt.date.fromisoformat(self.date[:10])).days)

    def to_json(self) -> dict:
        """The probe_cal.json object (`read_probe_calibration` reads it back)."""
        sd = np.sqrt(np.maximum(np.diag(self.cov), 0.0))
        names = self.names

        def num(v):
            return None if math.isnan(v) or math.isinf(v) else float(v)

        out = {
            "format": CALIBRATION_FORMAT,
            "units": self.units,
            "probe": self.probe,
            "date": self.date,
            "feed_mm_per_min": self.feed,
            "model": "r(theta) = r0 + sum_k a_k cos(k theta) + b_k sin(k theta); "
            "theta = atan2(a_z, a_x) of the approach direction"
            + ("; held at zero: " + ", ".join(self.fixed) if self.fixed else ""),
            "orders": list(self.orders),
            "coefficients": {n: float(v) for n, v in zip(names, self.coefficients, strict=True)},
            "standard_uncertainty": {n: float(v) for n, v in zip(names, sd, strict=True)},
            "covariance": self.cov.tolist(),
            "dof": num(self.dof),
            "residual_sd_mm": num(self.residual_sd),
            "probing_error_mm": num(self.probing_error),
            "n_points": int(self.n_points),
            "artefact": dict(self.artefact),
            "inputs": [dict(i) for i in self.inputs],
        }  # fmt: skip
        if self.fixed:
            out["fixed_at_zero"] = list(self.fixed)
        if self.directions:
            out["directions_deg"] = list(self.directions)
        if self.orders_choice is not None:
            out["orders_choice"] = self.orders_choice
        return out

    def to_json_text(self) -> str:
        return json.dumps(self.to_json(), indent=2) + "\n"


def _number(obj, key, where, *, positive=False, allow_none=False):
    v = obj.get(key)
    if v is None and allow_none:
        return None
    if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
        raise InputError(f"{where}: expected a finite number for {key!r}, got {v!r}", value=v)
    if positive and v <= 0:
        raise InputError(f"{where}: {key!r} must be positive, got {v!r}", value=v)
    return float(v)


def _extras(obj: dict, names, c, cov, where: str) -> dict:
    """The optional keys: `fixed_at_zero` (each a coefficient at 0 with no variance),
    `directions_deg` and `orders_choice`."""
    fixed = obj.get("fixed_at_zero") or []
    if not isinstance(fixed, list) or any(n not in names[1:] for n in fixed):
        raise InputError(f"fixed_at_zero must name coefficients out of {list(names[1:])}, "
                         f"got {fixed!r}", file=where, value=fixed)  # fmt: skip
    for n in fixed:
        i = names.index(n)
        if c[i] != 0.0 or np.any(cov[i] != 0.0):
            raise InputError(f"{n} is held at zero (fixed_at_zero) but its value is {c[i]!r} "
                             "or it has a covariance", file=where, value=n)  # fmt: skip
    dirs = obj.get("directions_deg") or []
    if not isinstance(dirs, list) or not all(
        isinstance(d, int | float) and not isinstance(d, bool) and math.isfinite(d) for d in dirs
    ):
        raise InputError(f"directions_deg must be a list of angles (degrees), got {dirs!r}",
                         file=where, value=dirs)  # fmt: skip
    choice = obj.get("orders_choice")
    if choice is not None and not isinstance(choice, dict):
        raise InputError(f"orders_choice must be an object, got {choice!r}", file=where)
    return {"fixed": tuple(fixed), "directions": tuple(dirs), "orders_choice": choice}


def read_probe_calibration(path, *, units: str = "mm") -> ProbeCalibration:
    """Read a probe_cal.json; refused when it is not one, holds another unit than
    `units`, or its numbers do not fit together (named)."""
    path = Path(path)
    where = str(path)
    try:
        obj = json.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise InputError("probe calibration file not found", file=where) from None
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise InputError(f"not a probe calibration (JSON): {exc}", file=where) from None
    if not isinstance(obj, dict) or obj.get("format") != CALIBRATION_FORMAT:
        got = obj.get("format") if isinstance(obj, dict) else type(obj).__name__
        raise InputError(
            f"not a probe calibration: format {got!r}, expected {CALIBRATION_FORMAT!r}",
            file=where, value=got,
        )  # fmt: skip
    if obj.get("units") != units:
        raise InputError(
            f"the calibration is in {obj.get('units')!r}, the study in {units!r}: "
            "calibrate in the study's units",
            file=where, value=obj.get("units"),
        )  # fmt: skip
    orders = obj.get("orders")
    if (
        not isinstance(orders, list)
        or any(k not in ALLOWED_ORDERS for k in orders)
        or len(set(orders)) != len(orders)
    ):
        raise InputError(
            f"orders must be distinct values of {list(ALLOWED_ORDERS)}, got {orders!r}",
            file=where, value=orders,
        )  # fmt: skip
    orders = tuple(sorted(orders))
    names = coefficient_names(orders)
    coefs = obj.get("coefficients")
    if not isinstance(coefs, dict) or set(coefs) != set(names):
        raise InputError(
            f"coefficients must be exactly {list(names)}, got "
            f"{sorted(coefs) if isinstance(coefs, dict) else coefs!r}",
            file=where,
        )  # fmt: skip
    c = np.array([_number(coefs, n, where) for n in names])
    if c[0] <= 0:
        raise InputError(f"r0 must be positive, got {c[0]!r}", file=where, value=c[0])
    cov = np.asarray(obj.get("covariance"), dtype=float) if obj.get("covariance") else None
    if cov is None or cov.shape != (len(names), len(names)) or not np.all(np.isfinite(cov)):
        raise InputError(
            f"covariance must be a finite {len(names)} x {len(names)} matrix", file=where
        )
    if not np.allclose(cov, cov.T, rtol=1e-9, atol=1e-30) or np.linalg.eigvalsh(
        0.5 * (cov + cov.T)
    ).min() < -1e-12 * max(float(np.abs(cov).max()), 1e-300):
        raise InputError("covariance is not symmetric positive semi-definite", file=where)
    dof = obj.get("dof")
    dof = math.inf if dof is None else _number(obj, "dof", where, positive=True)
    feed = _number(obj, "feed_mm_per_min", where, positive=True, allow_none=True)
    date = obj.get("date")
    if date is not None:
        try:
            _dt.date.fromisoformat(str(date)[:10])
        except ValueError:
            raise InputError(f"date {date!r} is not an ISO date", file=where, value=date) from None
    res = obj.get("residual_sd_mm")
    pe = obj.get("probing_error_mm")
    return ProbeCalibration(
        orders=orders, coefficients=c, cov=cov, dof=dof,
        residual_sd=math.nan if res is None else _number(obj, "residual_sd_mm", where),
        probing_error=math.nan if pe is None else _number(obj, "probing_error_mm", where),
        artefact=dict(obj.get("artefact") or {}), feed=feed,
        date=None if date is None else str(date), probe=obj.get("probe"), units=units,
        inputs=tuple(obj.get("inputs") or ()), n_points=int(obj.get("n_points") or 0),
        source=where, **_extras(obj, names, c, cov, where),
    )  # fmt: skip
