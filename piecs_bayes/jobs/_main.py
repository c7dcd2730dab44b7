"""The main job on one study, end to end: [`run_job`][] -> [`JobResults`][].

One call composes the public API in the order an engineer works: read the study and its
probe data, robust fit of every feature of one part, Bayesian fit with the study's error
sources, decisions per feature, the adjusted tool path with its uncertainty (GUM and
Monte Carlo), the adjusted part program, the error specification and tool-offset update
(three routes of one correction: `JobResults.apply` names the one to load), and a
capability study when the probe data hold at least 3 parts. Every step after the robust
fit is optional; a step that cannot give an answer does not stop the job
(`JobResults.unavailable` says why), while bad input to the job itself and a failed
robust fit raise. The results are one immutable bundle the writers in `export` read
(nothing is recomputed there), with the inputs' SHA-256 hashes, the package versions and
the settings, so that a report can be reproduced.

The steps and the bundle: docs/models/jobs.md.
"""

from __future__ import annotations

import contextlib
import datetime as _dt
import functools
import math
import sys
import threading
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from types import MappingProxyType

from ..errors import AnalysisError, InputError, PiecsError
from ..fit.mcmc import quiet_arviz_notice
from ..gcode import GAUGING_NAMES
from ..io import load_study
from ..uncertainty import normal_deviation_draws
from ._apply import apply_route
from ._capability import capability_study
from ._decide import characteristics, decide_study
from ._fit import (
    adjust_study_program,
    bayes_study,
    compensate_study,
    fit_study,
    linearised_uncertainty,
    load_probe_data,
    monte_carlo_uncertainty,
)
from ._machine import error_spec, tool_offsets
from ._probe_radius import calibration_warnings
from ._results import JobResults, hash_file, package_versions


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


@dataclass
class _Run:
    """The state of one run of the main job, passed from step to step."""

    study: object
    probe: object
    say: _Progress
    t0: float = 0.0
    fit: object = None
    gains: dict = field(default_factory=dict)
    timings: dict = field(default_factory=dict)
    unavailable: dict = field(default_factory=dict)
    skipped: list = field(default_factory=list)
    caught: list = field(default_factory=list)
    out: dict = field(default_factory=dict)

    @contextlib.contextmanager
    def timed(self, step):
        t0 = time.perf_counter()
        try:
            yield
        finally:
            self.timings[step] = self.timings.get(step, 0.0) + time.perf_counter() - t0


@dataclass(frozen=True)
class JobOptions:
    """What the main job does ([`run_job`][]); every step after the robust fit can be
    switched off.

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
    - `capability`: `"auto"` (when the probe data, or the job's `capability_files`, hold
      at least 3 parts), `True` or `False`.
    - `apply`: the route of the correction to the machine (`"program"`, `"errspec"`,
      `"tool_offset"`, `"none"`; default: the study's `[compensation] apply`, else
      `"program"` when it names a part program, else `"errspec"`).
    """

    method: str | None = None
    bayes: bool = True
    nsteps: int | None = None
    seed: int = 0
    decisions: bool = True
    uncertainty: bool = True
    program: bool = True
    nose_radius: float | None = None
    tool_table: object = None
    errspec: bool = True
    capability: bool | str = "auto"
    apply: str | None = None

    def __post_init__(self):
        capability = self.capability
        if not (capability is True or capability is False or capability == "auto"):
            raise InputError(f"capability: got {capability!r}, expected 'auto', True or False")


