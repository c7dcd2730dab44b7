r"""The calibration file of `piecs-bayes calibrate-probe` (TOML): the probe, the artefact
with its certificate, and the probe files of the calibration run.

[`read_calibration_file`][] reads `[calibration]` (probe, units: mm only, feed, date,
orders, declared repeatability and its dof, `sigma = "estimated"` or `"known"`),
`[artefact]` (`kind` one of `ARTEFACT_KINDS`, certified diameter with its expanded
uncertainty and coverage factor, nominal centre; `[artefact.face]` for a face pair) and
`[[probe_files]]` (file relative to the calibration file, format, X mode, plan) into a
[`CalibrationFile`][] with its [`CalibrationArtefact`][] and its probe files
([`CalibrationProbeFile`][]); [`parse_orders`][] reads `orders`. Every key is checked:
an unknown key, a wrong type, a unit other than mm, a size without its certificate's
uncertainty are refused (`InputError`), naming the file and the key.

The file, key by key: docs/formats.md, "Probe calibration".
"""

from __future__ import annotations

import datetime as _dt
import math
import tomllib
from dataclasses import dataclass, field
from pathlib import Path

from ..errors import InputError
from ._control_probe import PROBE_FORMATS
from ._probe_cal import PER_AXIS
from ._reader import Reader
from ._text import decode, read_bytes

#: sphere: probed from outside around its equator in the XZ plane; ring: a bore probed
#: from inside along +X and -X; diameter: a turned (measured) diameter probed from
#: outside along -X and +X
ARTEFACT_KINDS = ("sphere", "ring", "diameter")

_KEYS = {
    "": ("calibration", "artefact", "probe_files"),
    "calibration": ("probe", "units", "feed", "date", "orders", "repeatability",
                    "repeatability_dof", "sigma"),
    "artefact": ("kind", "diameter", "expanded_uncertainty", "coverage_factor", "centre", "face"),
    "artefact.face": ("width", "expanded_uncertainty", "coverage_factor"),
    "probe_files": ("file", "format", "x_mode", "plan"),
}  # fmt: skip


@dataclass(frozen=True)
class CalibrationArtefact:
    """The calibration artefact and its certificate (mm).

    - `kind`: one of `ARTEFACT_KINDS`; `diameter`, `expanded_uncertainty` U and
      `coverage_factor` k from the certificate (or the micrometer's), u(R) = U / (2k).
    - `centre`: nominal centre ``(x radius, z)``: the directions of a CSV without
      approach columns are taken from it.
    - `face_width`, `face_expanded_uncertainty`, `face_coverage_factor`: optional pair
      of parallel faces (ring or diameter only), width certified, probed from outside
      along -Z (the +Z face) and +Z (the -Z face).
    """

    kind: str
    diameter: float
    expanded_uncertainty: float
    coverage_factor: float
    centre: tuple[float, float] = (0.0, 0.0)
    face_width: float | None = None
    face_expanded_uncertainty: float | None = None
    face_coverage_factor: float | None = None

    def __post_init__(self):
        if self.kind not in ARTEFACT_KINDS:
            raise InputError(f"artefact kind {self.kind!r}; expected one of {ARTEFACT_KINDS}")
        sizes = [("diameter", self.diameter, self.expanded_uncertainty, self.coverage_factor)]
        if self.face_width is not None:
            if self.kind == "sphere":
                raise InputError("a face pair goes with a ring or a diameter, not a sphere")
            sizes.append(("face width", self.face_width, self.face_expanded_uncertainty,
                          self.face_coverage_factor))  # fmt: skip
        for what, size, u, k in sizes:
            if not (size is not None and math.isfinite(size) and size > 0):
                raise InputError(f"artefact {what} must be positive, got {size!r}", value=size)
            if u is None or not math.isfinite(u) or u <= 0:
                raise InputError(
                    f"an artefact with no certificate uncertainty: the {what}'s expanded "
                    f"uncertainty is {u!r}; give the certificate's U (> 0, mm)", value=u
                )  # fmt: skip
            if k is None or not math.isfinite(k) or k <= 0:
                raise InputError(f"artefact {what}: coverage factor must be > 0, got {k!r}")

    @property
    def radius_u(self) -> float:
        """u(R) = U / (2k) (mm)."""
        return self.expanded_uncertainty / (2.0 * self.coverage_factor)

    @property
    def face_half_width_u(self) -> float | None:
        if self.face_width is None:
            return None
        return self.face_expanded_uncertainty / (2.0 * self.face_coverage_factor)

    def to_json(self) -> dict:
        out = {"kind": self.kind, "diameter_mm": self.diameter,
               "expanded_uncertainty_mm": self.expanded_uncertainty,
               "coverage_factor": self.coverage_factor, "centre": list(self.centre)}  # fmt: skip
        if self.face_width is not None:
            out["face"] = {"width_mm": self.face_width,
                           "expanded_uncertainty_mm": self.face_expanded_uncertainty,
                           "coverage_factor": self.face_coverage_factor}  # fmt: skip
        return out


