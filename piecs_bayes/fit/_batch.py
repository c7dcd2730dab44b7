r"""Batch fitting: every feature of many parts in one compiled call per feature kind.

[`fit_profiles`][] takes the probe points of many parts of one profile (part and feature
of each point, ball centres in the part frame, mm, radius X) and returns a
[`BatchFit`][]: every `(part, feature)` problem that shares a residual function and a
point-count bucket is one group, solved by one jitted `jax.vmap` in batches of a fixed
size (`BATCH`), so each group compiles once whatever the study size and chunking. Each
problem is set up exactly as [`fit_feature`][] sets it up, so the results agree with the
per-part loop to the solvers' precision (values to 1e-9 mm, standard errors to 1e-6
relative, the same outlier flags and statuses); the probe sigma is pooled per part.
Failures are reported, not hidden: [`BatchFit.failures`][], [`BatchFit.part_error`][].
Parts are processed in chunks of `chunk_size` (`CHUNK_PARTS`); the kept arrays are
~1 kB per problem.

Groups, buckets, memory: docs/models/batch_fits.md.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..geometry import Profile
from ._batch_result import BatchFit, Group, inlier_ss
from ._batch_solve import (
    Settings,
    batch_rows,
    dispatch,
    fetch,
    geometry_table,
    group_solver,
    retry_lm,
)
from ._features import padded_size
from ._options import BatchOptions, FitOptions


def fit_profiles(
    profile: Profile,
    part_ids,
    feature_ids,
    centres,
    *,
    ball_radius: float,
    options: FitOptions = FitOptions(),
    batch: BatchOptions = BatchOptions(),
    lines=None,
    file: str | None = None,
) -> BatchFit:
    """Fit each feature of `profile` on every part, batched (see the module docstring).

    **Arguments:**

    - `part_ids`, `feature_ids`: `(n,)` part and feature of each point; parts keep
      the order of their first point (production order).
    - `centres`: `(n, 2)` ball centres in the part frame (mm, radius X).
    - `ball_radius`, `lines`, `file`: as in [`fit_profile`][].
    - `options`: the [`FitOptions`][] of [`fit_profile`][], for every part (the
      probe sigma is pooled per part). Its `solver`: `"auto"` (default): the lean
      batch kernel (`_batch_kernel`: the same staged objective and result
      statistics, Newton steps in closed form), then the engine's
      Levenberg-Marquardt for any problem it did not solve, so a failure carries the
      engine's status and message (every bucket, 8 to 4,096 points per feature and
      more, cost linear in points); `"fast"`: the kernel alone; or an engine solver
      for every problem: `"lm"` (`fit_profile`'s: the loop's exact path),
      `"gauss_newton"`, `"dogleg"`. Under `vmap` a batch runs as many steps as its
      slowest problem, and the engine's robust stages make LM take ~125 steps per
      problem; the kernel takes ~12-20 and is 10-20x faster than `"lm"`, with the
      same minimum (~1e-10 mm, 1e-7 standard errors, on the batch data:
      `tests/fit/test_batch.py`). `rtol`, `atol`, `max_steps`: as in
      [`least_squares`][].
    - `batch`: the [`BatchOptions`][]: parts per compiled call (`chunk_size`),
      problems per compiled call (`batch_size`) and `progress`.

    **Returns:** a [`BatchFit`][]. Input errors (unknown feature, too few points)
    raise the same [`InputError`][piecs_bayes.errors.InputError] as the loop;
    a fit that does not converge is reported in `BatchFit.failures`.
    """
    sigma, declared, chunk_size = options.sigma, options.declared, batch.chunk_size
    fix, min_points = options.fix, options.min_points
    pts = _index_points(profile, part_ids, feature_ids, centres, lines, file)
    _validate(profile, pts.counts, fix, min_points, file)
    specs, pp, ff = _group_specs(profile, pts.counts, fix)
    # covariances at a reference sigma (known or declared: it sets the stationarity
    # test's scale), rescaled per part to its probe sigma
    ref = options.reference_sigma
    st = Settings(
        loss=options.solve_loss,
        solver=options.solver,
        rtol=options.rtol,
        atol=options.atol,
        max_steps=options.max_steps,
        ball_radius=jnp.asarray(float(ball_radius)),
        scale=jnp.asarray(np.nan if options.scale is None else float(options.scale)),
        sigma=jnp.asarray(ref),
    )
    chunk_of = pp // chunk_size
    n_chunks = int(math.ceil(len(pts.parts) / chunk_size))
    data = (pp, ff, pts.counts, pts.starts, pts.order, pts.centres, geometry_table(profile))
    progress = _Progress(batch.progress, pts.parts, chunk_size)
    results = _solve_chunks(specs, chunk_of, n_chunks, data, st, int(batch.batch_size), progress)
    groups = _collect_groups(specs, results, chunk_of, n_chunks, pp, ff, pts)
    ss, dof = _pooled(groups, len(pts.parts))
    return BatchFit(
        profile=profile,
        parts=pts.parts,
        pooled_ss=ss,
        pooled_dof=dof,
        sigma_rule=(
            declared if sigma is None else float(sigma),
            options.declared_dof,
            sigma is not None,
        ),  # fmt: skip
        reference_sigma=ref,
        method="lsq" if options.method == "lsq" else f"robust/{options.loss}",
        loss=st.loss,
        fix=fix,
        groups=tuple(groups),
        centres=pts.centres,
        lines=pts.lines,
        order=pts.order,
        ball_radius=float(ball_radius),
        file=file,
    )


class _Points(NamedTuple):
    """The study's points indexed by (part, feature): `counts[p, f]` points each,
    starting at `starts[p, f]` in the point order `order` (grouped by part and
    feature, file order within). `parts` in order of first appearance."""

    centres: np.ndarray
    lines: np.ndarray
    parts: tuple[str, ...]
    counts: np.ndarray
    starts: np.ndarray
    order: np.ndarray


def _index_points(profile, part_ids, feature_ids, centres, lines, file) -> _Points:
    """Check the point arrays and index them by (part, feature)."""
    centres = np.asarray(centres, dtype=float)
    feature_ids = np.asarray(feature_ids).astype(str)
    n_pts = len(centres)
    if centres.shape != (n_pts, 2) or len(feature_ids) != n_pts or len(part_ids) != n_pts:
        raise InputError(
            f"centres must be (n, 2) with one part id and feature id per point; got "
            f"{centres.shape}, {len(part_ids)} part ids, {len(feature_ids)} feature ids"
        )
    lines = np.arange(1, n_pts + 1) if lines is None else np.asarray(lines)
    parts, part_idx = _first_appearance(np.asarray(part_ids).astype(str))
    f_index = {fid: i for i, fid in enumerate(profile.ids)}
    unknown = [fid for fid in dict.fromkeys(feature_ids.tolist()) if fid not in f_index]
    if unknown:
        fid = unknown[0]
        raise InputError(
            f"unknown feature id {fid!r}; the profile has {', '.join(profile.ids)}",
            file=file,
            line=int(lines[np.flatnonzero(feature_ids == fid)[0]]),
            column="feature",
            feature=fid,
        )
    uniq, inv = np.unique(feature_ids, return_inverse=True)
    feat_idx = np.array([f_index[f] for f in uniq.tolist()], dtype=int)[inv.reshape(-1)]
    n_parts, n_feat = len(parts), len(profile.features)
    key = part_idx * n_feat + feat_idx
    counts = np.bincount(key, minlength=n_parts * n_feat).reshape(n_parts, n_feat)
    order = np.argsort(key, kind="stable")  # points grouped by (part, feature), file order
    starts = np.zeros(n_parts * n_feat, dtype=int)
    starts[1:] = np.cumsum(counts.ravel())[:-1]
    return _Points(centres, lines, parts, counts, starts.reshape(n_parts, n_feat), order)


def _first_appearance(values: np.ndarray) -> tuple[tuple[str, ...], np.ndarray]:
    """Unique values in order of first appearance, and each element's index."""
    uniq, first, inv = np.unique(values, return_index=True, return_inverse=True)
    rank = np.empty(len(uniq), dtype=int)
    rank[np.argsort(first, kind="stable")] = np.arange(len(uniq))
    ordered = uniq[np.argsort(first, kind="stable")]
    return tuple(str(v) for v in ordered.tolist()), rank[inv]


