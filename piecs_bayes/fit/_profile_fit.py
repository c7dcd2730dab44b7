"""Fit every feature of a profile from one part's probe points."""

from __future__ import annotations

import dataclasses
import functools
import math

import numpy as np

from ..errors import InputError
from ..geometry import Profile
from ._features import _check_point_count, _free_parameters, fit_feature, padded_size
from ._lsq_types import Status
from ._profile_result import ProfileFit
from ._sigma import DECLARED_DOF, pooled_residuals, probe_sigma

__all__ = ["ProfileFit", "fit_profile"]


def fit_profile(
    profile: Profile,
    feature_ids,
    centres,
    *,
    ball_radius: float,
    method: str = "lsq",
    loss: str = "huber",
    scale: float | None = None,
    sigma: float | None = None,
    declared: float | None = None,
    declared_dof: float = DECLARED_DOF,
    fix: dict | None = None,
    lines=None,
    min_points: dict | None = None,
    file: str | None = None,
    part: str | None = None,
    solver: str = "lm",
) -> ProfileFit:
    """Fit each feature of ``profile`` to its points.

    **Arguments:**

    - `feature_ids`: ``(n,)`` feature id of each point.
    - `centres`: ``(n, 2)`` ball centres in the part frame (mm, radius X).
    - `sigma`: the probe sigma, known (every covariance scaled by it, $\\nu = \\infty$).
    - `declared`, `declared_dof`: with `sigma=None` (the default), the covariances
      are scaled by the residual sd **pooled over every feature** of the part,
      combined with the declared repeatability as a prior worth `declared_dof`
      degrees of freedom (`piecs_bayes.fit._sigma`); never by one feature's own
      residuals, which say little with few points.
    - `fix`: ``{feature_id: (param, ...)}`` parameters held at nominal.
    - `min_points`: ``{"line": 3, "arc": 4}``; fewer (but some) points is an error.
    - `file`, `lines`: where the points came from, for messages and reports.
    - `solver`: ``"lm"`` (the default, the reference): each feature by
      `least_squares` (the engine's Levenberg-Marquardt), one solve per feature;
      ``"auto"``: the batch path's kernel (`fit_profiles(solver="auto")`: the same
      objective, statistics and LM retries), every feature of the part in one
      compiled call whose trace is kept across processes (`_config.persisted`);
      the same results to the solvers' precision, ~10x faster. With neither
      `sigma` nor `declared`, ``"auto"`` is ``"lm"`` (its two passes).

    **Returns:** a :class:`ProfileFit`; features with no points are listed as
    unmeasured (they are left as drawn by compensation).
    """
    if solver not in ("lm", "auto"):
        raise InputError(f"unknown solver {solver!r}; expected 'lm' or 'auto'")
    feature_ids = np.asarray(feature_ids).astype(str)
    centres = np.asarray(centres, dtype=float)
    lines = np.arange(1, len(centres) + 1) if lines is None else np.asarray(lines)
    min_points = {"line": 3, "arc": 4, **(min_points or {})}
    fix = fix or {}
    unknown = sorted(set(feature_ids.tolist()).difference(profile.ids))
    if unknown:
        fid = unknown[0]
        first = int(lines[np.flatnonzero(feature_ids == fid)[0]])
        raise InputError(
            f"unknown feature id {fid!r}; the profile has {', '.join(profile.ids)}",
            file=file,
            line=first,
            column="feature",
            feature=fid,
        )
    # the reference sigma of the solves: the known or declared one (it also sets the
    # scale of the stationarity test, so it should be realistic); with neither, a first
    # pass at 1 mm gives the pooled residual sd and the solves are repeated at it
    ref = float(sigma if sigma is not None else (declared if declared is not None else 1.0))
    if solver == "auto" and (sigma is not None or declared is not None):
        kw = dict(ball_radius=ball_radius, method=method, loss=loss, scale=scale, sigma=sigma,
                  declared=declared, declared_dof=declared_dof)  # fmt: skip
        return _fit_part(profile, feature_ids, centres, lines, fix, min_points, file, part, ref, kw)
    kw = dict(ball_radius=ball_radius, method=method, loss=loss, scale=scale)
    fits, unmeasured = _fit_features(profile, feature_ids, centres, lines, fix, min_points,
                                     file, ref, kw)  # fmt: skip
    if sigma is None and declared is None and fits:
        ss, dof = pooled_residuals(fits.values())
        if dof > 0 and ss > 0:
            ref = float(np.sqrt(ss / dof))
            fits, _ = _fit_features(profile, feature_ids, centres, lines, fix, min_points,
                                    file, ref, kw)  # fmt: skip
    if not fits:
        raise InputError("no probe point belongs to any profile feature", file=file)
    ss, dof = pooled_residuals(fits.values())
    try:
        ps = probe_sigma(
            ss, dof, declared=declared if sigma is None else sigma,
            declared_dof=declared_dof, known=sigma is not None,
            what=f"part {part!r}" if part is not None else "part",
        )  # fmt: skip
    except InputError as exc:
        raise InputError(str(exc), file=file) from None
    return ProfileFit(
        profile, scale_fits(fits, ps.value / ref), method, tuple(unmeasured), part, sigma=ps
    )