def run_job(
    study,
    options: JobOptions | None = None,
    *,
    part: str | None = None,
    capability_files: Sequence | None = None,
    progress: bool | Callable[[str], None] = False,
) -> JobResults:
    """Run the main job on one study (one part) and return the results bundle.

    **Arguments:**

    - `study`: a `Study` or the path of a study file.
    - `options`: what the job does (a [`JobOptions`][]; default: every step, the
      study's settings).
    - `part`: the part to fit when the probe data hold several (default: the last).
    - `capability_files`: probe files of the parts for the capability study, instead
      of the study's probe data.
    - `progress`: `True` prints timed progress lines to stderr and shows the
      sampler's progress bar; a callable receives the lines; `False` is silent.

    **Returns:** a [`JobResults`][].
    """
    o = options if options is not None else JobOptions()
    created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    run = _read(study, _Progress(progress))
    run.out["apply"] = route = apply_route(run.study, o.apply)
    part, part_note = _choose_part(run, part)
    run.say(f"fitting {len(run.study.profile)} features")
    with run.timed("fit"):
        run.fit = fit_study(run.study, run.probe, method=o.method, part=part)
    run.say(f"fitted {len(run.fit.fits)} features ({run.fit.method}, part {run.fit.part})")
    run.gains = _clip_gains({f.id: run.study.compensation.gain for f in run.study.profile.features})
    beside = _Beside(run, o.decisions, o.uncertainty)
    if o.bayes:
        beside.start()  # the steps that need only the robust fit, while the sampler runs
    _step_bayes(run, o.bayes, o.nsteps, o.seed)
    _step_decisions(run, o.decisions, beside)
    _step_path(run, o.uncertainty, beside)
    nose_radius, tool_table = _nose_radius_and_tools(run.study, o.nose_radius, o.tool_table)
    _step_program(run, o.program, nose_radius, tool_table, created)
    _step_errspec(run, o.errspec)
    _step_capability(run, o.capability, capability_files, o.method, o.seed)
    run.say(f"main job finished in {time.perf_counter() - run.t0:.1f} s; route: {route[0]}")
    return _results(run, o.seed, nose_radius, tool_table, capability_files, created, part_note)


def _read(study, say: _Progress) -> _Run:
    t0 = time.perf_counter()
    if not hasattr(study, "profile"):
        study = load_study(study)
    probe = load_probe_data(study)
    run = _Run(study=study, probe=probe, say=say, t0=t0)
    for msg in calibration_warnings(study.probe):  # in the outputs and the report
        warnings.warn(msg, stacklevel=2)
        run.caught.append(msg)
    run.timings["read"] = time.perf_counter() - t0
    say(f"read {study!r}: {len(probe)} probe points, {len(probe.parts)} part(s)")
    return run


def _choose_part(run: _Run, part):
    """The part to fit; with several and none named, the last (production order), said."""
    parts = run.probe.parts
    if part is not None or len(parts) <= 1:
        return part, ""
    part = parts[-1]
    note = (
        f"the probe data hold {len(parts)} parts: part {part} (the last, in "
        "production order) is fitted and compensated; choose another with --part"
    )
    run.say(note)
    return part, note


class _Beside:
    """Steps 3 to 5 as far as they need only the robust fit: the decisions, the gains
    they give, the adjusted path and its linearised uncertainty. With the Bayesian fit
    on, a thread computes them while the sampler runs (its compiled loop releases the
    GIL; on 2 cores it still uses part of the second, so the gain grows with cores:
    docs/models/jobs.md); without it, the first `result()` computes them here. Each
    is the step's own call on the same inputs, so the results do not depend on which
    thread made them; the steps read them in their order, report them and re-raise a
    failure that is not a `PiecsError` where the step would have. The timings are the
    computations' own."""

    def __init__(self, run: _Run, decisions: bool, uncertainty: bool):
        self._args = (run.study, run.fit, run.probe, dict(run.gains), decisions, uncertainty)
        self._out: dict | None = None
        self._error: BaseException | None = None
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._thread = threading.Thread(target=self._work, name="piecs-bayes-beside",
                                        daemon=True)  # fmt: skip
        self._thread.start()

    def result(self) -> dict:
        if self._thread is not None:
            self._thread.join()
        elif self._out is None and self._error is None:
            self._work()
        if self._error is not None:
            raise self._error
        return self._out

    def _work(self) -> None:
        try:
            self._out = self._compute(*self._args)
        except BaseException as exc:  # noqa: BLE001 - re-raised by result()
            self._error = exc

    @staticmethod
    def _compute(study, fit, probe, gains, decisions, uncertainty) -> dict:
        out: dict = {"timings": {}, "gains": gains}

        def attempt(step, key, fn, *errors):
            t0 = time.perf_counter()
            try:
                out[key] = fn()
            except errors as exc:
                out[f"{key}_error"] = exc
            out["timings"][step] = time.perf_counter() - t0
            return out.get(key)

        if decisions:
            decide = functools.partial(decide_study, study, fit)
            table = attempt("decisions", "decisions", decide, PiecsError)
            if table is not None:
                gains.update(_clip_gains(table.gains))
        adjust = functools.partial(compensate_study, study, fit, gain=gains)
        path = attempt("path", "path", adjust, AnalysisError)
        if uncertainty and path is not None:
            lin = functools.partial(linearised_uncertainty, study, fit, probe, gain=gains)
            attempt("uncertainty", "linearised", lin, PiecsError)
        return out