def _validate(profile, counts, fix, min_points, file):
    """The checks of `fit_profile` / `fit_feature`, raising the same `InputError`
    for the first offending part (production order) and feature (profile order)."""
    for fid, names in fix.items():
        if fid not in profile.ids:
            continue
        f = profile[fid]
        for name in names:
            if name not in f.param_names:
                raise InputError(
                    f"cannot fix {name!r}: parameters are {', '.join(f.param_names)}",
                    feature=f.id,
                    value=name,
                )
    kinds = [f.kind for f in profile.features]
    need = np.array([min_points[k] for k in kinds])
    nfree = np.array(
        [sum(n not in fix.get(f.id, ()) for n in f.param_names) for f in profile.features]
    )
    bad = (counts > 0) & ((counts < need) | (counts <= nfree))
    if bad.any():
        p, j = np.argwhere(bad)[0]
        f, k = profile.features[j], int(counts[p, j])
        if k < need[j]:
            raise InputError(
                f"{k} point(s) are too few for a {f.kind}: at least {need[j]} are needed",
                file=file,
                feature=f.id,
                value=k,
            )
        raise InputError(
            f"{k} points are too few to fit {nfree[j]} parameters with an uncertainty "
            f"(need at least {nfree[j] + 1})",
            feature=f.id,
            value=k,
        )
    empty = np.flatnonzero(counts.sum(axis=1) == 0)
    if empty.size:
        raise InputError("no probe point belongs to any profile feature", file=file)


