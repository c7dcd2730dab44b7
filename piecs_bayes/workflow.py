"""The main job on one study, end to end: [`run_job`][] -> [`JobResults`][].

One call composes the public API in the order an engineer works:

1. read the study and its probe data; **robust fit** of every feature of one part;
2. **Bayesian fit** (emcee) with the study's error sources as nuisance parameters;
3. **decisions** per feature (compensate with a gain, do not compensate, measure
   more), from the robust fit's normal deviations (`decisions.decide_study`);
4. the **adjusted tool path** (PIECS mirroring with the decisions' gains);
5. its **uncertainty**: linearised (GUM) and, with the posterior, Monte Carlo
   (JCGM 101): vertex covariances, pointwise and simultaneous bands, budget;
6. the **adjusted part program** and its diff, when the study names a program;
7. the **error specification** and the **tool-offset update**;
8. a **capability study** when the probe data hold several parts (at least 3).

Every step after the robust fit is optional (keyword switches). A step that
cannot give an answer (an `AnalysisError` or `InputError` of that step only,
e.g. a program block that maps to no feature) does not stop the job: the
results say which step is unavailable and why (`JobResults.unavailable`). Bad
input to the job itself (the study, the probe files) and a failed robust fit
raise as usual.

The results are one immutable bundle that the writers in `export` (tables,
`report_html`, `report_pdf`) read; nothing in it is recomputed by them. The
bundle also records the inputs (files with SHA-256 hashes), the package
versions and the settings, so that a report can be reproduced.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import hashlib
import math
import platform
import sys
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from types import MappingProxyType

import numpy as np

from .errors import AnalysisError, InputError, PiecsError

__all__ = ["InputFile", "JobResults", "run_job", "package_versions"]

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


def _hash_file(role: str, path) -> InputFile:
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
    """

    study: object
    part: str | None
    fit: object
    bayes: object | None = None
    bayes_characteristics: Mapping[str, tuple[float, float]] | None = None
    decisions: object | None = None
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

    @property
    def converged(self) -> bool | None:
        """The posterior's convergence verdict (`None` without a Bayesian fit)."""
        return None if self.bayes is None else bool(self.bayes.posterior.converged)

    def summary_rows(self) -> list[dict]:
        """One row per feature: nominal, tolerance, deviation with U (k=2), verdict, gain."""
        from .export._report import summary_rows

        return summary_rows(self)

    def __repr__(self) -> str:
        done = [s for s in STEPS if s not in self.unavailable and s not in self.skipped]
        lines = [
            f"JobResults({self.study.name!r}, part {self.part!r}; done: {', '.join(done)})",
        ]
        for r in self.summary_rows():
            lines.append(
                f"  {r['feature']:<10} {r['deviation_um']:+8.2f} ± {r['U_um']:5.2f} um (k=2)  "
                f"{r['verdict']:<18} gain {r['gain']:.2f}"
            )
        for step, why in self.unavailable.items():
            lines.append(f"  {step}: unavailable: {why}")
        return "\n".join(lines)

    def _repr_html_(self) -> str:
        from .export._report import summary_html

        return summary_html(self)


class _Progress:
    """Progress lines: to a callable (as they are), to stderr with the elapsed time
    (`True`), or nowhere (`False`)."""

    def __init__(self, progress):
        t0 = time.perf_counter()
        if progress is True:
            self.out = lambda msg: print(
                f"[{time.perf_counter() - t0:6.1f} s] {msg}", file=sys.stderr, flush=True
            )
        elif callable(progress):
            self.out = progress
        else:
            self.out = None

    @property
    def bar(self) -> bool:
        """Whether the sampler shows its progress bar."""
        return self.out is not None

    def __call__(self, msg: str) -> None:
        if self.out is not None:
            self.out(msg)


def _clip_gains(gains: Mapping[str, float]) -> dict[str, float]:
    """Gains in [0, 1] (a Bayes-optimal gain can come back as 1 + 1 ulp)."""
    out = {}
    for fid, g in gains.items():
        g = float(g)
        out[fid] = min(max(g, 0.0), 1.0) if math.isfinite(g) else 0.0
    return out