def _step_bayes(run: _Run, bayes: bool, nsteps, seed) -> None:
    """2. The Bayesian fit; its warnings are recorded and re-issued."""
    if not bayes:
        run.skipped.append("bayes")
        return
    steps = run.study.fit.bayes_steps if nsteps is None else nsteps
    run.say(f"sampling the posterior ({run.study.fit.bayes_ensembles} ensembles x {steps} steps)")
    fit = None
    with run.timed("bayes"), warnings.catch_warnings(record=True) as ws:
        warnings.simplefilter("always")
        # but arviz's import notice, which the prefetch thread may raise while this
        # records (it did whenever the fit was done before arviz was imported)
        quiet_arviz_notice()
        try:
            fit = bayes_study(
                run.study, run.fit, run.probe, part=run.fit.part, nsteps=nsteps, seed=seed,
                progress=run.say if run.say.bar else False,
            )  # fmt: skip
        except PiecsError as exc:
            run.unavailable["bayes"] = str(exc)
    for w in ws:  # re-issue outside the recorder: the caller's filters decide
        run.caught.append(str(w.message))
        warnings.warn_explicit(w.message, w.category, w.filename, w.lineno)
    run.out["bayes"] = fit
    if fit is not None:
        post = fit.posterior
        run.say(
            f"posterior: {len(post.names)} parameters, "
            f"{'converged' if post.converged else 'NOT converged'}, "
            f"{post.ess_per_second:.0f} effective samples/s"
        )


def _bayes_characteristics(bayes, decisions):
    """Posterior mean and sd of each feature's normal deviation at the decision point."""
    draws = bayes.deviation_samples
    out = {}
    for d, c in zip(decisions.decisions, decisions.estimates, strict=True):
        if c is None or d.feature not in draws:
            continue
        vals = normal_deviation_draws(bayes.profile[d.feature], draws[d.feature], c.t)
        out[d.feature] = (float(vals.mean()), float(vals.std(ddof=1)))
    return MappingProxyType(out)


def _step_decisions(run: _Run, decisions: bool, beside: _Beside) -> None:
    """3. Decisions per feature; their gains drive the path, program and error spec."""
    if not decisions:
        run.skipped.append("decisions")
        return
    early = beside.result()
    run.timings["decisions"] = early["timings"]["decisions"]
    table = early.get("decisions")
    if table is None:
        run.unavailable["decisions"] = str(early["decisions_error"])
    else:
        run.gains.update(early["gains"])
        if run.out.get("bayes") is not None:
            with run.timed("decisions"):
                try:
                    run.out["bayes_characteristics"] = _bayes_characteristics(
                        run.out["bayes"], table
                    )
                except PiecsError as exc:
                    run.unavailable["decisions"] = str(exc)
    run.out["decisions"] = table
    if table is not None:
        verdicts = ", ".join(f"{d.feature} {d.verdict}" for d in table.decisions)
        run.say(f"decided: {verdicts}")


