r"""Capability studies over many parts: batch fits in chunks, in-process or on Dask.

[`capability_study`][piecs_bayes.jobs.capability_study] needs, per part and feature, the
characteristic (normal deviation at a nominal point) and its linearised uncertainty.
[`capability_values`][] computes them chunk by chunk: [`fit_study_batch`][] fits a chunk
with [`fit_profiles`][piecs_bayes.fit.fit_profiles] (parts whose fit fails are refitted
by plain least squares, parts that fail both are left out, with the loop's notes), and
`uncertainty.characteristic_arrays` evaluates every part of a feature at once.
[`path_uncertainty_batch`][] propagates every part's fit covariance to its adjusted
tool path. Without a scheduler the chunks run in this process; with `scheduler=`
(`"tcp://host:8786"` or a `distributed.Client`) each chunk is a task on an existing Dask
cluster, with identical results (bit for bit on the same CPU type). Joint fits
(`fit.free_transform`) are not batched: `capability_study` keeps its per-part loop.

The chunks, the workers and why identical: docs/models/batch_fits.md.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Callable, Mapping
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..fit import (
    CHUNK_PARTS,
    DECLARED_DOF,
    BatchOptions,
    FitOptions,
    fit_profiles,
    to_part_frame,
)
from ..geometry import MachineTransform, Profile
from ..io import parse_fix
from ..uncertainty import characteristic_arrays, path_grid, path_jacobian_function
from ._options import fit_options, robust_scale


@dataclass(frozen=True)
class CapabilityJob:
    """What a worker needs to fit and characterise parts (picklable, unlike `Study`)."""

    profile: Profile
    transform: MachineTransform
    ball_radius: float
    method: str
    loss: str
    scale: float
    sigma: float | None
    fix: tuple
    min_points: tuple
    at: str
    sources: tuple
    file: str | None = None
    declared: float | None = None
    declared_dof: float = DECLARED_DOF


def capability_job(study, *, method: str, at: str, sources: Mapping[str, float], file=None):
    """The [`CapabilityJob`][] of a study (the settings `fit_study` would use)."""
    return CapabilityJob(
        profile=study.profile,
        transform=study.transform,
        ball_radius=float(study.probe.ball_radius),
        method=method,
        loss=study.fit.loss,
        scale=float(robust_scale(study)),
        sigma=float(study.probe.repeatability) if study.fit.known_sigma else None,
        declared=float(study.probe.repeatability),
        declared_dof=float(study.probe.repeatability_dof),
        fix=tuple(sorted(parse_fix(study.fit.fix).items())),
        min_points=(("line", study.fit.min_points_line), ("arc", study.fit.min_points_arc)),
        at=at,
        sources=tuple(sorted((k, float(v)) for k, v in sources.items())),
        file=file,
    )


def _fit_job(job: CapabilityJob, part_ids, feature_ids, machine_points, lines, method):
    options = FitOptions(
        method=method,
        loss=job.loss,
        scale=job.scale,
        sigma=job.sigma,
        declared=job.declared,
        declared_dof=job.declared_dof,
        fix=dict(job.fix),
        min_points=dict(job.min_points),
    )
    return fit_profiles(
        job.profile,
        part_ids,
        feature_ids,
        to_part_frame(job.transform, machine_points),
        ball_radius=job.ball_radius,
        options=options,
        batch=BatchOptions(chunk_size=max(1, len(set(np.asarray(part_ids).tolist())))),
        lines=lines,
        file=job.file,
    )


def fit_study_batch(
    study, probe=None, *, method: str | None = None, progress=False, chunk_size=None
):
    """Fit every part of a study in batches: the batch form of
    `[fit_study(study, probe.for_part(p)) for p in probe.parts]` (not for joint fits).

    `method`: `"lsq"` or `"robust"` (default the study's; `"bayes"` means robust).
    Returns a [`BatchFit`][piecs_bayes.fit.BatchFit].
    """
    from ._fit import load_probe_data

    if study.fit.free_transform:
        raise InputError(
            "batch fits do not cover joint fits (fit.free_transform); use fit_study per part"
        )
    probe = load_probe_data(study) if probe is None else probe
    method = method or study.fit.method
    method = "robust" if method == "bayes" else method
    return fit_profiles(
        study.profile,
        probe.part,
        probe.feature,
        to_part_frame(study.transform, probe.points),
        ball_radius=study.probe.ball_radius,
        options=fit_options(study, method),
        batch=BatchOptions(chunk_size=chunk_size or CHUNK_PARTS, progress=progress),
        lines=probe.lines,
        file=probe.file,
    )


@dataclass(frozen=True)
class ChunkValues:
    """Per-part results of one chunk: characteristic value, fit uncertainty and
    systematic uncertainty by feature (`NaN`: left out), and the notes, in part order."""

    parts: tuple[str, ...]
    values: dict
    u: dict
    u_systematic: dict
    notes: tuple[tuple[int, str], ...]


#: one chunk at a time per process: two concurrent XLA executions on the CPU
#: client's small thread pool were seen to deadlock (a Dask worker with several
#: threads would run chunks concurrently); parallelism comes from worker processes
_XLA_LOCK = threading.Lock()


def _chunk_values(job: CapabilityJob, part_ids, feature_ids, machine_points, lines):
    """Fit and characterise one chunk of parts (runs in a worker or in process)."""
    with _XLA_LOCK:
        return _chunk_values_locked(job, part_ids, feature_ids, machine_points, lines)


def _chunk_values_locked(job, part_ids, feature_ids, machine_points, lines):
    first = _fit_job(job, part_ids, feature_ids, machine_points, lines, job.method)
    parts = first.parts
    notes: list[tuple[int, str]] = []
    fits = {i: first for i in range(len(parts))}
    bad = np.flatnonzero(~first.ok)
    if bad.size:
        if job.method == "lsq":
            for i in bad:
                notes.append((int(i), f"{parts[i]}: left out, the fit failed: "
                              f"{first.part_error(int(i))}"))  # fmt: skip
                fits.pop(int(i))
        else:
            keep = np.isin(np.asarray(part_ids).astype(str), [parts[i] for i in bad])
            second = _fit_job(
                job,
                np.asarray(part_ids)[keep],
                np.asarray(feature_ids)[keep],
                np.asarray(machine_points)[keep],
                np.asarray(lines)[keep],
                "lsq",
            )
            for i in bad:
                j = second.parts.index(parts[i])
                e = first.part_error(int(i))
                if second.ok[j]:
                    notes.append((int(i), f"{parts[i]}: {job.method} fit failed ({e}); "
                                  "fitted with plain least squares"))  # fmt: skip
                    fits[int(i)] = (second, j)
                else:
                    notes.append((int(i), f"{parts[i]}: left out, the fit failed: "
                                  f"{second.part_error(j)}"))  # fmt: skip
                    fits.pop(int(i))
    sources = dict(job.sources)
    out_v, out_u, out_s = {}, {}, {}
    for fid in job.profile.ids:
        v = np.full(len(parts), np.nan)
        u = np.full(len(parts), np.nan)
        s = np.full(len(parts), np.nan)
        for batch, rows_of in _by_batch(fits, first):
            if fid not in batch.feature_ids:
                continue
            mean, u_fit, u_sys, _ = characteristic_arrays(batch, fid, at=job.at, sources=sources)
            for i, j in rows_of:
                v[i], u[i], s[i] = mean[j], u_fit[j], u_sys[j]
        nocov = np.isfinite(v) & ~np.isfinite(u)
        for i in np.flatnonzero(nocov):
            notes.append((int(i), f"{parts[i]}: {fid} left out: feature {fid!r}: the fit has no "
                          "covariance (too few points or a singular fit); no uncertainty, "
                          "no decision"))  # fmt: skip
            v[i] = np.nan
        out_v[fid], out_u[fid], out_s[fid] = v, u, s
    notes.sort(key=lambda t: t[0])  # stable: per part, fit notes before feature notes
    return ChunkValues(parts, out_v, out_u, out_s, tuple(notes))


def _by_batch(fits: dict, first):
    """Group `{part index: batch or (batch, row)}` into `(batch, [(i, row)])`."""
    groups: dict[int, tuple] = {}
    for i, b in fits.items():
        batch, j = (b, i) if b is first else b
        groups.setdefault(id(batch), (batch, []))[1].append((i, j))
    return list(groups.values())


def _chunks(probe, chunk_parts: int):
    """Row masks of `probe` by chunks of consecutive parts (production order)."""
    parts = probe.parts
    index = {p: i for i, p in enumerate(parts)}
    pidx = np.fromiter((index[p] for p in probe.part.tolist()), dtype=int, count=len(probe))
    chunk = pidx // chunk_parts
    order = np.argsort(chunk, kind="stable")
    bounds = np.searchsorted(chunk[order], np.arange(math.ceil(len(parts) / chunk_parts) + 1))
    for a, b in zip(bounds[:-1], bounds[1:], strict=True):
        yield order[a:b]


def capability_values(
    study,
    probe,
    *,
    method: str,
    at: str,
    sources: Mapping[str, float],
    progress: Callable[[int, int, str], None] | None = None,
    scheduler=None,
    chunk_parts: int = CHUNK_PARTS,
):
    """Per-part characteristics of every feature, in chunks, in-process or on Dask.

    **Arguments:**

    - `method`: `"lsq"` or `"robust"`; `at`, `sources`: as in
      `uncertainty.feature_characteristic`.
    - `progress`: `progress(done, total, last_part)` after each chunk.
    - `scheduler`: `None` (in-process), a scheduler address (`"tcp://host:8786"`) or a
      `distributed.Client`.
    - `chunk_parts`: parts per chunk (per task on a cluster).

    **Returns:** `(values, u, part_ids, u_systematic, notes)` as `capability_study`
    collects them: dicts by feature id of lists over the included parts, the
    systematic uncertainty by feature, and the notes in part order.
    """
    if chunk_parts < 1:
        raise InputError(f"chunk_parts must be >= 1, got {chunk_parts!r}", value=chunk_parts)
    job = capability_job(study, method=method, at=at, sources=sources, file=probe.file)
    chunks = list(_chunks(probe, chunk_parts))
    total = len(probe.parts)

    def args(rows):
        return (probe.part[rows], probe.feature[rows], probe.points[rows], probe.lines[rows])

    results: list[ChunkValues | None] = [None] * len(chunks)
    done = 0
    if scheduler is None:
        for k, rows in enumerate(chunks):
            results[k] = _chunk_values(job, *args(rows))
            done += len(results[k].parts)
            if progress is not None:
                progress(done, total, results[k].parts[-1])
    else:
        results = _run_dask(scheduler, job, [args(r) for r in chunks], progress, total)
    return _merge(job, results)


def _run_dask(scheduler, job, chunk_args, progress, total):
    try:
        from distributed import Client, as_completed
    except ImportError as exc:  # the optional extra `dask`: say how to install it
        raise InputError(
            "--scheduler needs Dask's distributed package, an optional extra: "
            'pip install "piecs_bayes[dask]"'
        ) from exc
    own = not isinstance(scheduler, Client)
    client = Client(scheduler) if own else scheduler
    try:
        futures = [client.submit(_chunk_values, job, *a, pure=False) for a in chunk_args]
        index = {f.key: k for k, f in enumerate(futures)}
        results: list = [None] * len(futures)
        done = 0
        for fut in as_completed(futures):
            res = fut.result()
            results[index[fut.key]] = res
            done += len(res.parts)
            if progress is not None:
                progress(done, total, res.parts[-1])
        return results
    finally:
        if own:
            client.close()


def _merge(job, results):
    values: dict[str, list] = {}
    us: dict[str, list] = {}
    pids: dict[str, list] = {}
    usys: dict[str, float] = {}
    notes: list[str] = []
    for res in results:
        notes += [n for _, n in res.notes]
        for fid in job.profile.ids:
            v, u, s = res.values[fid], res.u[fid], res.u_systematic[fid]
            for i in np.flatnonzero(np.isfinite(v)):
                values.setdefault(fid, []).append(float(v[i]))
                us.setdefault(fid, []).append(float(u[i]))
                pids.setdefault(fid, []).append(res.parts[i])
                usys[fid] = float(s[i])
    return values, us, pids, usys, notes


@dataclass(frozen=True)
class PathUncertaintyBatch:
    """Linearised uncertainty of the adjusted tool path of every part of a batch.

    From each part's fit covariance (probe repeatability and the fit; the study's
    systematic sources are not in it: see `jobs.toolpath_uncertainty` for one
    part with them): `vertices` `(P, n+1, 2)` and `vertex_sd` (x and z standard
    uncertainties), `offset` / `offset_sd` `(P, m)` the normal offset of the
    adjusted path from nominal at the grid points (`grid`) and its standard
    uncertainty. `NaN` for parts whose fit has no covariance.
    """

    parts: tuple[str, ...]
    grid: object
    vertices: np.ndarray
    vertex_sd: np.ndarray
    offset: np.ndarray
    offset_sd: np.ndarray


def path_uncertainty_batch(batch, *, gain=1.0, per_feature: int = 21, chunk: int = 2048):
    """[`PathUncertaintyBatch`][] of a [`BatchFit`][piecs_bayes.fit.BatchFit]: the
    GUM propagation $u^2(y_i) = \\sum_{jk} J_{ij} C_{jk} J_{ik}$ of each part's
    block-diagonal deviation covariance $C$ through the Jacobian $J$ of the adjusted
    path (mirroring with `gain`, re-intersection), one compiled `vmap` over parts.
    Unmeasured features count as drawn (deviation 0, no uncertainty)."""
    profile = batch.profile
    grid = path_grid(profile, per_feature)
    fn = path_jacobian_function(profile, grid, gain, batched=True)
    devs, covs = [], []
    for f in profile.features:
        if f.id in batch.feature_ids:
            v, c = batch.values(f.id), batch.covariance(f.id)
            unmeasured = batch.status(f.id) < 0
            v = np.where(unmeasured[:, None], 0.0, v)
            c = np.where(unmeasured[:, None, None], 0.0, c)
        else:
            v = np.zeros((len(batch), f.nparams))
            c = np.zeros((len(batch), f.nparams, f.nparams))
        devs.append(v)
        covs.append(c)
    dev = np.concatenate(devs, axis=1)
    n_v = 2 * (len(profile) + 1)
    ys, sds = [], []
    for lo in range(0, len(batch), chunk):
        d = dev[lo : lo + chunk]
        pad = chunk - len(d) if len(batch) > chunk else 0  # one shape for every chunk
        y, jac = map(np.asarray, fn(jnp.asarray(np.pad(d, ((0, pad), (0, 0))))))
        y, jac = y[: len(d)], jac[: len(d)]
        var = np.zeros(y.shape)
        k = 0
        for c in covs:  # block-diagonal C: one feature block at a time
            w = c.shape[-1]
            jb = jac[:, :, k : k + w]
            var += np.einsum("pij,pjk,pik->pi", jb, c[lo : lo + chunk], jb)
            k += w
        ys.append(y)
        sds.append(np.sqrt(np.where(var >= 0, var, np.nan)))
    y, sd = np.concatenate(ys), np.concatenate(sds)
    return PathUncertaintyBatch(
        parts=batch.parts,
        grid=grid,
        vertices=y[:, :n_v].reshape(len(batch), -1, 2),
        vertex_sd=sd[:, :n_v].reshape(len(batch), -1, 2),
        offset=y[:, n_v:],
        offset_sd=sd[:, n_v:],
    )