@dataclass(frozen=True)
class CalibrationProbeFile:
    """One probe file of the run: its path (resolved against the TOML), format,
    X mode (CSV) and plan (control formats)."""

    file: Path
    format: str
    x_mode: str = "diameter"
    plan: Path | None = None


@dataclass(frozen=True)
class CalibrationFile:
    """A checked calibration file (module docstring). `orders` is ``"auto"``, ``"a2"``
    (one radius per axis) or a sorted tuple of orders in (2, 3); `repeatability` the
    declared sigma (mm)."""

    path: Path
    probe: str
    artefact: CalibrationArtefact
    probe_files: tuple[CalibrationProbeFile, ...]
    repeatability: float
    repeatability_dof: float = 8.0
    sigma: str = "estimated"
    orders: str | tuple[int, ...] = "auto"
    units: str = "mm"
    feed: float | None = None
    date: str | None = None
    inputs: tuple[Path, ...] = field(default=())


def _check_keys(r: Reader, table: dict, name: str, shown: str | None = None) -> None:
    allowed = _KEYS[name]
    shown = name if shown is None else shown
    for key, val in table.items():
        if key not in allowed:
            path = f"{shown}.{key}" if shown else key
            raise r.error(path, f"unknown key {key!r}; expected one of {', '.join(allowed)}",
                          value=val)  # fmt: skip


def parse_orders(value, where: str = "orders") -> str | tuple[int, ...]:
    """``"auto"``, ``"a2"`` (one radius per axis: r0 + a2 cos 2 theta) or a sorted
    tuple of distinct orders in (2, 3) (``[]``: K = 0)."""
    if value in ("auto", PER_AXIS):
        return value
    if (
        not isinstance(value, list | tuple)
        or any(isinstance(k, bool) or k not in (2, 3) for k in value)
        or len(set(value)) != len(value)
    ):
        raise InputError(
            f"{where}: expected \"auto\", \"a2\" (one radius per axis) or a list of distinct "
            f"orders out of [2, 3] ([] for one radius), got {value!r} (order 1 is the probe's "
            "offset: never fitted)",
            value=value,
        )  # fmt: skip
    return tuple(sorted(int(k) for k in value))


def _string(r: Reader, tree: dict, key: str, path: str, *, required=True) -> str | None:
    if key not in tree:
        if required:
            raise r.error(f"{path}{key}", "missing required text")
        return None
    val = tree[key]
    if isinstance(val, bool) or not isinstance(val, str | int) or str(val).strip() == "":
        raise r.error(f"{path}{key}", f"expected a name, got {val!r}", value=val)
    return str(val)


def _artefact(r: Reader, tree: dict) -> CalibrationArtefact:
    art = r.table(tree, "artefact", "", required=True)
    _check_keys(r, art, "artefact")
    kind = r.choice(art, "kind", "artefact.", ARTEFACT_KINDS, None)
    for key in ("expanded_uncertainty", "coverage_factor"):
        if key not in art:
            raise r.error(
                f"artefact.{key}",
                "missing: an artefact with no certificate uncertainty cannot calibrate (its "
                "size is the length the radii are measured against); give the certificate's "
                "U and k",
            )
    diameter = r.number(art, "diameter", "artefact.", positive=True)
    u = r.number(art, "expanded_uncertainty", "artefact.", nonneg=True)
    if u == 0:
        raise r.error("artefact.expanded_uncertainty",
                      "an artefact with no certificate uncertainty (U = 0): give the "
                      "certificate's U", value=u)  # fmt: skip
    k = r.number(art, "coverage_factor", "artefact.", positive=True)
    centre = r.point(art, "centre", "artefact.", None) if "centre" in art else [0.0, 0.0]
    face = r.table(art, "face", "artefact.")
    fw = fu = fk = None
    if face:
        _check_keys(r, face, "artefact.face")
        if kind == "sphere":
            raise r.error("artefact.face", "a face pair goes with a ring or a diameter")
        fw = r.number(face, "width", "artefact.face.", positive=True)
        if "expanded_uncertainty" not in face or "coverage_factor" not in face:
            raise r.error("artefact.face", "an artefact with no certificate uncertainty: the "
                          "faces need expanded_uncertainty and coverage_factor")  # fmt: skip
        fu = r.number(face, "expanded_uncertainty", "artefact.face.", positive=True)
        fk = r.number(face, "coverage_factor", "artefact.face.", positive=True)
    return CalibrationArtefact(kind, diameter, u, k, (centre[0], centre[1]), fw, fu, fk)