def _step_path(run: _Run, uncertainty: bool, beside: _Beside) -> None:
    """4. The adjusted tool path and 5. its uncertainty."""
    early = beside.result()
    run.timings["path"] = early["timings"]["path"]
    path = early.get("path")
    if path is None:
        run.unavailable["path"] = str(early["path_error"])
    run.out["path"] = path
    if path is not None:
        run.say(f"adjusted tool path: {path!r}")
    if not uncertainty:
        run.skipped.append("uncertainty")
        return
    if path is None:
        run.unavailable["uncertainty"] = "no adjusted tool path"
        return
    unc = None
    bayes = run.out.get("bayes")
    mc = " and Monte Carlo" if bayes is not None else ""
    run.say(f"tool-path uncertainty: linearised (GUM){mc} propagation")
    run.timings["uncertainty"] = early["timings"]["uncertainty"]
    lin = early.get("linearised")
    if lin is None:
        run.unavailable["uncertainty"] = str(early["linearised_error"])
    else:
        with run.timed("uncertainty"):
            try:
                mc = None
                if bayes is not None:
                    mc = monte_carlo_uncertainty(run.study, bayes, lin, gain=run.gains)
                unc = MappingProxyType({"linearised": lin, "monte_carlo": mc})
            except PiecsError as exc:
                run.unavailable["uncertainty"] = str(exc)
    run.out["uncertainty"] = unc
    if unc is not None:
        run.say(f"tool-path bounds: {unc['linearised']!r}")


def _nose_radius_and_tools(study, nose_radius, tool_table):
    """The nose radius for the gouge check: given, else `[program]`, else `[offsets]
    current_r`; the tool table: given, else `[program] tool_table`."""
    ps = getattr(study, "program_settings", None)
    if nose_radius is None and ps is not None and ps.nose_radius is not None:
        nose_radius = float(ps.nose_radius)
    if nose_radius is None and "current_r" in study.offsets:
        nose_radius = float(study.offsets["current_r"])
    if tool_table is None and ps is not None and ps.tool_table is not None:
        tool_table = ps.tool_table
    return nose_radius, tool_table


def _step_program(run: _Run, program: bool, nose_radius, tool_table, created) -> None:
    """6. The adjusted part program, when the study names one."""
    path = run.out.get("path")
    if program and run.study.program is None:
        run.unavailable["program"] = "the study names no part program (study.part_program)"
    elif program and path is None:
        run.unavailable["program"] = "no adjusted tool path"
    elif not program:
        run.skipped.append("program")
    else:
        adjustment = None
        with run.timed("program"):
            try:
                adjustment = adjust_study_program(
                    run.study,
                    path,
                    nose_radius=nose_radius,
                    tool_table=tool_table,
                    created=created,
                )
            except PiecsError as exc:
                run.unavailable["program"] = str(exc)
        run.out["program"] = adjustment
        if adjustment is not None:
            run.say(f"adjusted program: {adjustment!r}")


def _step_errspec(run: _Run, errspec: bool) -> None:
    """7. The error specification and the tool-offset update."""
    if not errspec:
        run.skipped.append("errspec")
        return
    spec = upd = None
    onotes: tuple[str, ...] = ()
    with run.timed("errspec"):
        try:
            spec = error_spec(run.study, run.fit, gain=run.gains)
        except PiecsError as exc:
            run.unavailable["errspec"] = str(exc)
        try:
            upd, onotes = tool_offsets(run.study, run.fit)
        except PiecsError as exc:
            onotes = (f"no tool-offset update: {exc}",)
    run.out.update(errspec=spec, offsets=upd, offset_notes=tuple(onotes))
    if spec is not None:
        run.say(f"error spec: {len(spec.tables)} table(s); tool offsets: {_offset_line(upd)}")


