"""The bundle of results of the main job ([`run_job`][piecs_bayes.jobs.run_job]) and
what a reproduction needs: input files with SHA-256 hashes, package versions."""

from __future__ import annotations

import hashlib
import platform
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

#: packages whose versions a report lists (those that change numbers)
VERSIONED_PACKAGES = (
    "piecs_bayes",
    "jax",
    "jaxlib",
    "optimistix",
    "equinox",
    "emcee",
    "numpy",
    "scipy",
    "arviz",
    "matplotlib",
)

STEPS = ("fit", "bayes", "decisions", "path", "uncertainty", "program", "errspec", "capability")


@dataclass(frozen=True)
class InputFile:
    """One input of the job: its role (`study`, `probe`, `program`, `tool_table`),
    path, size in bytes and SHA-256 hash."""

    role: str
    path: Path
    size: int
    sha256: str


def hash_file(role: str, path) -> InputFile:
    path = Path(path)
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(1 << 16), b""):
            h.update(block)
    return InputFile(role, path, path.stat().st_size, h.hexdigest())


def package_versions(names: Sequence[str] = VERSIONED_PACKAGES) -> dict[str, str]:
    """Installed versions of `names` (and of Python); `"not installed"` where absent."""
    from importlib import metadata

    out = {"python": platform.python_version()}
    for name in names:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


@dataclass(frozen=True, eq=False)
class JobResults:
    """Everything one run of the main job produced (see [`run_job`][]).

    **Fields** (`None` where a step was switched off or unavailable; see
    `unavailable` for why):

    - `study`, `part`, `fit`: the study, the part fitted, its robust (or plain) fit.
    - `bayes`: the Bayesian fit (`BayesProfileFit`; `.posterior` holds the draws
      and the convergence diagnostics).
    - `bayes_characteristics`: by feature id, `(mean, sd)` (mm) of the normal
      deviation at the decision's point, from the posterior draws.
    - `decisions`: the `DecisionTable`; `gains` the gain per feature applied to the
      path, the program and the error spec (the decisions' gains, else the study's).
    - `characteristics`: without a decision table, by feature id, the `Characteristic`
      at the worst point of each fitted feature (the report's deviations); `None`
      with one (its `estimates` hold them).
    - `path`: the adjusted tool path (`AdjustedPath`).
    - `uncertainty`: `{"linearised": ToolpathUncertainty, "monte_carlo": ... or None}`.
    - `program`: the `ProgramAdjustment` (`.text`, `.diff`); `nose_radius` the nose
      radius (mm) it was checked with for gouges, or `None`.
    - `errspec`, `offsets`, `offset_notes`: the error specification, the tool-offset
      update and its notes.
    - `capability`: the `CapabilityStudy` over the parts of the probe data.
    - `unavailable`: step -> reason for every step that was asked for and could not
      be done; `skipped`: steps switched off.
    - `inputs`, `versions`, `settings`, `timings` (s per step), `created` (ISO time),
      `warnings`: what a reproduction needs.
    - `apply`: the one route of the correction to the machine (`"program"`,
      `"errspec"`, `"tool_offset"` or `"none"`; see `apply_route`), `apply_why` why
      it was chosen. The other routes' data are results too, never to be combined.
    """

    study: object
    part: str | None
    fit: object
    bayes: object | None = None
    bayes_characteristics: Mapping[str, tuple[float, float]] | None = None
    decisions: object | None = None
    characteristics: Mapping[str, object] | None = None
    gains: Mapping[str, float] = field(default_factory=dict)
    path: object | None = None
    uncertainty: Mapping[str, object] | None = None
    program: object | None = None
    nose_radius: float | None = None
    errspec: object | None = None
    offsets: object | None = None
    offset_notes: tuple[str, ...] = ()
    capability: object | None = None
    unavailable: Mapping[str, str] = field(default_factory=dict)
    skipped: tuple[str, ...] = ()
    inputs: tuple[InputFile, ...] = ()
    versions: Mapping[str, str] = field(default_factory=dict)
    settings: Mapping[str, object] = field(default_factory=dict)
    timings: Mapping[str, float] = field(default_factory=dict)
    created: str = ""
    warnings: tuple[str, ...] = ()
    part_note: str = ""
    apply: str | None = None
    apply_why: str = ""

    @property
    def converged(self) -> bool | None:
        """The posterior's convergence verdict (`None` without a Bayesian fit)."""
        return None if self.bayes is None else bool(self.bayes.posterior.converged)

    def __repr__(self) -> str:
        done = [s for s in STEPS if s not in self.unavailable and s not in self.skipped]
        lines = [
            f"JobResults({self.study.name!r}, part {self.part!r}; done: {', '.join(done)})",
        ]
        if self.decisions is not None:
            for d in self.decisions.decisions:
                lines.append(
                    f"  {d.feature:<10} {d.estimate * 1e3:+8.2f} um, u {d.u_estimate * 1e3:5.2f} "
                    f"um  {d.verdict:<18} gain {self.gains.get(d.feature, 0.0):.2f}"
                )
        for step, why in self.unavailable.items():
            lines.append(f"  {step}: unavailable: {why}")
        if self.apply is not None:
            lines.append(f"  apply: {self.apply} ({self.apply_why})")
        return "\n".join(lines)
