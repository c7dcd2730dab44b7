"""One part of a study: probe data -> fits -> adjusted path, program and bounds.

``study -> probe data -> fits -> adjusted path``; each step returns plain,
immutable results that print well and that the writers in `piecs_bayes.export` read.
The probe data are read once (`load_probe_data`) and passed down.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from ..errors import InputError
from ..fit import ProfileFit, fit_profile, fit_profile_joint, pooled_residuals, to_part_frame
from ..io import (
    ProbeData,
    Study,
    check_probe_data,
    read_bytes,
    read_control_probe,
    read_plan_points,
    read_probe_csv,
)
from ._options import bayes_options, calibration_sds, fit_options, sampler_options
from ._probe_radius import calibrated_points, radius_components

if TYPE_CHECKING:  # compensate pulls in scipy (~0.6 s): imported where it is used
    from ..compensate import AdjustedPath


def load_probe_data(study: Study, files=None) -> ProbeData:
    """Read the study's probe files (or ``files``) into one :class:`ProbeData`.

    Rows of several files are concatenated; each file's rows get the file stem
    as part id unless the file has a ``part`` column. A file listed twice (or two
    files with identical contents) is refused; every file's points pass the
    plausibility checks (`io.check_probe_data`: distance from the nominal feature,
    position along it, repeated triggers) before anything is fitted. With a probe
    calibration (`[probe] calibration`) the points are then corrected to its r0
    (`calibrated_points`: each along its contact normal by r(theta) - r0).
    """
    files = list(files) if files is not None else list(study.probe_files)
    if not files:
        raise InputError("the study lists no probe files (study.probe_files)", file=str(study.path))
    _refuse_repeated_files(files)
    read = _probe_reader(study)
    datas = [
        check_probe_data(
            read(f),
            study.profile,
            transform=study.transform,
            ball_radius=study.probe.ball_radius,
            max_correction=study.compensation.max_correction,
            settings=study.plausibility,
            study_file=str(study.path),
            x_mode=study.probe.x_mode,
            units=study.units,
        )
        for f in files
    ]
    cal = study.probe.calibration
    if cal is not None:
        datas = [
            replace(
                d,
                points=calibrated_points(
                    study.profile, d.feature, d.points, study.transform, cal, d.approach, d.part
                ),
            )  # fmt: skip
            for d in datas
        ]
    if len(datas) == 1:
        return datas[0]

    def cat(attr):
        vals = [getattr(d, attr) for d in datas]
        return None if any(v is None for v in vals) else np.concatenate(vals)

    return ProbeData(
        file=tuple(f for d in datas for f in d.file),
        feature=cat("feature"),
        points=cat("points"),
        lines=cat("lines"),
        part=cat("part"),
        approach=cat("approach"),
        time=cat("time"),
        temperature=cat("temperature"),
    )


def _probe_reader(study: Study):
    """How the study's probe files are read: the package's CSV, or a control's file
    against the study's probe plan (`[study] probe_format`, `probe_plan`)."""
    if study.probe_format == "csv":
        return lambda f: read_probe_csv(
            f, units=study.units, x_mode=study.probe.x_mode, features=study.profile.ids,
            encoding=study.encoding,
        )  # fmt: skip
    plan = read_plan_points(study.probe_plan)
    unknown = sorted(set(plan.feature) - set(study.profile.ids))
    if unknown:
        raise InputError(
            f"the probe plan names feature(s) {', '.join(map(repr, unknown))} that the study's "
            f"profile does not have ({', '.join(study.profile.ids)}): the plan of another study",
            file=plan.file,
            feature=unknown[0],
        )
    limit = float(study.plausibility.get("max_distance", 0.5))
    return lambda f: read_control_probe(f, study.probe_format, plan, limit_mm=limit)


def _refuse_repeated_files(files) -> None:
    """The same probe data listed twice would count every trigger twice."""
    import hashlib

    seen: dict[str, str] = {}
    for f in files:
        digest = hashlib.sha256(read_bytes(f, what="probe file")).hexdigest()
        if digest in seen:
            same = "is listed twice" if Path(seen[digest]) == Path(f) else f"repeats {seen[digest]}"
            raise InputError(
                f"probe file {same} (identical contents): its triggers would count twice",
                file=str(f),
            )
        seen[digest] = str(f)


