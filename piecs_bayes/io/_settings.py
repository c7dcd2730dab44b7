"""The validated contents of a study file: the probe, fit, compensation and
part-program settings and the [`Study`][] that holds them, in mm and radius X.

`_study.load_study` builds these from a TOML file; nothing here reads a file.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

from ..geometry import MachineTransform, Profile
from ._probe_cal import ProbeCalibration

#: the routes of a correction to the machine (`[compensation] apply`): the adjusted part
#: program, the error specification (native + LinuxCNC comp tables), the tool-offset
#: update, or nothing. One route only: two together apply the correction twice.
APPLY_ROUTES = ("program", "errspec", "tool_offset", "none")


@dataclass(frozen=True)
class ProbeSpec:
    """Touch-trigger probe: ball radius (mm) with its standard uncertainty,
    repeatability sigma (mm), how the probe files write X, pretravel (mm), and the
    degrees of freedom the declared repeatability is worth as a prior for the
    pooled residual sigma (``repeatability_dof``; 0: no prior; see docs/uncertainty.md).
    For the gauging program: the probe's ``tool`` number and its probing ``feed``
    (mm/min: a calibration holds only at the feed it was made at); None: not given.
    ``calibration``: the probe's `ProbeCalibration` (``[probe] calibration``, a
    probe_cal.json), whose r0 is then ``ball_radius``; a calibration older than
    ``calibration_max_age_days`` is a warning in the outputs."""

    ball_radius: float
    ball_radius_u: float = 0.0
    repeatability: float = 0.001
    x_mode: str = "diameter"
    pretravel: float = 0.0
    repeatability_dof: float = 8.0
    tool: int | None = None
    feed: float | None = None
    calibration: ProbeCalibration | None = None
    calibration_max_age_days: float = 30.0


@dataclass(frozen=True)
class FitSettings:
    """How features are fitted. ``loss`` applies to ``method="robust"``; ``scale``
    is the robust standard deviation (mm; default: the probe repeatability);
    ``known_sigma`` scales covariances by the probe repeatability instead of the
    residual variance."""

    method: str = "robust"
    loss: str = "huber"
    scale: float | None = None
    known_sigma: bool = False
    min_points_line: int = 3
    min_points_arc: int = 4
    fix: tuple[str, ...] = ()
    free_transform: tuple[str, ...] = ()
    likelihood: str = "gaussian"
    nu: float = 4.0
    bayes_steps: int = 6000
    bayes_walkers: int | None = None
    bayes_ensembles: int = 4


@dataclass(frozen=True)
class CompensationSettings:
    """PIECS mirroring: ``gain`` in [0, 1] (1 = full mirroring), the largest
    correction (mm) of any vertex that the tool accepts, and ``apply``, the one
    route of the correction to the machine (one of `APPLY_ROUTES`; ``None``: not
    given, the jobs' default: ``"program"`` when the study names a part program,
    else ``"errspec"``)."""

    gain: float = 1.0
    max_correction: float = 0.2
    apply: str | None = None


#: the part-program dialects a study may name (`[program] dialect`; gcode reads them)
PROGRAM_DIALECTS = ("linuxcnc", "fanuc", "haas", "okuma")


@dataclass(frozen=True)
class ProgramSettings:
    """How the part program is adjusted: the tool-nose radius (mm) or a LinuxCNC
    tool table for the gouge check, an explicit ``{feature id: (line, ...)}``
    mapping of finish-cut blocks (overrides the mapping by geometry) and the
    distance (mm) within which a block counts as lying on a feature; ``stock``: the
    most material the semifinished part may carry beyond the nominal profile (mm),
    which the gauging program's moves keep clear of; ``dialect``: the part program's
    dialect (one of ``PROGRAM_DIALECTS``; None: detected from the program)."""

    nose_radius: float | None = None
    tool_table: Path | None = None
    mapping: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    tolerance: float = 0.01
    stock: float = 0.5
    dialect: str | None = None
    path_tip: int | None = None
    """The program is a tool path without G41/G42 (CAM output) written for this point:
    LinuxCNC orientation 1-8 (the imaginary tip), 0 or 9 (the nose centre); its nose is
    ``nose_radius``. None: the program is compensated (G41/G42)."""


@dataclass(frozen=True, eq=False)
class Study:
    """One compensation job, validated, in mm and radius X."""

    path: Path
    name: str
    units: str
    profile: Profile
    probe: ProbeSpec
    transform: MachineTransform
    sources: MappingProxyType
    probe_files: tuple[Path, ...]
    program: Path | None
    fit: FitSettings
    compensation: CompensationSettings
    sections: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    decision: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    capability: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    offsets: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    errspec: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    plan: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))
    probe_format: str = "csv"
    probe_plan: Path | None = None
    program_settings: ProgramSettings = field(default_factory=ProgramSettings)
    encoding: str = "utf-8"
    plausibility: MappingProxyType = field(default_factory=lambda: MappingProxyType({}))

    def __repr__(self) -> str:
        return (
            f"Study({self.name!r}, {len(self.profile)} features "
            f"[{', '.join(self.profile.ids)}], {len(self.probe_files)} probe file(s), "
            f"program={self.program.name if self.program else None})"
        )


def split_fix(item: str) -> tuple[str, str]:
    """One `[fit] fix` entry, ``"feature.parameter"``, as ``(feature, parameter)``."""
    fid, _, name = str(item).partition(".")
    return fid, name


def parse_fix(items) -> dict[str, tuple[str, ...]]:
    """The study's `[fit] fix` list as ``{feature: (parameter, ...)}``, in order."""
    fix: dict[str, list[str]] = {}
    for item in items:
        fid, name = split_fix(item)
        fix.setdefault(fid, []).append(name)
    return {k: tuple(v) for k, v in fix.items()}