class _Spec(NamedTuple):
    """One group: its residual function (`kind`, `free`), its bucket `n_pad`, and
    its problems `ks` (indices into the measured (part, feature) pairs `pp`, `ff`,
    in (part, feature) order)."""

    kind: str
    free: tuple[int, ...]
    n_pad: int
    ks: np.ndarray


def _group_specs(profile, counts, fix) -> tuple[list[_Spec], np.ndarray, np.ndarray]:
    """The groups (kind, free parameters, bucket) of the measured (part, feature)
    pairs `pp`, `ff` (the nonzero `counts`)."""
    free_of = [
        tuple(i for i, n in enumerate(f.param_names) if n not in fix.get(f.id, ()))
        for f in profile.features
    ]
    pp, ff = np.nonzero(counts)
    buckets = np.array([padded_size(c) for c in counts[pp, ff]])
    gkeys = {}
    for k, (j, b) in enumerate(zip(ff.tolist(), buckets.tolist(), strict=True)):
        gkeys.setdefault((profile.features[j].kind, free_of[j], b), []).append(k)
    return [_Spec(*key, np.asarray(ks)) for key, ks in gkeys.items()], pp, ff


class _Progress:
    """`fit_profiles`' `progress`, called with the parts done after each chunk: a
    tqdm bar (`True`), a callable `progress(done, total, part)`, or nothing."""

    def __init__(self, progress, parts: tuple[str, ...], chunk_size: int):
        self.parts, self.chunk_size = parts, chunk_size
        self.bar = None
        if progress is True:
            from tqdm.auto import tqdm

            self.bar = tqdm(total=len(parts), desc="batch fit", unit="part")
        self.callback = progress if callable(progress) else None

    def chunk_done(self, c: int) -> None:
        n_parts = len(self.parts)
        done = min(n_parts, (c + 1) * self.chunk_size)
        if self.bar is not None:
            self.bar.update(done - self.bar.n)
        if self.callback is not None:
            self.callback(done, n_parts, self.parts[done - 1])

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


def _solve_chunks(specs, chunk_of, n_chunks, data, st: Settings, bsize: int, progress):
    """Every group's problems solved chunk by chunk of parts, in batches of `bsize`:
    per group, field name -> the chunks' result arrays."""
    results = [dict() for _ in specs]
    for c in range(n_chunks):
        pending = []
        for g_i, spec in enumerate(specs):
            sel = spec.ks[chunk_of[spec.ks] == c]
            if sel.size == 0:
                continue
            solve = group_solver(st, spec.kind, spec.free, spec.n_pad)
            g_data = (*data, spec.n_pad)
            g_bsize = batch_rows(bsize, spec.n_pad)
            for lo in range(0, sel.size, g_bsize):
                rows = sel[lo : lo + g_bsize]
                # dispatched now (asynchronous: XLA computes while Python prepares the
                # next batch), fetched after the chunk. Not from several threads: two
                # concurrent executions on XLA's CPU pool were seen to deadlock.
                pending.append((g_i, rows, g_data, dispatch(solve, rows, g_data, g_bsize, st)))
        for g_i, rows, g_data, dev in pending:
            out = fetch(dev, rows.size)
            spec = specs[g_i]
            if st.solver == "auto":
                retry_lm(out, rows, g_data, spec.kind, spec.free, st)
            for name, a in out.items():
                results[g_i].setdefault(name, []).append(a)
        progress.chunk_done(c)
    progress.close()
    return results


def _collect_groups(specs, results, chunk_of, n_chunks, pp, ff, pts: _Points) -> list[Group]:
    """The solved groups, their arrays in the order they were solved."""
    groups = []
    for spec, res in zip(specs, results, strict=True):
        ks = spec.ks
        # the problems were solved chunk by chunk in (part, feature) order
        order_ks = np.concatenate([ks[chunk_of[ks] == c] for c in range(n_chunks)])
        arrays = {name: np.concatenate(v) for name, v in res.items()}
        groups.append(
            Group(
                kind=spec.kind,
                free=spec.free,
                n_pad=spec.n_pad,
                part=pp[order_ks],
                feature=ff[order_ks],
                count=pts.counts[pp[order_ks], ff[order_ks]],
                start=pts.starts[pp[order_ks], ff[order_ks]],
                arrays=arrays,
            )
        )
    return groups


def _pooled(groups, n_parts: int) -> tuple[np.ndarray, np.ndarray]:
    """Per part: residual sum of squares and dof of its inliers, over its features."""
    ss, dof = np.zeros(n_parts), np.zeros(n_parts, dtype=int)
    for g in groups:
        g_ss, g_dof = inlier_ss(g)
        np.add.at(ss, g.part, g_ss)
        np.add.at(dof, g.part, g_dof)
    return ss, dof