def fit_study(
    study: Study,
    probe: ProbeData | None = None,
    *,
    method: str | None = None,
    part: str | None = None,
    solver: str = "auto",
) -> ProfileFit:
    """Fit one part of a study (``method``: ``"lsq"`` or ``"robust"``, default from the study).

    With several parts in the probe data, ``part`` chooses one (required: an
    `InputError` lists the parts when it is missing).

    The features are fitted by the batch path's compiled kernel, every feature in
    one call (`fit.fit_profile(solver="auto")`, as `fit.fit_profiles` solves them),
    and returned as the [`ProfileFit`][piecs_bayes.fit.ProfileFit] of the per-feature
    loop with its errors (`AnalysisError` for a fit that does not converge, with the
    engine's status and message); the results agree with the loop to the solvers'
    precision (tests/jobs/test_fit_fast_path.py); ``solver="lm"`` is that loop (the
    reference the batch path is tested against). A joint fit (``fit.free_transform``)
    is `fit.fit_profile_joint`.
    """
    probe = load_probe_data(study) if probe is None else probe
    data = _part_data(study, probe, part)
    part = data.parts[0]
    method = method or study.fit.method
    if method == "bayes":
        method = "robust"  # the Bayesian fit starts from the robust one; see fit.bayes
    if study.fit.free_transform:
        return fit_profile_joint(
            study.profile,
            data.feature,
            data.points,
            ball_radius=study.probe.ball_radius,
            transform=study.transform,
            free_transform=study.fit.free_transform,
            options=fit_options(study, method),
            lines=data.lines,
            part=part,
        )
    return fit_profile(
        study.profile,
        data.feature,
        to_part_frame(study.transform, data.points),
        ball_radius=study.probe.ball_radius,
        options=replace(fit_options(study, method), solver=solver),
        lines=data.lines,
        file=data.file,
        part=part,
    )


def compensate_study(study: Study, fit: ProfileFit, *, gain=None) -> AdjustedPath:
    """Mirror a fit into the adjusted tool path, with the study's gain and limit."""
    from ..compensate import adjusted_path

    return adjusted_path(
        study.profile,
        fit.deviations,
        gain=study.compensation.gain if gain is None else gain,
        max_correction=study.compensation.max_correction,
    )


def _part_data(study: Study, probe: ProbeData | None, part: str | None) -> ProbeData:
    """The rows of one part: `part`, or the only one; several and none named: refused."""
    probe = load_probe_data(study) if probe is None else probe
    parts = probe.parts
    if part is None and len(parts) > 1:
        shown = ", ".join(parts[:8]) + (", ..." if len(parts) > 8 else "")
        raise InputError(
            f"the probe data hold {len(parts)} parts ({shown}); fit one with --part PART "
            "(part=... from Python), or all of them with `piecs-bayes capability`",
            file=probe.file,
        )
    if part is not None and part not in parts:
        raise InputError(
            f"no part {part!r} in the probe data; parts are {', '.join(parts)}", file=probe.file
        )
    return probe if len(parts) == 1 else probe.for_part(part)


def inliers(fit: ProfileFit, probe: ProbeData) -> ProbeData:
    """The triggers of ``probe`` (one part) that the fit did not flag as outliers."""
    keep = np.ones(len(probe), dtype=bool)
    for f in fit:
        rows = np.flatnonzero(probe.feature == f.id)
        keep[rows[f.outliers]] = False
    return probe.select(keep)


def pooled_sigma(fit: ProfileFit) -> tuple[float, int]:
    """Pooled residual standard deviation of the inliers over all features, and its dof
    (without the declared prior: ``fit.sigma`` is what the uncertainties use)."""
    ss, dof = pooled_residuals(fit)
    if dof <= 0:
        raise InputError("too few points to estimate the probe repeatability from the residuals")
    return float(np.sqrt(ss / dof)), dof