def _probe_files(r: Reader, tree: dict, base: Path) -> tuple[CalibrationProbeFile, ...]:
    rows = tree.get("probe_files")
    if not isinstance(rows, list) or not rows or not all(isinstance(x, dict) for x in rows):
        raise r.error("probe_files", "expected one or more [[probe_files]] tables", value=rows)
    out = []
    for i, row in enumerate(rows):
        path = f"probe_files[{i}]."
        _check_keys(r, row, "probe_files", f"probe_files[{i}]")
        file = _string(r, row, "file", path)
        fmt = r.choice(row, "format", path, PROBE_FORMATS, "csv")
        x_mode = r.choice(row, "x_mode", path, ("diameter", "radius"), "diameter")
        plan = _string(r, row, "plan", path, required=fmt != "csv")
        if fmt == "csv" and plan is not None:
            raise r.error(f"{path}plan", "a CSV carries its own points: no plan", value=plan)
        if fmt != "csv" and "x_mode" in row and fmt != "fanuc-dprnt":
            raise r.error(f"{path}x_mode", f"{fmt} writes X as a radius: no x_mode")
        out.append(CalibrationProbeFile(base / file, fmt, x_mode,
                                        None if plan is None else base / plan))  # fmt: skip
    return tuple(out)


def read_calibration_file(path) -> CalibrationFile:
    """Read and check a calibration file (module docstring); paths in it are relative
    to the file. Raises `InputError` naming the file and the key."""
    path = Path(path)
    name = str(path)
    text = decode(read_bytes(path, what="calibration file"), file=name)
    try:
        tree = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not a TOML file: {exc}", file=name) from None
    r = Reader(name)
    _check_keys(r, tree, "")
    cal = r.table(tree, "calibration", "", required=True)
    _check_keys(r, cal, "calibration")
    units = cal.get("units", "mm")
    if units != "mm":
        raise r.error("calibration.units", f"a calibration is made in 'mm', got {units!r}: "
                      "convert the artefact and the probe files to mm", value=units)  # fmt: skip
    probe = _string(r, cal, "probe", "calibration.")
    date = _string(r, cal, "date", "calibration.", required=False)
    if isinstance(cal.get("date"), _dt.date):
        date = cal["date"].isoformat()
    elif date is not None:
        try:
            _dt.date.fromisoformat(date[:10])
        except ValueError:
            raise r.error("calibration.date", f"expected an ISO date, got {date!r}") from None
    feed = r.number(cal, "feed", "calibration.", positive=True) if "feed" in cal else None
    try:
        orders = parse_orders(cal.get("orders", "auto"), "calibration.orders")
    except InputError as exc:
        raise InputError(exc.reason, file=name, value=cal.get("orders")) from None
    rep = r.number(cal, "repeatability", "calibration.", positive=True)
    rep_dof = r.number(cal, "repeatability_dof", "calibration.", 8.0, positive=True)
    sigma = r.choice(cal, "sigma", "calibration.", ("estimated", "known"), "estimated")
    try:
        artefact = _artefact(r, tree)
    except InputError as exc:
        if exc.file is None:
            raise InputError(exc.reason, file=name, value=exc.value) from None
        raise
    files = _probe_files(r, tree, path.parent)
    inputs = tuple(dict.fromkeys(p for f in files for p in (f.file, f.plan) if p is not None))
    return CalibrationFile(
        path=path, probe=probe, artefact=artefact, probe_files=files, repeatability=rep,
        repeatability_dof=rep_dof, sigma=sigma, orders=orders, units=units, feed=feed,
        date=date, inputs=inputs,
    )  # fmt: skip