def _normal_deviations(feature, devs, t: float) -> np.ndarray:
    """Normal deviation (mm, + outward) at the nominal point at fraction `t` of
    `feature` for each row of deviation draws `devs` (NumPy; the same model as
    `decisions.normal_deviation`)."""
    q = np.asarray(feature.point_at(np.array([t])), dtype=float)[0]
    devs = np.asarray(devs, dtype=float)
    if feature.kind == "line":
        n0 = np.asarray(feature.normal, dtype=float)
        mid = np.asarray(feature.midpoint, dtype=float)
        c, s = np.cos(devs[:, 1]), np.sin(devs[:, 1])  # geometry.rotate, CCW in the drawing
        n = np.stack([c * n0[0] + s * n0[1], -s * n0[0] + c * n0[1]], axis=1)
        point = mid + devs[:, :1] * n0
        return -np.sum((q - point) * n, axis=1)
    centre = np.asarray(feature.center, dtype=float) + devs[:, :2]
    r = feature.radius + devs[:, 2]
    return -feature.sense * (np.linalg.norm(q - centre, axis=1) - r)


def _bayes_characteristics(bayes, decisions):
    """Posterior mean and sd of each feature's normal deviation at the decision point."""
    draws = bayes.deviation_samples
    out = {}
    for d, c in zip(decisions.decisions, decisions.estimates, strict=True):
        if c is None or d.feature not in draws:
            continue
        vals = _normal_deviations(bayes.profile[d.feature], draws[d.feature], c.t)
        out[d.feature] = (float(vals.mean()), float(vals.std(ddof=1)))
    return MappingProxyType(out)