def bayes_study(
    study: Study,
    fit: ProfileFit | None = None,
    probe: ProbeData | None = None,
    *,
    part: str | None = None,
    nsteps: int | None = None,
    n_ensembles: int | None = None,
    seed: int = 0,
    progress=True,
    on_fail: str = "warn",
    sampler: str = "lockstep",
):
    """Bayesian fit of one part: deviations plus the study's error sources.

    Starts from the robust fit (``fit``, made if not given). With the Gaussian
    likelihood the robust fit's outliers are left out; the Student-t
    likelihood keeps every trigger (it is the robust Bayesian option).
    ``sampler``: the lockstep JAX sampler (default) or ``"emcee"``
    (`fit.fit_profile_bayes`).
    """
    from ..fit import fit_profile_bayes

    data = _part_data(study, probe, part)
    fit = fit_study(study, data, method="robust") if fit is None else fit
    use = data if study.fit.likelihood == "student_t" else inliers(fit, data)
    return fit_profile_bayes(
        study.profile,
        use.feature,
        use.points,
        start=fit.deviations,
        start_cov=fit.covariances,
        approach=use.approach,
        lines=use.lines,
        part=fit.part,
        options=bayes_options(study),
        sampling=sampler_options(
            study,
            nsteps=nsteps,
            n_ensembles=n_ensembles,
            seed=seed,
            progress=progress,
            on_fail=on_fail,
            sampler=sampler,
        ),
    )


def toolpath_uncertainty(
    study: Study,
    fit: ProfileFit,
    probe: ProbeData | None = None,
    *,
    bayes=None,
    part: str | None = None,
    gain=None,
):
    """Uncertainty of the adjusted tool path: linearised (GUM) from the fit, and
    Monte Carlo (JCGM 101) from the posterior when ``bayes`` is given.

    The linearised probe sigma and its degrees of freedom are the fit's
    (``ProfileFit.sigma``: declared and known, or pooled over the part's features
    with the declared repeatability as prior); intervals and bands use Student-t
    quantiles with Welch-Satterthwaite effective degrees of freedom.

    **Returns:** ``{"linearised": ToolpathUncertainty, "monte_carlo": ... or None}``.
    """
    lin = linearised_uncertainty(study, fit, probe, part=part, gain=gain)
    mc = None if bayes is None else monte_carlo_uncertainty(study, bayes, lin, gain=gain)
    return {"linearised": lin, "monte_carlo": mc}


def linearised_uncertainty(study: Study, fit: ProfileFit, probe=None, *, part=None, gain=None):
    """The linearised (GUM) half of [`toolpath_uncertainty`][]: from the robust fit
    alone (the main job computes it while the sampler runs)."""
    from ..fit.mcmc import prior_from_spec
    from ..uncertainty import LINEARISED_SOURCES, LinearisedOptions, linearised_toolpath

    data = inliers(fit, _part_data(study, probe, part or fit.part))
    gain = study.compensation.gain if gain is None else gain
    if fit.sigma is not None:  # the part's probe sigma rule (docs/uncertainty.md)
        sigma, dof = fit.sigma.value, fit.sigma.dof
    else:
        sigma, dof = study.probe.repeatability, float("inf")
    source_sd = {}
    for name, spec in study.sources.items():
        if name in LINEARISED_SOURCES:
            source_sd[name] = prior_from_spec(name, dict(spec), file=str(study.path)).sd
    radius = radius_components(study.probe.calibration)
    source_sd.update(calibration_sds(study))
    options = LinearisedOptions(
        ball_radius=study.probe.ball_radius,
        loss=_fit_loss(fit),
        transform=study.transform,
        source_sd=source_sd,
        gain=gain,
        radius=radius,
    )
    return linearised_toolpath(
        study.profile,
        data.feature,
        data.points,
        fit.deviations,
        options=options,
        sigma=sigma,
        dof=dof,
        approach=data.approach if "pretravel" in source_sd or radius else None,
    )


def monte_carlo_uncertainty(study: Study, bayes, linearised, *, gain=None):
    """The Monte Carlo (JCGM 101) half of [`toolpath_uncertainty`][]: the posterior's
    draws through the adjusted path, on the linearised result's grid."""
    from ..uncertainty import monte_carlo_toolpath

    gain = study.compensation.gain if gain is None else gain
    return monte_carlo_toolpath(
        study.profile, bayes.deviation_samples, gain=gain, grid=linearised.grid
    )


