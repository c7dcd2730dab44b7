"""`fit_profile(solver="auto")`: every feature of one part in one compiled call of
the batch kernel, and the part's [`ProfileFit`][] built straight from its arrays.

A production run fits part after part of the same layout (the same features with
the same point counts), so what depends only on the layout is made once and kept
(`_Plan`, by profile, feature ids of the points, fixed parameters, minimum points
and loss): the checks and their messages, the groups (kind, free parameters, point
bucket) and their padding, the gather indices of the points, the nominal geometry,
the compiled solve and where each field lies in its packed result. A call then
gathers the points, runs the solve (one transfer) and builds the fits: what
`fit_profiles(...).profile_fit(0)` builds, field for field and bit for bit
(tests/jobs/test_fit_fast_path.py), without the many-part bookkeeping.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import threading
from collections import OrderedDict

import numpy as np

from ..errors import InputError
from ..geometry import Profile
from ._features import FeatureFit, check_point_count, embed_free, free_parameters, padded_size
from ._options import BatchOptions
from ._profile_result import ProfileFit
from ._sigma import probe_sigma
from .lsq import Status, flat_structure, result_from_arrays

#: problems per compiled call of a group (residual function, point bucket) of one
#: part: a part with more features of a group pads to the next multiple
PART_BATCH = 1
#: a part's point buckets of one model (kind, free parameters) merge into the next
#: larger bucket when that adds at most this many padded points (problems x extra
#: padding): on the CPU a compiled group costs ~0.1 ms however small, a padded point
#: ~2 us (the demo part: lines of 8 and 16 points become one group, 0.1 ms less)
MERGE_POINTS = 64
#: layouts kept (least recently used dropped first)
PLAN_CACHE = 32


def check_feature_ids(profile: Profile, feature_ids: np.ndarray, lines, file) -> None:
    """Every point's feature id must be the profile's: the first unknown one is named
    with its file line."""
    unknown = sorted(set(feature_ids.tolist()).difference(profile.ids))
    if unknown:
        fid = unknown[0]
        first = int(lines[np.flatnonzero(feature_ids == fid)[0]])
        raise InputError(
            f"unknown feature id {fid!r}; the profile has {', '.join(profile.ids)}",
            file=file, line=first, column="feature", feature=fid,
        )  # fmt: skip


@dataclasses.dataclass(frozen=True, eq=False)
class _GroupPlan:
    """One compiled group: its real problems' feature indices, the point rows to
    gather `(B, n_pad)`, the nominal geometry and weights of its `B` problems (on the
    device: not copied again for every part), where its packed fields lie, and which
    of its padded points are real `(m, n_pad)`."""

    kind: str
    free: tuple[int, ...]
    n_pad: int
    features: tuple[int, ...]
    gather: np.ndarray
    geometry: tuple
    weights: np.ndarray
    valid: np.ndarray
    block: tuple[int, int, int]  # start in the packed vector, problems B, width
    fields: tuple  # (name, start, shape, dtype)
    surfaces: int  # start of its (surface, nominal) points


@dataclasses.dataclass(frozen=True, eq=False)
class _Plan:
    """Everything about a part that its layout fixes (see the module's docstring)."""

    profile: Profile
    groups: tuple[_GroupPlan, ...]
    run: object
    #: measured features in profile order: (feature index, group, row, point rows)
    measured: tuple[tuple[int, int, int, np.ndarray], ...]
    unmeasured: tuple[str, ...]
    fixed: dict  # feature id -> its fixed parameter names
    #: (ball radius, loss scale, reference sigma) -> those scalars on the device
    scalars: dict = dataclasses.field(default_factory=dict)


_PLANS: OrderedDict = OrderedDict()
_LOCK = threading.Lock()


def fit_part(profile, feature_ids, centres, lines, options, file, part, ref, ball_radius):
    """`fit_profile(solver="auto")` of one part (see the module's docstring), with the
    [`FitOptions`][] `options` and covariances at the reference sigma `ref`.

    `fit_profile`'s checks and messages; each group padded as `fit_profiles` pads
    it and solved with the measured surface points in one compiled call whose
    program depends only on the groups' shapes (the geometry is data), so parts
    and profiles of the same shapes share it. A problem the kernel does not solve
    sends the part to `fit_profiles` itself (its LM retries, the engine's status
    and message).
    """
    method, loss, sigma, declared = options.method, options.loss, options.sigma, options.declared
    loss_name = options.solve_loss
    fix, min_points = options.fix, options.min_points
    tolerances = (options.rtol, options.atol, options.max_steps)
    plan = _plan(profile, feature_ids, lines, fix, min_points, file, loss_name, tolerances)
    scale = np.nan if options.scale is None else options.scale
    args = tuple((centres[g.gather], g.geometry, g.weights) for g in plan.groups)
    numbers = (float(ball_radius), float(scale), ref)
    key = tuple(v.hex() for v in numbers)  # NaN (no scale) is a key too
    scalars = plan.scalars.get(key)
    if scalars is None:  # a run's parts share them: on the device once
        import jax

        if len(plan.scalars) >= 8:
            plan.scalars.clear()
        scalars = plan.scalars[key] = jax.device_put([np.asarray(v) for v in numbers])
    flat = np.asarray(plan.run(args, *scalars))
    arrays = [_fields(flat, g) for g in plan.groups]
    ok = int(Status.SUCCESSFUL)
    if any(code != ok for a in arrays for code in a["status_code"]):
        return _fit_part_batch(profile, feature_ids, centres, lines, options, file, part,
                               ball_radius)  # fmt: skip
    name = "" if part is None else str(part)
    ss, dof = _pooled(plan, arrays)
    try:
        ps = probe_sigma(
            ss, dof, declared=declared if sigma is None else float(sigma),
            declared_dof=options.declared_dof, known=sigma is not None, what=f"part {name!r}",
        )  # fmt: skip
    except InputError as exc:
        raise InputError(str(exc), file=file) from None
    fits = _feature_fits(plan, flat, arrays, centres, lines, (ps.value / ref) ** 2, loss_name,
                         "lsq" if method == "lsq" else f"robust/{loss}")  # fmt: skip
    return ProfileFit(profile, fits, "lsq" if method == "lsq" else "robust", plan.unmeasured,
                      None if part is None else name, sigma=ps)  # fmt: skip


def _pooled(plan: _Plan, arrays: list[dict]) -> tuple[float, int]:
    """Residual sum of squares and dof of the inliers pooled over the part's features."""
    ss = dof = 0
    for g, a in zip(plan.groups, arrays, strict=True):
        inl = g.valid & ~np.asarray(a["outlier"], dtype=bool)
        r = np.where(inl, np.asarray(a["residuals"]), 0.0)
        ss += float(np.sum(np.sum(r * r, axis=1)))
        dof += int(np.sum(inl.sum(axis=1) - len(g.free)))
    return ss, dof


def _feature_fits(plan, flat, arrays, centres, lines, factor2, loss, method) -> dict:
    """Each measured feature's [`FeatureFit`][] (its `LsqResult` as `least_squares`
    builds it), covariances times `factor2` (the part's sigma over the solves')."""
    robust = loss != "linear"
    per_group = []
    for g, a in zip(plan.groups, arrays, strict=True):  # what a group computes at once
        pts = flat[g.surfaces : g.surfaces + g.block[1] * 4 * g.n_pad].reshape(2, -1, g.n_pad, 2)
        full = len(g.free) == len(plan.profile.features[g.features[0]].param_names)
        cov = a["covariance"] * factor2 if full else None
        with np.errstate(invalid="ignore"):  # rows without a covariance hold NaN
            se = None if cov is None else np.sqrt(np.diagonal(cov, axis1=1, axis2=2))
        per_group.append((pts[1], pts[0] - pts[1], cov, se, flat_structure(len(g.free))))
    fits = {}
    for j, g_i, row, pts_idx in plan.measured:
        g, a, (nominal, errors, covs, ses, (names, unravel)) = (
            plan.groups[g_i], arrays[g_i], per_group[g_i])  # fmt: skip
        f = plan.profile.features[j]
        n = len(pts_idx)
        arr = {k: v[row] for k, v in a.items()}
        res = result_from_arrays(arr, params=np.asarray(arr["params_flat"]), loss=loss,
                                 robust=robust, names=names, unravel=unravel)  # fmt: skip
        cov = se = None
        if covs is not None:
            values = np.array(res.params, dtype=float)
            if res.covariance is not None:
                cov, se = covs[row], ses[row]
        else:  # fixed parameters: zeros in the values and the covariance
            values, cov = embed_free(f.nparams, g.free, res.params, res.covariance)
            if cov is not None:
                cov = cov * factor2
                se = np.sqrt(np.diag(cov))
        fits[f.id] = FeatureFit(
            feature=f,
            values=values,
            std_errors=se,
            covariance=cov,
            points=centres[pts_idx],
            residuals=np.asarray(res.residuals)[:n],
            weights=np.asarray(res.weights)[:n],
            outliers=np.asarray(res.outliers, dtype=int),
            lines=lines[pts_idx],
            nominal_points=nominal[row, :n],
            error_vectors=errors[row, :n],
            method=method,
            result=res,
            fixed=plan.fixed.get(f.id, ()),
        )
    return fits


def _fields(flat: np.ndarray, g: _GroupPlan) -> dict:
    """A group's `LsqArrays` fields (its real problems) from the packed result: the
    per-problem scalars as lists (Python numbers), the others as arrays."""
    start, b, width = g.block
    m = len(g.features)
    block = flat[start : start + b * width].reshape(b, width)[:m]
    out = {}
    for name, lo, shape, dtype in g.fields:
        if not shape:
            col = block[:, lo]
            out[name] = (col if dtype == "float64" else col.astype(dtype)).tolist()
            continue
        col = block[:, lo : lo + math.prod(shape)].reshape(m, *shape)
        out[name] = col if dtype == "float64" else col.astype(dtype)
    return out


def _plan(profile, feature_ids, lines, fix, min_points, file, loss_name, tolerances) -> _Plan:
    """The part's `_Plan`, made on the first part of its layout (checks included);
    `tolerances` = `(rtol, atol, max_steps)`."""
    key = (id(profile), feature_ids.dtype.str, feature_ids.tobytes(),
           tuple(sorted((k, tuple(v)) for k, v in fix.items())),
           tuple(sorted(min_points.items())), loss_name, tolerances)  # fmt: skip
    with _LOCK:
        plan = _PLANS.get(key)
        if plan is not None and plan.profile is profile:  # held: its id is not reused
            _PLANS.move_to_end(key)
            return plan
    plan = _make_plan(profile, feature_ids, lines, fix, min_points, file, loss_name, tolerances)
    with _LOCK:
        _PLANS[key] = plan
        while len(_PLANS) > PLAN_CACHE:
            _PLANS.popitem(last=False)
    return plan


def _make_plan(profile, feature_ids, lines, fix, min_points, file, loss_name, tolerances
               ) -> _Plan:  # fmt: skip
    check_feature_ids(profile, feature_ids, lines, file)
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
        free = tuple(free_parameters(f, tuple(fix.get(f.id, ()))))
        check_point_count(f, int(counts[j]), len(free))
        specs.setdefault((f.kind, free, padded_size(counts[j])), []).append(j)
    if not specs:
        raise InputError("no probe point belongs to any profile feature", file=file)
    specs = _merge_buckets(specs)
    order = np.argsort(feat, kind="stable")  # points by feature, file order within
    starts = np.concatenate([[0], np.cumsum(counts)[:-1]])
    takes = [js + [js[0]] * (PART_BATCH * -(-len(js) // PART_BATCH) - len(js))
             for js in specs.values()]  # fmt: skip
    sig = (loss_name, *tolerances,
           tuple((*key, len(t)) for key, t in zip(specs, takes, strict=True)))  # fmt: skip
    run, meta = _part_solver(_table_key(profile), sig)
    import jax

    from ._batch_solve import geometry_table

    table = geometry_table(profile)
    groups, where, k = [], {}, 0
    for ((kind, free, n_pad), js), take, (b, width, fields) in zip(
        specs.items(), takes, meta["layout"], strict=True
    ):
        cnt, i = counts[take], np.arange(n_pad)
        valid = i[None, :] < cnt[:, None]
        idx = starts[take][:, None] + np.where(valid, i[None, :], 0)
        fields = tuple((name, lo, tuple(shape), dtype) for name, lo, shape, dtype in fields)
        groups.append(_GroupPlan(
            kind=kind, free=free, n_pad=n_pad, features=tuple(js), gather=order[idx],
            geometry=jax.device_put(tuple(leaf[take] for leaf in table)),
            weights=jax.device_put(valid.astype(float)),
            valid=valid[: len(js)], block=(k, b, width), fields=fields,
            surfaces=k + b * width,
        ))  # fmt: skip
        for row, j in enumerate(js):
            where[j] = (len(groups) - 1, row)
        k += b * width + b * 4 * n_pad
    measured = tuple(
        (j, *where[j], order[starts[j] : starts[j] + counts[j]])
        for j in range(len(profile.features)) if j in where
    )  # fmt: skip
    unmeasured = tuple(f.id for j, f in enumerate(profile.features) if j not in where)
    fixed = {f.id: tuple(fix.get(f.id, ())) for f in profile.features}
    return _Plan(profile, tuple(groups), run, measured, unmeasured, fixed)


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


def _fit_part_batch(profile, feature_ids, centres, lines, options, file, part, ball_radius):
    """The part through `fit_profiles` (kernel, then LM for what it did not solve)."""
    from ._batch import fit_profiles

    batch = fit_profiles(
        profile, np.full(len(centres), "" if part is None else str(part)), feature_ids, centres,
        ball_radius=ball_radius, options=options, batch=BatchOptions(batch_size=PART_BATCH),
        lines=lines, file=file,
    )  # fmt: skip
    fit = batch.profile_fit(0, throw=True)
    return fit if part is not None else dataclasses.replace(fit, part=None)


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
        from .lsq import LsqArrays

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