def run_job(
    study,
    *,
    part: str | None = None,
    method: str | None = None,
    bayes: bool = True,
    nsteps: int | None = None,
    seed: int = 0,
    decisions: bool = True,
    uncertainty: bool = True,
    program: bool = True,
    nose_radius: float | None = None,
    tool_table=None,
    errspec: bool = True,
    capability: bool | str = "auto",
    capability_files: Sequence | None = None,
    progress: bool | Callable[[str], None] = False,
) -> JobResults:
    """Run the main job on one study (one part) and return the results bundle.

    **Arguments:**

    - `study`: a `Study` or the path of a study file.
    - `part`: the part to fit when the probe data hold several (default: the first).
    - `method`: `"robust"` or `"lsq"` (default: the study's `fit.method`; `"bayes"` there
      means a robust fit first).
    - `bayes`: also sample the posterior (`nsteps` per ensemble, default the study's
      `[fit] bayes_steps`; `seed`). A run that has not converged warns
      (`ConvergenceWarning`) and the results say so (`converged`, the posterior's
      `problems`).
    - `decisions`: decide per feature; the decisions' gains (0 unless "compensate")
      then drive the path, the program and the error spec. Without it, the study's
      `compensation.gain` does.
    - `uncertainty`: linearised and (with `bayes`) Monte Carlo tool-path uncertainty.
    - `program`: rewrite the study's part program (`study.part_program`) to the
      adjusted path; `nose_radius` (mm) or `tool_table` (a `ToolTable` or a LinuxCNC
      `.tbl` path in mm) let the result be checked for gouges with the nose radius
      (default: the study's `[program] nose_radius` or `tool_table`, else `[offsets]
      current_r`, else no nose-radius check).
    - `errspec`: error specification and tool-offset update.
    - `capability`: `"auto"` (when the probe data, or `capability_files`, hold at
      least 3 parts), `True` or `False`.
    - `progress`: `True` prints timed progress lines to stderr and shows the
      sampler's progress bar; a callable receives the lines; `False` is silent.

    **Returns:** a [`JobResults`][].
    """
    from .pipeline import (
        bayes_study,
        compensate_study,
        fit_study,
        load_probe_data,
        load_study,
        toolpath_uncertainty,
    )

    say = _Progress(progress)
    timings: dict[str, float] = {}
    unavailable: dict[str, str] = {}
    skipped: list[str] = []
    caught: list[str] = []
    created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")

    @contextlib.contextmanager
    def timed(step):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            timings[step] = timings.get(step, 0.0) + time.perf_counter() - t0

    with timed("read"):
        if not hasattr(study, "profile"):
            study = load_study(study)
        probe = load_probe_data(study)
    say(f"read {study!r}: {len(probe)} probe points, {len(probe.parts)} part(s)")
    part_note = ""
    if part is None and len(probe.parts) > 1:
        # the part just measured (production order) is the one to compensate; said, not silent
        part = probe.parts[-1]
        part_note = (
            f"the probe data hold {len(probe.parts)} parts: part {part} (the last, in "
            "production order) is fitted and compensated; choose another with --part"
        )
        say(part_note)

    # 1. robust fit
    with timed("fit"):
        fit = fit_study(study, probe, method=method, part=part)
    say(f"fitted {len(fit.fits)} features ({fit.method}, part {fit.part})")
    gains = _clip_gains({f.id: study.compensation.gain for f in study.profile.features})

    # 2. Bayesian fit
    bayes_fit = None
    if bayes:
        say("sampling the posterior (emcee)")
        with timed("bayes"), warnings.catch_warnings(record=True) as ws:
            warnings.simplefilter("always")
            try:
                bayes_fit = bayes_study(
                    study, fit, probe, part=fit.part, nsteps=nsteps, seed=seed, progress=say.bar
                )
            except PiecsError as exc:
                unavailable["bayes"] = str(exc)
        for w in ws:  # re-issue outside the recorder: the caller's filters decide
            caught.append(str(w.message))
            warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
        if bayes_fit is not None:
            post = bayes_fit.posterior
            say(
                f"posterior: {len(post.names)} parameters, "
                f"{'converged' if post.converged else 'NOT converged'}, "
                f"{post.ess_per_second:.0f} effective samples/s"
            )
    else:
        skipped.append("bayes")

    # 3. decisions
    table = None
    bayes_chars = None
    if decisions:
        with timed("decisions"):
            try:
                from .decisions import decide_study

                table = decide_study(study, fit)
                gains.update(_clip_gains(table.gains))
                if bayes_fit is not None:
                    bayes_chars = _bayes_characteristics(bayes_fit, table)
            except (PiecsError, ImportError) as exc:
                unavailable["decisions"] = str(exc)
        if table is not None:
            verdicts = ", ".join(f"{d.feature} {d.verdict}" for d in table.decisions)
            say(f"decided: {verdicts}")
    else:
        skipped.append("decisions")

    # 4. adjusted tool path
    with timed("path"):
        try:
            path = compensate_study(study, fit, gain=gains)
        except AnalysisError as exc:
            path = None
            unavailable["path"] = str(exc)
    if path is not None:
        say(f"adjusted tool path: {path!r}")

    # 5. its uncertainty
    unc = None
    if uncertainty and path is not None:
        with timed("uncertainty"):
            try:
                unc = MappingProxyType(
                    dict(toolpath_uncertainty(study, fit, probe, bayes=bayes_fit, gain=gains))
                )
            except PiecsError as exc:
                unavailable["uncertainty"] = str(exc)
        if unc is not None:
            say(f"tool-path bounds: {unc['linearised']!r}")
    elif not uncertainty:
        skipped.append("uncertainty")
    else:
        unavailable["uncertainty"] = "no adjusted tool path"

    # 6. adjusted part program
    adjustment = None
    ps = getattr(study, "program_settings", None)
    if nose_radius is None and ps is not None and ps.nose_radius is not None:
        nose_radius = float(ps.nose_radius)
    if nose_radius is None and "current_r" in study.offsets:
        nose_radius = float(study.offsets["current_r"])
    if tool_table is None and ps is not None and ps.tool_table is not None:
        tool_table = ps.tool_table
    if program and study.program is None:
        unavailable["program"] = "the study names no part program (study.part_program)"
    elif program and path is None:
        unavailable["program"] = "no adjusted tool path"
    elif program:
        with timed("program"):
            try:
                from .pipeline import adjust_study_program

                adjustment = adjust_study_program(
                    study, path, nose_radius=nose_radius, tool_table=tool_table
                )
            except (PiecsError, ImportError) as exc:
                unavailable["program"] = str(exc)
        if adjustment is not None:
            say(f"adjusted program: {adjustment!r}")
    else:
        skipped.append("program")

    # 7. error spec and tool offsets
    spec = upd = None
    onotes: tuple[str, ...] = ()
    if errspec:
        with timed("errspec"):
            try:
                from .decisions import error_spec, tool_offsets

                spec = error_spec(study, fit, gain=gains)
            except (PiecsError, ImportError) as exc:
                unavailable["errspec"] = str(exc)
            try:
                from .decisions import tool_offsets

                upd, onotes = tool_offsets(study, fit)
            except (PiecsError, ImportError) as exc:
                onotes = (f"no tool-offset update: {exc}",)
        if spec is not None:
            say(f"error spec: {len(spec.tables)} table(s); tool offsets: {_offset_line(upd)}")
    else:
        skipped.append("errspec")

    # 8. capability over the parts
    cap = None
    cap_probe = probe if capability_files is None else load_probe_data(study, capability_files)
    n_parts = len(cap_probe.parts)
    if capability is True or (capability == "auto" and n_parts >= 3):
        from .decisions import capability_study

        every = max(1, n_parts // 6)

        def tick(i, n, p):
            if i % every == 0 or i == n:
                say(f"capability: fitted {i}/{n} parts ({p})")

        with timed("capability"):
            try:
                cap = capability_study(study, cap_probe, method=method, seed=seed, progress=tick)
            except (PiecsError, ImportError) as exc:
                unavailable["capability"] = str(exc)
    elif capability == "auto":
        unavailable["capability"] = (
            f"the probe data hold {n_parts} part(s); a capability study needs at least 3"
        )
    elif capability is not False:
        raise InputError(f"capability: got {capability!r}, expected 'auto', True or False")
    else:
        skipped.append("capability")

    inputs = [_hash_file("study", study.path)]
    inputs += [_hash_file("probe", p) for p in study.probe_files]
    if capability_files is not None:
        inputs += [_hash_file("probe (capability)", p) for p in capability_files]
    if study.program is not None:
        inputs.append(_hash_file("program", study.program))
    if tool_table is not None and not hasattr(tool_table, "get"):
        inputs.append(_hash_file("tool_table", tool_table))
    post = None if bayes_fit is None else bayes_fit.posterior
    settings = {
        "method": fit.method,
        "loss": study.fit.loss,
        "seed": seed,
        "bayes_steps": None if post is None else post.nsteps,
        "bayes_walkers": None if post is None else post.nwalkers,
        "bayes_ensembles": None if post is None else post.n_ensembles,
        "bayes_burn": None if post is None else post.burn,
        "likelihood": study.fit.likelihood,
        "gain": study.compensation.gain,
        "max_correction_mm": study.compensation.max_correction,
        "nose_radius_mm": nose_radius,
        "decision_characteristic": None if table is None else table.characteristic,
        "command": " ".join(sys.argv) if sys.argv and sys.argv[0] else "",
    }
    say("done")
    return JobResults(
        study=study,
        part=fit.part,
        fit=fit,
        bayes=bayes_fit,
        bayes_characteristics=bayes_chars,
        decisions=table,
        gains=MappingProxyType(gains),
        path=path,
        uncertainty=unc,
        program=adjustment,
        nose_radius=nose_radius if adjustment is not None else None,
        errspec=spec,
        offsets=upd,
        offset_notes=tuple(onotes),
        capability=cap,
        unavailable=MappingProxyType(unavailable),
        skipped=tuple(skipped),
        inputs=tuple(inputs),
        versions=MappingProxyType(package_versions()),
        settings=MappingProxyType(settings),
        timings=MappingProxyType(timings),
        created=created,
        part_note=part_note,
        warnings=tuple(caught),
    )


def _offset_line(upd) -> str:
    if upd is None:
        return "none"
    if upd.blocked:
        return "blocked"
    return "update" if upd.any_update else "no change"