def _fit_features(profile, feature_ids, centres, lines, fix, min_points, file, ref, kw):
    """Every measured feature fitted with covariances at the reference sigma `ref`."""
    fits, unmeasured = {}, []
    for f in profile.features:
        m = feature_ids == f.id
        k = int(m.sum())
        if k == 0:
            unmeasured.append(f.id)
            continue
        need = min_points[f.kind]
        if k < need:
            raise InputError(
                f"{k} point(s) are too few for a {f.kind}: at least {need} are needed",
                file=file,
                feature=f.id,
                value=k,
            )
        fits[f.id] = fit_feature(
            f, centres[m], sigma=ref, fix=tuple(fix.get(f.id, ())), lines=lines[m], **kw
        )
    return fits, unmeasured


def scale_fits(fits: dict, factor: float) -> dict:
    """Feature fits with their covariances multiplied by `factor`**2 (the part's probe
    sigma over the sigma the solves used)."""
    out = {}
    for fid, f in fits.items():
        cov = None if f.covariance is None else np.asarray(f.covariance) * factor**2
        se = None if cov is None else np.sqrt(np.diag(cov))
        out[fid] = dataclasses.replace(f, covariance=cov, std_errors=se)
    return out


# ------------------------------------------------------------------ solver="auto"
#: problems per compiled call of a group (residual function, point bucket) of one
#: part: a part with more features of a group pads to the next multiple
PART_BATCH = 1
#: a part's point buckets of one model (kind, free parameters) merge into the next
#: larger bucket when that adds at most this many padded points (problems x extra
#: padding): on the CPU a compiled group costs ~0.1 ms however small, a padded point
#: ~2 us (the demo part: lines of 8 and 16 points become one group, 0.1 ms less)
MERGE_POINTS = 64
#: `fit_profiles`' tolerances (those of `least_squares`, which the loop uses)
_TOLERANCES = (1e-10, 1e-12, 1000)