def _fit_loss(fit: ProfileFit) -> str:
    """The loss a profile fit minimised ("robust/huber", "joint/cauchy" -> the loss)."""
    method = next(iter(fit)).method
    loss = method.split("/")[-1] if "/" in method else "linear"
    return "linear" if loss in ("lsq", "linear") else loss


def adjust_study_program(
    study: Study,
    path: AdjustedPath,
    *,
    nose_radius=None,
    tool_table=None,
    created: str | None = None,
    output: str | None = None,
):
    """Rewrite the study's part program for the adjusted tool path (PIECS option 2).

    Finish-cut blocks are mapped to profile features by geometry (or by the
    study's ``[program] mapping``); only their coordinate words change, every
    other line stays byte-identical. Refuses (``AnalysisError``) a change above
    ``compensation.max_correction``, a block that cannot be mapped, or a
    result that gouges with the nose radius (``nose_radius`` mm, else the
    study's ``[program] nose_radius``, else the tool table's).

    The result starts with a comment block that traces it (`program_header`): the
    piecs_bayes version, the date (``created``, an ISO time; default now, UTC), the
    study file's and each probe file's name and SHA-256, and the gain per feature.
    The diff names the input ``a/<program path>`` and the output ``b/<output>``
    (default ``<program stem>_adjusted<suffix>``, the name it is written under).

    **Returns:** a ``ProgramAdjustment`` (``.text``, ``.diff``, ``.changes``).
    """
    from ..gcode import ToolPath, adjust_path_program, adjust_program, read_gcode, read_tool_table
    from ..geometry import profile_kind

    if study.program is None:
        raise InputError(
            "the study names no part program (study.part_program)", file=str(study.path)
        )
    ps = study.program_settings
    if ps.path_tip is not None:  # a tool path without G41/G42: moved as the nose runs
        return adjust_path_program(
            read_gcode(study.program, ps.dialect),
            study.profile,
            path.profile,
            tool_path=ToolPath(ps.nose_radius, ps.path_tip, profile_kind(study.profile)),
            max_correction_mm=study.compensation.max_correction,
            header=program_header(study, path.gain, created=created),
            output_name=output,
        )
    table = tool_table if tool_table is not None else ps.tool_table
    if table is not None and not hasattr(table, "get"):
        table = read_tool_table(table)
    return adjust_program(
        read_gcode(study.program, ps.dialect),
        study.profile,
        path.profile,
        max_correction_mm=study.compensation.max_correction,
        mapping=dict(ps.mapping) or None,
        tol_mm=ps.tolerance,
        tool_table=table,
        nose_radius_mm=nose_radius if nose_radius is not None else ps.nose_radius,
        header=program_header(study, path.gain, created=created),
        output_name=output,
    )


def program_header(study: Study, gain, *, created: str | None = None) -> tuple[str, ...]:
    """The comment texts that trace an adjusted program to its run: version, date
    (`created`, ISO; default now, UTC), the study and probe files with their SHA-256,
    and the gain per feature (`gain`: a number or a mapping by feature id)."""
    import datetime as _dt
    import hashlib

    from .. import __version__

    if created is None:
        created = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")

    def sha(f) -> str:
        try:
            return "sha256 " + hashlib.sha256(read_bytes(f, what="file")).hexdigest()
        except InputError:  # a study made in memory: say so rather than refuse the program
            return "not readable, no sha256"

    lines = [
        f"piecs_bayes {__version__} adjusted finish cut: only coordinate words changed",
        f"date {created}",
        f"study {Path(study.path).name} {sha(study.path)}",
    ]
    lines += [f"probe {Path(f).name} {sha(f)}" for f in study.probe_files]
    gains = [
        f"{fid} {float(gain.get(fid, 0.0) if hasattr(gain, 'get') else gain):g}"
        for fid in study.profile.ids
    ]
    row: list[str] = []
    for g in gains:  # a few per line: controllers limit a block's length
        if row and len(", ".join([*row, g])) > 60:
            lines.append("gains " + ", ".join(row))
            row = []
        row.append(g)
    lines.append("gains " + ", ".join(row))
    return tuple(lines)