def _step_capability(run: _Run, capability, capability_files, method, seed) -> None:
    """8. A capability study over the parts of the probe data (or `capability_files`)."""
    probe = run.probe
    if capability_files is not None:
        probe = load_probe_data(run.study, capability_files)
    n_parts = len(probe.parts)
    if capability is True or (capability == "auto" and n_parts >= 3):
        every = max(1, n_parts // 6)

        def tick(i, n, p):
            if i % every == 0 or i == n:
                run.say(f"capability: fitted {i}/{n} parts ({p})")

        with run.timed("capability"):
            try:
                run.out["capability"] = capability_study(
                    run.study, probe, method=method, seed=seed, progress=tick
                )
            except PiecsError as exc:
                run.unavailable["capability"] = str(exc)
    elif capability == "auto":
        run.unavailable["capability"] = (
            f"the probe data hold {n_parts} part(s); a capability study needs at least 3"
        )
    else:  # False (`JobOptions` refuses anything else)
        run.skipped.append("capability")


def _inputs(study, tool_table, capability_files) -> tuple:
    inputs = [hash_file("study", study.path)]
    inputs += [hash_file("probe", p) for p in study.probe_files]
    if capability_files is not None:
        inputs += [hash_file("probe (capability)", p) for p in capability_files]
    if study.program is not None:
        inputs.append(hash_file("program", study.program))
    if study.probe_plan is not None and study.probe_plan.is_file():
        inputs.append(hash_file("probe plan", study.probe_plan))
        gauging = [study.probe_plan.parent / n for n in GAUGING_NAMES.values()]
        inputs += [hash_file("gauging program", g) for g in gauging if g.is_file()]
    if tool_table is not None and not hasattr(tool_table, "get"):
        inputs.append(hash_file("tool_table", tool_table))
    cal = study.probe.calibration
    if cal is not None and cal.source is not None:
        inputs.append(hash_file("probe calibration", cal.source))
    return tuple(inputs)


def _settings(run: _Run, seed, nose_radius) -> dict:
    study, table = run.study, run.out.get("decisions")
    bayes = run.out.get("bayes")
    post = None if bayes is None else bayes.posterior
    return {
        "method": run.fit.method,
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
        "apply": run.out["apply"][0],
        "command": " ".join(sys.argv) if sys.argv and sys.argv[0] else "",
    }


def _results(run: _Run, seed, nose_radius, tool_table, capability_files, created, part_note):
    out = run.out
    worst = None  # without a decision table, the deviations the report shows
    if out.get("decisions") is None:
        worst = characteristics(run.study, run.fit, at="worst")
    return JobResults(
        study=run.study,
        part=run.fit.part,
        fit=run.fit,
        bayes=out.get("bayes"),
        bayes_characteristics=out.get("bayes_characteristics"),
        decisions=out.get("decisions"),
        characteristics=worst,
        gains=MappingProxyType(run.gains),
        path=out.get("path"),
        uncertainty=out.get("uncertainty"),
        program=out.get("program"),
        nose_radius=nose_radius if out.get("program") is not None else None,
        errspec=out.get("errspec"),
        offsets=out.get("offsets"),
        offset_notes=out.get("offset_notes", ()),
        capability=out.get("capability"),
        unavailable=MappingProxyType(run.unavailable),
        skipped=tuple(run.skipped),
        inputs=_inputs(run.study, tool_table, capability_files),
        versions=MappingProxyType(package_versions()),
        settings=MappingProxyType(_settings(run, seed, nose_radius)),
        timings=MappingProxyType(run.timings),
        created=created,
        part_note=part_note,
        warnings=tuple(run.caught),
        apply=out["apply"][0],
        apply_why=out["apply"][1],
    )


def _offset_line(upd) -> str:
    if upd is None:
        return "none"
    if upd.blocked:
        return "blocked"
    return "update" if upd.any_update else "no change"