def _fit_part(profile, feature_ids, centres, lines, fix, min_points, file, part, ref, kw):
    """`fit_profile(solver="auto")`: the batch kernel, every feature in one compiled call.

    The loop's checks and messages; then each group (kind, free parameters, point
    bucket) padded to a multiple of `PART_BATCH` problems as `fit_profiles` pads
    them, solved in one call with the measured surface points, one transfer; the
    arrays become a one-part `BatchFit` whose `profile_fit` is the result. The
    program depends only on the groups' shapes (the geometry is data), so parts and
    profiles of the same shapes share it. A
    problem the kernel does not solve sends the part to `fit_profiles` itself (its
    LM retries, the engine's status and message).
    """
    from ._batch_result import BatchFit, Group, inlier_ss

    method, loss, sigma, declared = kw["method"], kw["loss"], kw["sigma"], kw["declared"]
    if method not in ("lsq", "robust"):
        raise ValueError(f"unknown method {method!r}; expected 'lsq' or 'robust'")
    f_index = {f.id: j for j, f in enumerate(profile.features)}
    feat = np.array([f_index[f] for f in feature_ids.tolist()], dtype=int)
    counts = np.bincount(feat, minlength=len(f_index))
    specs: dict[tuple, list[int]] = {}
    for j, f in enumerate(profile.features):
        if counts[j] == 0:
            continue
        if counts[j] < min_points[f.kind]:
            raise InputError(
                f"{counts[j]} point(s) are too few for a {f.kind}: at least "
                f"{min_points[f.kind]} are needed", file=file, feature=f.id, value=int(counts[j]),
            )  # fmt: skip
        free = tuple(_free_parameters(f, tuple(fix.get(f.id, ()))))
        _check_point_count(f, int(counts[j]), len(free))
        specs.setdefault((f.kind, free, padded_size(counts[j])), []).append(j)
    if not specs:
        raise InputError("no probe point belongs to any profile feature", file=file)
    specs = _merge_buckets(specs)
    order = np.argsort(feat, kind="stable")  # points by feature, file order within
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    loss_name = "linear" if method == "lsq" else loss
    takes = [js + [js[0]] * (PART_BATCH * -(-len(js) // PART_BATCH) - len(js))
             for js in specs.values()]  # fmt: skip
    sig = (loss_name, *_TOLERANCES,
           tuple((*key, len(t)) for key, t in zip(specs, takes, strict=True)))  # fmt: skip
    args = _part_arguments(profile, centres, order, counts, starts, specs, takes)
    scale = np.nan if kw["scale"] is None else kw["scale"]
    scalars = [np.asarray(float(v)) for v in (kw["ball_radius"], scale, ref)]
    run, meta = _part_solver(_table_key(profile), sig)
    arrays, surfaces = _unpack(np.asarray(run(args, *scalars)), meta["layout"], specs)
    if any(np.any(a["status_code"] != int(Status.SUCCESSFUL)) for a in arrays):
        return _fit_part_batch(profile, feature_ids, centres, lines, fix, min_points, file, part,
                               kw)  # fmt: skip
    groups = [
        Group(
            kind=kind,
            free=free,
            n_pad=n_pad,
            part=np.zeros(len(js), dtype=int),
            feature=np.asarray(js),
            count=counts[js],
            start=starts[js],
            arrays=a,
        )  # fmt: skip
        for ((kind, free, n_pad), js), a in zip(specs.items(), arrays, strict=True)
    ]
    ss_dof = [inlier_ss(g) for g in groups]
    batch = BatchFit(
        profile=profile, parts=("" if part is None else str(part),),
        method="lsq" if method == "lsq" else f"robust/{loss}", loss=loss_name,
        fix={k: tuple(v) for k, v in fix.items()}, groups=tuple(groups), centres=centres,
        lines=lines, order=order, ball_radius=float(kw["ball_radius"]), file=file,
        pooled_ss=np.array([sum(float(np.sum(s)) for s, _ in ss_dof)]),
        pooled_dof=np.array([sum(int(np.sum(d)) for _, d in ss_dof)]),
        sigma_rule=(declared if sigma is None else float(sigma), kw["declared_dof"],
                    sigma is not None),
        reference_sigma=ref, surfaces={(0, j): pair for j, pair in surfaces.items()},
    )  # fmt: skip
    fit = batch.profile_fit(0, throw=True)
    return fit if part is not None else dataclasses.replace(fit, part=None)


def _merge_buckets(specs: dict[tuple, list[int]]) -> dict[tuple, list[int]]:
    """`(kind, free, n_pad) -> feature indices` with each model's buckets merged
    upwards while a merge adds at most `MERGE_POINTS` padded points; groups in the
    order of their first feature, features in profile order."""
    by_model: dict[tuple, list] = {}
    for (kind, free, n_pad), js in sorted(specs.items(), key=lambda kv: kv[0][2]):
        buckets = by_model.setdefault((kind, free), [])
        if buckets and len(buckets[-1][1]) * (n_pad - buckets[-1][0]) <= MERGE_POINTS:
            buckets[-1] = (n_pad, sorted(buckets[-1][1] + js))
        else:
            buckets.append((n_pad, list(js)))
    merged = {(*model, n_pad): js for model, b in by_model.items() for n_pad, js in b}
    return dict(sorted(merged.items(), key=lambda kv: kv[1][0]))


def _fit_part_batch(profile, feature_ids, centres, lines, fix, min_points, file, part, kw):
    """The part through `fit_profiles` (kernel, then LM for what it did not solve)."""
    from ._batch import fit_profiles

    batch = fit_profiles(
        profile, np.full(len(centres), "" if part is None else str(part)), feature_ids, centres,
        **kw, fix=fix, lines=lines, min_points=min_points, file=file, batch_size=PART_BATCH,
    )  # fmt: skip
    fit = batch.profile_fit(0, throw=True)
    return fit if part is not None else dataclasses.replace(fit, part=None)


def _part_arguments(profile, centres, order, counts, starts, specs, takes):
    """Per group `(points (B, n_pad, 2), nominal geometry (B, ...), weights (B, n_pad))`,
    padded as `fit_profiles` pads: a feature's first point with weight zero, the
    group's first feature for the problems beyond its features."""
    from ._batch_solve import geometry_table

    table = geometry_table(profile)
    out = []
    for (_, _, n_pad), take in zip(specs, takes, strict=True):
        cnt, j = counts[take], np.arange(n_pad)
        valid = j[None, :] < cnt[:, None]
        idx = starts[take][:, None] + np.where(valid, j[None, :], 0)
        geom = tuple(leaf[take] for leaf in table)
        out.append((centres[order[idx]], geom, valid.astype(float)))
    return tuple(out)


def _unpack(flat: np.ndarray, layout, specs) -> tuple[list[dict], dict]:
    """The packed result: each group's `LsqArrays` fields (its real problems) and, per
    feature index, its measured surface and nominal points."""
    arrays, surfaces, k = [], {}, 0
    for (b, width, fields), ((_, _, n_pad), js) in zip(layout, specs.items(), strict=True):
        block = flat[k : k + b * width].reshape(b, width)[: len(js)]
        k += b * width
        a = {}
        for name, start, shape, dtype in fields:
            col = block[:, start : start + math.prod(shape)].reshape(len(js), *shape)
            a[name] = col if dtype == "float64" else col.astype(dtype)
        arrays.append(a)
        pts = flat[k : k + b * 4 * n_pad].reshape(2, b, n_pad, 2)
        k += b * 4 * n_pad
        for i, j in enumerate(js):
            surfaces[j] = (pts[0, i], pts[1, i])
    return arrays, surfaces


@functools.lru_cache(maxsize=64)
def _table_key(profile: Profile):
    """Shapes and dtypes of the nominal geometry's leaves (the geometry is data)."""
    from ._batch_solve import geometry_table

    return tuple((tuple(leaf.shape[1:]), str(leaf.dtype)) for leaf in geometry_table(profile))


def _surface_points(kind: str, pts, geom, values, ball_radius):
    """Measured surface points (ball-corrected along the fitted outward normal) and
    their nearest nominal points, `(B, n, 2)` each, from the geometry as data: what
    `Feature.outward_normal` and `Feature.closest_point` compute (`_surface_and_nominal`)."""
    import jax.numpy as jnp

    from ..geometry import rotate

    a, b, radius, sense = geom
    if kind == "line":  # a: mid-point, b: nominal outward normal; values: offset, rotation
        surface = pts - ball_radius * rotate(b, values[:, 1])[:, None, :]
        dist = jnp.sum((surface - a[:, None, :]) * b[:, None, :], axis=-1)
        return surface, surface - dist[..., None] * b[:, None, :]
    v = pts - (a + values[:, :2])[:, None, :]  # arc: a: centre; values: centre x, z, radius
    normal = sense[:, None, None] * v / jnp.sqrt(jnp.sum(v * v, axis=-1))[..., None]
    surface = pts - ball_radius * normal
    u = surface - a[:, None, :]
    return surface, a[:, None, :] + radius[:, None, None] * u / jnp.sqrt(jnp.sum(u * u, axis=-1))[
        ..., None
    ]


@functools.lru_cache(maxsize=32)
def _part_solver(table_key, sig):
    """The compiled one-part solve for signature `sig` (loss, tolerances, groups):
    `run(groups, ball_radius, scale, sigma)` -> every group's `LsqArrays` and its
    measured surface and nominal points, packed into one float64 vector
    (`meta["layout"]`); any profile (its geometry is data). Its trace is persisted
    (`_config.persisted`)."""
    from .. import _config

    def build():
        import jax
        import jax.numpy as jnp

        from ._batch_solve import Settings, group_solver
        from ._lsq_types import LsqArrays

        loss, rtol, atol, max_steps, groups = sig
        st = Settings(loss=loss, solver="auto", rtol=rtol, atol=atol, max_steps=max_steps,
                      ball_radius=None, scale=None, sigma=None)  # fmt: skip
        layout: list = []
        # made before tracing: the residual functions are cached with their constants
        solves = [group_solver(st, kind, free, n_pad) for kind, free, n_pad, _ in groups]

        def run(group_args, ball_radius, scale, sigma):
            flat = []
            for solve, (kind, free, _, b), (pts, geom, w) in zip(solves, groups, group_args,
                                                                 strict=True):  # fmt: skip
                res = solve(pts, geom, ball_radius, w, scale, sigma)
                fields, cols, width = [], [], 0
                for name in LsqArrays._fields:
                    a = getattr(res, name)
                    fields.append((name, width, list(a.shape[1:]), str(a.dtype)))
                    cols.append(jnp.reshape(a, (b, -1)).astype(jnp.float64))
                    width += cols[-1].shape[1]
                layout.append((b, width, fields))
                flat.append(jnp.concatenate(cols, axis=1).ravel())
                values = jnp.zeros((b, 2 if kind == "line" else 3))
                values = values.at[:, jnp.asarray(free)].set(res.params_flat)
                surface, nominal = _surface_points(kind, pts, geom, values, ball_radius)
                flat += [surface.ravel(), nominal.ravel()]
            return jnp.concatenate(flat)

        example = tuple(
            (
                jax.ShapeDtypeStruct((b, n_pad, 2), float),
                tuple(jax.ShapeDtypeStruct((b, *shape), dtype) for shape, dtype in table_key),
                jax.ShapeDtypeStruct((b, n_pad), float),
            )
            for _, _, n_pad, b in groups
        )
        scalars = [jax.ShapeDtypeStruct((), float)] * 3
        return jax.jit(run), (example, *scalars), {"layout": layout}

    key = (table_key, sig)
    return _config.persisted("part_fit", key, build, packages=("fit", "geometry"))
