r"""Batch fitting: every feature of many parts in one compiled call per feature kind.

A capability study fits thousands of parts of one study. The per-part loop
([`fit_profile`][]) dispatches one solve per feature and part; here all the
`(part, feature)` problems that share a residual function and a point-count
bucket form one *group*, solved by one jitted `jax.vmap` over problems in
batches of a fixed size, so each group compiles once (and the persistent cache
keeps it across runs). The solver is the lean batch kernel (`_batch_kernel`)
with the engine's LM as the fallback (`solver="auto"`), or `jax.vmap` of
[`solve_arrays`][] itself (`solver="lm"` etc.).

**Same numbers as the loop.** Each problem is set up exactly as
[`fit_feature`][] sets it up: the same residual function
(`feature_residuals(kind, free)`), nominal geometry passed as data, the same
point-count bucket (`padded_size`), padding by the first point with weight
zero, the same loss, scale and sigma, the same result statistics. The results
agree with the loop to the solvers' precision (tested: values to 1e-9 mm,
standard errors to 1e-6 relative, identical outlier flags and statuses).

**Failures are reported, not hidden.** Every problem keeps its
[`Status`][piecs_bayes.fit.Status]; [`BatchFit.failures`][] lists the parts and
features that did not converge, and [`BatchFit.part_error`][] gives the message
the loop would have raised for that part.

**Batch size and memory.** Parts are processed in chunks of `chunk_size` parts
(progress is reported per chunk); within a chunk each group is solved in batches
of a fixed size (`BATCH`), the last one padded, so one compilation per group
serves every study size and every chunking. The kept arrays are ~1 kB per
problem (residuals, weights and the Jacobian are kept so that
[`BatchFit.profile_fit`][] can rebuild any part's [`ProfileFit`][]): ~70 MB for
10,000 parts of 7 features. For more, split the study (as
`piecs_bayes._distributed` does) and keep only what you need.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable
from dataclasses import dataclass, field

import jax
import jax.numpy as jnp
import numpy as np

from ..errors import InputError
from ..geometry import Profile
from ._batch_kernel import kernel_solver
from ._features import (
    FeatureFit,
    _geometry_args,
    _surface_and_nominal,
    feature_residuals,
    padded_size,
)
from ._least_squares import (
    _COV_OK,
    _COV_REASONS,
    LsqArrays,
    LsqResult,
    Status,
    _is_linear,
    _param_names,
    _ravel,
    solve_arrays,
)
from ._profile_fit import ProfileFit, scale_fits
from ._sigma import DECLARED_DOF, probe_sigma, sigma_arrays

__all__ = ["BatchFit", "fit_profiles"]

#: parts per chunk (progress is reported per chunk)
CHUNK_PARTS = 1024
#: problems per compiled call. One fixed size: every study, chunking and cluster
#: reuses one compilation per group, and a problem's result does not depend on
#: which others share its batch. (Padding a small study to it costs milliseconds.)
BATCH = 256
#: largest padded bucket (points per feature) fitted by the batch kernel. With
#: 64-point buckets, XLA's CPU runtime (jaxlib 0.10.2) was seen to hang inside the
#: kernel's nested while loops, every thread idle, whatever the batch size or
#: dispatch; Levenberg-Marquardt (optimistix) does not. Larger buckets use it.
KERNEL_MAX_POINTS = 32
#: batch size of the Levenberg-Marquardt retries of `solver="auto"`
_RETRY_BATCH = 8
#: fields of `LsqArrays` kept per problem (all of them: `profile_fit` rebuilds results)
_FIELDS = LsqArrays._fields


@functools.lru_cache(maxsize=64)
def _group_solver(kind, free, loss, solver, rtol, atol, max_steps):
    """Jitted `vmap` of `solve_arrays` for one residual function and settings."""
    fn = feature_residuals(kind, free)
    p = len(free)

    def one(points, geom, ball_radius, weights, scale, sigma):
        return solve_arrays(
            fn,
            jnp.zeros(p),
            (points, geom, ball_radius),
            weights,
            loss=loss,
            scale=scale,
            sigma=sigma,
            solver=solver,
            rtol=rtol,
            atol=atol,
            max_steps=max_steps,
        )

    return jax.jit(jax.vmap(one, in_axes=(0, 0, None, 0, None, None)))


@dataclass(frozen=True, eq=False)
class _Group:
    """Problems of one residual function and bucket: `kind`, free parameter indices,
    padded point count; per problem its part and feature index, its point count,
    where its points start in the sorted point order, and the solver's arrays."""

    kind: str
    free: tuple[int, ...]
    n_pad: int
    part: np.ndarray
    feature: np.ndarray
    count: np.ndarray
    start: np.ndarray
    arrays: dict


@dataclass(frozen=True, eq=False)
class BatchFit:
    """Per-feature fits of many parts, solved in batches (see [`fit_profiles`][]).

    Arrays are by feature id over parts (in `parts` order); a feature a part did
    not measure has `NaN` values and status `-1`.

    - `values(fid)`, `covariance(fid)`, `std_errors(fid)`: over all the feature's
      parameters (fixed ones 0), `(P, k)`, `(P, k, k)`, `(P, k)`; the covariance
      is `NaN` where the fit has none (`covariance_code(fid)` says why).
    - `status(fid)`: [`Status`][piecs_bayes.fit.Status] codes; `ok`: parts whose
      every measured feature converged; `failures`: what did not.
    - `profile_fit(part)`: the part's [`ProfileFit`][], the same as `fit_profile`.
    """

    profile: Profile
    parts: tuple[str, ...]
    method: str
    loss: str
    fix: dict
    groups: tuple[_Group, ...]
    centres: np.ndarray = field(repr=False)
    lines: np.ndarray = field(repr=False)
    order: np.ndarray = field(repr=False)
    ball_radius: float = 1.0
    file: str | None = None
    #: per part: residual sum of squares and dof pooled over its features (inliers)
    pooled_ss: np.ndarray | None = field(default=None, repr=False)
    pooled_dof: np.ndarray | None = field(default=None, repr=False)
    #: the probe-sigma rule: (declared, declared_dof, known) - see `fit._sigma`
    sigma_rule: tuple = (None, DECLARED_DOF, False)
    #: the sigma the solves' covariances were computed with (rescaled to `sigma`)
    reference_sigma: float = 1.0
    _index: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        f_index = {f.id: i for i, f in enumerate(self.profile.features)}
        # (part, feature) -> (group, row), -1 where not measured
        where = np.full((len(self.parts), len(f_index), 2), -1, dtype=np.int64)
        for g_i, g in enumerate(self.groups):
            where[g.part, g.feature, 0] = g_i
            where[g.part, g.feature, 1] = np.arange(len(g.part))
            for fid, fi in f_index.items():
                rows = np.flatnonzero(g.feature == fi)
                if rows.size:
                    self._index.setdefault(fid, []).append((g_i, rows))
        object.__setattr__(self, "_where", where)
        if self.pooled_ss is None:
            object.__setattr__(self, "pooled_ss", np.zeros(len(self.parts)))
            object.__setattr__(self, "pooled_dof", np.zeros(len(self.parts), dtype=int))
        declared, declared_dof, known = self.sigma_rule
        value, nu = sigma_arrays(
            self.pooled_ss, self.pooled_dof, declared=declared, declared_dof=declared_dof,
            known=known,
        )  # fmt: skip
        object.__setattr__(self, "_sigma", (value, nu))

    @property
    def sigma(self) -> np.ndarray:
        """`(P,)` probe sigma each part's covariances are scaled by (mm; NaN: none)."""
        return self._sigma[0]

    @property
    def sigma_dof(self) -> np.ndarray:
        """`(P,)` degrees of freedom of `sigma` (`inf` when declared known)."""
        return self._sigma[1]

    def probe_sigma(self, part: str | int):
        """The part's [`ProbeSigma`][piecs_bayes.fit.ProbeSigma] (what `fit_profile` reports)."""
        i = self._part_index(part)
        declared, declared_dof, known = self.sigma_rule
        return probe_sigma(
            self.pooled_ss[i], int(self.pooled_dof[i]), declared=declared,
            declared_dof=declared_dof, known=known, what=f"part {self.parts[i]!r}",
        )  # fmt: skip

    # ------------------------------------------------------------------ arrays
    def __len__(self) -> int:
        return len(self.parts)

    @property
    def feature_ids(self) -> tuple[str, ...]:
        """The features measured on at least one part (profile order)."""
        return tuple(f.id for f in self.profile.features if f.id in self._index)

    def _scatter(self, fid: str, name: str, fill, shape=()):
        out = np.full((len(self.parts), *shape), fill)
        for g_i, rows in self._index.get(fid, []):
            g = self.groups[g_i]
            out[g.part[rows]] = g.arrays[name][rows]
        return out

    def _free(self, fid: str) -> list[int]:
        f = self.profile[fid]
        return [i for i, n in enumerate(f.param_names) if n not in self.fix.get(fid, ())]

    def values(self, fid: str) -> np.ndarray:
        """Fitted deviations `(P, k)` of feature `fid` (`NaN`: not measured)."""
        f = self.profile[fid]
        free = self._free(fid)
        out = np.full((len(self.parts), f.nparams), np.nan)
        measured = self.status(fid) >= 0
        out[measured] = 0.0
        out[:, free] = self._scatter(fid, "params_flat", np.nan, (len(free),))
        return out

    def covariance(self, fid: str) -> np.ndarray:
        """Covariances `(P, k, k)` (fixed parameters: zero rows; `NaN`: none)."""
        f = self.profile[fid]
        free = self._free(fid)
        p = len(free)
        cov_free = self._scatter(fid, "covariance", np.nan, (p, p))
        out = np.zeros((len(self.parts), f.nparams, f.nparams))
        out[np.ix_(np.arange(len(self.parts)), free, free)] = cov_free
        out *= ((self.sigma / self.reference_sigma) ** 2)[:, None, None]  # -> the part's sigma
        bad = self.covariance_code(fid) != _COV_OK
        out[bad] = np.nan
        return out

    def std_errors(self, fid: str) -> np.ndarray:
        c = self.covariance(fid)
        return np.sqrt(np.diagonal(c, axis1=1, axis2=2))

    def status(self, fid: str) -> np.ndarray:
        """`Status` code per part (`-1`: the part did not measure `fid`)."""
        return self._scatter(fid, "status_code", -1).astype(int)

    def covariance_code(self, fid: str) -> np.ndarray:
        return self._scatter(fid, "covariance_code", -1).astype(int)

    def n_points(self, fid: str) -> np.ndarray:
        return self._scatter(fid, "n_used", 0).astype(int)

    def n_outliers(self, fid: str) -> np.ndarray:
        out = np.zeros(len(self.parts), dtype=int)
        for g_i, rows in self._index.get(fid, []):
            g = self.groups[g_i]
            out[g.part[rows]] = g.arrays["outlier"][rows].sum(axis=1)
        return out

    def residual_sd(self, fid: str) -> np.ndarray:
        """`(P,)` the feature's own residual sd over its inliers, $\\sqrt{\\sum r^2/\\nu}$
        (mm; NaN without residual dof or not measured), as `FeatureFit.residual_sd`."""
        out = np.full(len(self.parts), np.nan)
        for g_i, rows in self._index.get(fid, []):
            g = self.groups[g_i]
            ss, dof = _inlier_ss(g, rows)
            with np.errstate(divide="ignore", invalid="ignore"):
                out[g.part[rows]] = np.where(dof > 0, np.sqrt(ss / np.maximum(dof, 1)), np.nan)
        return out

    def steps(self, fid: str) -> np.ndarray:
        return self._scatter(fid, "steps", 0).astype(int)

    @property
    def outlier_mask(self) -> np.ndarray:
        """`(n,)` true for the input points flagged as outliers (input order)."""
        mask = np.zeros(len(self.centres), dtype=bool)
        for g in self.groups:
            j = np.arange(g.n_pad)
            valid = j[None, :] < g.count[:, None]
            idx = g.start[:, None] + j[None, :]
            mask[self.order[idx[valid]]] = g.arrays["outlier"][valid]
        return mask

    @property
    def ok(self) -> np.ndarray:
        """`(P,)` true where every measured feature of the part converged."""
        good = np.ones(len(self.parts), dtype=bool)
        for fid in self.feature_ids:
            s = self.status(fid)
            good &= (s == -1) | (s == int(Status.SUCCESSFUL))
        return good

    @property
    def failures(self) -> list[tuple[str, str, Status]]:
        """`(part, feature, status)` of every problem that did not converge."""
        out = []
        for fid in self.feature_ids:
            s = self.status(fid)
            for i in np.flatnonzero((s >= 0) & (s != int(Status.SUCCESSFUL))):
                out.append((self.parts[i], fid, Status(int(s[i]))))
        order = {p: i for i, p in enumerate(self.parts)}
        fo = {fid: i for i, fid in enumerate(self.profile.ids)}
        return sorted(out, key=lambda t: (order[t[0]], fo[t[1]]))

    def part_error(self, part: str | int) -> str | None:
        """The message [`fit_profile`][] would raise for this part (its first failed
        feature in profile order), or `None` when every feature converged."""
        i = self._part_index(part)
        for fid in self.profile.ids:
            if fid not in self._index:
                continue
            s = int(self.status(fid)[i])
            if s > 0:
                steps = int(self.steps(fid)[i])
                return f"least-squares fit failed: {Status(s).message} (after {steps} steps)"
        return None

    def _part_index(self, part: str | int) -> int:
        if isinstance(part, int | np.integer):
            return int(part)
        try:
            return self.parts.index(part)
        except ValueError:
            raise KeyError(f"no part {part!r}; parts are {', '.join(self.parts[:5])}...") from None

    # ------------------------------------------------------------------ per part
    def _result(self, g: _Group, row: int) -> LsqResult:
        """The `LsqResult` that `least_squares` builds from the same arrays."""
        arr = {k: np.asarray(v[row]) for k, v in g.arrays.items()}
        y0 = jnp.zeros(len(g.free))
        _, unravel = _ravel(y0)
        status = Status(int(arr["status_code"]))
        cov_code = int(arr["covariance_code"])
        cov = None if cov_code != _COV_OK else np.array(arr["covariance"])
        robust = not _is_linear(self.loss)
        outliers = tuple(int(i) for i in np.flatnonzero(arr["outlier"]))
        return LsqResult(
            params=np.asarray(arr["params_flat"]),
            status=status,
            residuals=arr["residuals"],
            weights=arr["weights"],
            robust_weights=arr["robust_weights"],
            rss=float(arr["rss"]),
            cost=float(arr["cost"]),
            n=int(arr["n_used"]),
            dof=int(arr["dof"]),
            residual_sd=float(arr["residual_sd"]),
            covariance=cov,
            covariance_reason=None if cov is not None else _COV_REASONS[cov_code],
            param_names=_param_names(y0),
            jacobian=arr["jacobian"],
            steps=int(arr["steps"]),
            loss=self.loss,
            scale=float(arr["scale"]) if robust else float("nan"),
            condition_number=float(arr["condition"]),
            outliers=outliers,
            outlier_weights=arr["robust_weights"][list(outliers)],
            params_flat=arr["params_flat"],
            _unravel=unravel,
        )

    def profile_fit(self, part: str | int) -> ProfileFit:
        """The [`ProfileFit`][] of one part, field for field what `fit_profile` returns
        (with `throw=False` semantics: check `fit.converged` per feature, or
        `part_error`)."""
        i = self._part_index(part)
        fits, unmeasured = {}, []
        for j, f in enumerate(self.profile.features):
            g_i, row = (int(v) for v in self._where[i, j])
            if g_i < 0:
                unmeasured.append(f.id)
                continue
            g = self.groups[g_i]
            n = int(g.count[row])
            pts_idx = self.order[g.start[row] : g.start[row] + n]
            centres = self.centres[pts_idx]
            res = self._result(g, row)
            values = np.zeros(f.nparams)
            values[list(g.free)] = np.asarray(res.params)
            cov = None
            if res.covariance is not None:
                cov = np.zeros((f.nparams, f.nparams))
                cov[np.ix_(g.free, g.free)] = np.asarray(res.covariance)
            surface, nominal = map(
                np.asarray, _surface_and_nominal(f, centres, values, float(self.ball_radius))
            )
            fits[f.id] = FeatureFit(
                feature=f,
                values=values,
                std_errors=None if cov is None else np.sqrt(np.diag(cov)),
                covariance=cov,
                points=centres,
                residuals=np.asarray(res.residuals)[:n],
                weights=np.asarray(res.weights)[:n],
                outliers=np.asarray(res.outliers, dtype=int),
                lines=self.lines[pts_idx],
                nominal_points=nominal,
                error_vectors=surface - nominal,
                method=self.method,
                result=res,
                fixed=tuple(self.fix.get(f.id, ())),
            )
        ps = self.probe_sigma(i)
        return ProfileFit(
            self.profile,
            scale_fits(fits, ps.value / self.reference_sigma),
            "lsq" if self.method == "lsq" else "robust",
            tuple(unmeasured),
            self.parts[i],
            sigma=ps,
        )

    def rows(self) -> list[dict]:
        """One row per part, feature and parameter (for CSV / DataFrames)."""
        out = []
        for fid in self.feature_ids:
            f = self.profile[fid]
            v, se, st = self.values(fid), self.std_errors(fid), self.status(fid)
            n, no, sd = self.n_points(fid), self.n_outliers(fid), self.residual_sd(fid)
            sig, sig_dof = self.sigma, self.sigma_dof
            for i, part in enumerate(self.parts):
                if st[i] < 0:
                    continue
                for k, name in enumerate(f.param_names):
                    out.append(
                        {
                            "part": part,
                            "feature": fid,
                            "parameter": name,
                            "value": float(v[i, k]),
                            "std_error": float(se[i, k]),
                            "n_points": int(n[i]),
                            "n_outliers": int(no[i]),
                            "residual_sd": float(sd[i]),
                            "sigma": float(sig[i]),
                            "sigma_dof": float(sig_dof[i]),
                            "status": Status(int(st[i])).name,
                            "method": self.method,
                        }
                    )
        return out

    def __repr__(self) -> str:
        bad = self.failures
        head = (
            f"BatchFit({self.method}, {len(self.parts)} parts, {len(self.feature_ids)} features, "
            f"{sum(len(g.part) for g in self.groups)} fits in {len(self.groups)} groups, "
            f"{len(bad)} failed)"
        )
        lines = [head]
        for part, fid, st in bad[:10]:
            lines.append(f"  {part} {fid}: {st.name} ({st.message})")
        if len(bad) > 10:
            lines.append(f"  ... and {len(bad) - 10} more")
        return "\n".join(lines)


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


def fit_profiles(
    profile: Profile,
    part_ids,
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
    solver: str = "auto",
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_steps: int = 1000,
    chunk_size: int = CHUNK_PARTS,
    batch_size: int = BATCH,
    progress: bool | Callable[[int, int, str], None] = False,
) -> BatchFit:
    """Fit each feature of `profile` on every part, batched (see the module docstring).

    **Arguments:**

    - `part_ids`, `feature_ids`: `(n,)` part and feature of each point; parts keep
      the order of their first point (production order).
    - `centres`: `(n, 2)` ball centres in the part frame (mm, radius X).
    - `ball_radius`, `method` (`"lsq"`/`"robust"`), `loss`, `scale`, `sigma`,
      `declared`, `declared_dof`, `fix`, `lines`, `min_points`, `file`: as in
      [`fit_profile`][], for every part (the probe sigma is pooled per part).
    - `solver`: `"auto"` (default): the lean batch kernel (`_batch_kernel`: the
      same staged objective and result statistics, Newton steps in closed form),
      then the engine's Levenberg-Marquardt for any problem it did not solve, so a
      failure carries the engine's status and message (features with more than
      `KERNEL_MAX_POINTS` points go to Levenberg-Marquardt directly); `"fast"`:
      the kernel alone (same limit);
      or an engine solver for every problem: `"lm"` (`fit_profile`'s: the loop's
      exact path), `"gauss_newton"`, `"dogleg"`. Under `vmap` a batch runs as many
      steps as its slowest problem, and the engine's robust stages make LM take
      ~125 steps per problem; the kernel takes ~12-20 and is 10-20x faster than
      `"lm"`, with the same minimum (~1e-10 mm, 1e-7 standard errors, on the batch
      data: `tests/test_batch.py`).
    - `rtol`, `atol`, `max_steps`: as in [`least_squares`][] (`fit_profile`'s
      defaults).
    - `chunk_size`: parts per compiled call (memory grows with it).
    - `batch_size`: problems per compiled call (see `BATCH`).
    - `progress`: `True` for a tqdm bar, or a callable `progress(done, total, part)`
      called after each chunk.

    **Returns:** a [`BatchFit`][]. Input errors (unknown feature, too few points)
    raise the same [`InputError`][piecs_bayes.errors.InputError] as the loop;
    a fit that does not converge is reported in `BatchFit.failures`.
    """
    if method not in ("lsq", "robust"):
        raise ValueError(f"unknown method {method!r}; expected 'lsq' or 'robust'")
    if solver not in ("auto", "fast", "lm", "gauss_newton", "dogleg"):
        raise InputError(
            f"unknown solver {solver!r}; expected 'auto', 'fast', 'lm', 'gauss_newton' or 'dogleg'"
        )
    if chunk_size < 1 or batch_size < 1:
        raise InputError(
            f"chunk_size and batch_size must be >= 1, got {chunk_size!r}, {batch_size!r}"
        )
    fix = {k: tuple(v) for k, v in (fix or {}).items()}
    min_points = {"line": 3, "arc": 4, **(min_points or {})}
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
    _validate(profile, counts, fix, min_points, file)

    order = np.argsort(key, kind="stable")  # points grouped by (part, feature), file order
    starts = np.zeros(n_parts * n_feat, dtype=int)
    starts[1:] = np.cumsum(counts.ravel())[:-1]
    starts = starts.reshape(n_parts, n_feat)

    loss_used = "linear" if method == "lsq" else loss
    free_of = [
        tuple(i for i, n in enumerate(f.param_names) if n not in fix.get(f.id, ()))
        for f in profile.features
    ]
    geoms = _geometry_table(profile)
    # groups: (kind, free, bucket) -> problems in (part, feature) order
    pp, ff = np.nonzero(counts)
    buckets = np.array([padded_size(c) for c in counts[pp, ff]])
    gkeys = {}
    for k, (j, b) in enumerate(zip(ff.tolist(), buckets.tolist(), strict=True)):
        gkeys.setdefault((profile.features[j].kind, free_of[j], b), []).append(k)
    chunk_of = pp // chunk_size
    n_chunks = int(math.ceil(n_parts / chunk_size))
    specs = []
    for key, ks in gkeys.items():
        specs.append((*key, np.asarray(ks), int(batch_size)))

    bar = None
    if progress is True:
        from tqdm.auto import tqdm

        bar = tqdm(total=n_parts, desc="batch fit", unit="part")
    callback = progress if callable(progress) else None

    rb = jnp.asarray(float(ball_radius))
    s_arr = jnp.asarray(np.nan if scale is None else float(scale))
    # covariances at a reference sigma (known or declared: it sets the stationarity
    # test's scale), rescaled per part to its probe sigma
    ref = float(sigma if sigma is not None else (declared if declared is not None else 1.0))
    sig_arr = jnp.asarray(ref)
    results = [dict() for _ in specs]
    pending: list = []

    def finish(g_i, rows, data, out):
        out = _fetch(out, rows.size)
        if solver == "auto" and specs[g_i][2] <= KERNEL_MAX_POINTS:
            kind, free = specs[g_i][:2]
            _retry_lm(out, rows, data, kind, free, loss_used, rtol, atol, max_steps,
                      rb, s_arr, sig_arr)  # fmt: skip
        return out

    for c in range(n_chunks):
        for g_i, (kind, free, n_pad, ks, bsize) in enumerate(specs):
            sel = ks[chunk_of[ks] == c]
            if sel.size == 0:
                continue
            if solver in ("auto", "fast") and n_pad > KERNEL_MAX_POINTS:
                solve = _group_solver(kind, free, loss_used, "lm", rtol, atol, max_steps)
            elif solver in ("auto", "fast"):
                solve = kernel_solver(feature_residuals(kind, free), len(free), loss_used,
                                      rtol, atol)  # fmt: skip
            else:
                solve = _group_solver(kind, free, loss_used, solver, rtol, atol, max_steps)
            data = (pp, ff, counts, starts, order, centres, geoms, n_pad)
            for lo in range(0, sel.size, bsize):
                rows = sel[lo : lo + bsize]
                # dispatched now (asynchronous: XLA computes while Python prepares the
                # next batch), fetched after the chunk. Not from several threads: two
                # concurrent executions on XLA's CPU pool were seen to deadlock.
                dev = _dispatch(solve, rows, *data, bsize, rb, s_arr, sig_arr)
                pending.append((g_i, (rows, data, dev)))
        for g_i, out in pending:
            out = finish(g_i, *out)
            for name, a in out.items():
                results[g_i].setdefault(name, []).append(a)
        pending.clear()
        done = min(n_parts, (c + 1) * chunk_size)
        if bar is not None:
            bar.update(done - bar.n)
        if callback is not None:
            callback(done, n_parts, parts[done - 1])
    if bar is not None:
        bar.close()

    groups = []
    for (kind, free, n_pad, ks, _), res in zip(specs, results, strict=True):
        # the problems were solved chunk by chunk in (part, feature) order
        order_ks = np.concatenate([ks[chunk_of[ks] == c] for c in range(n_chunks)])
        arrays = {name: np.concatenate(v) for name, v in res.items()}
        groups.append(
            _Group(
                kind=kind,
                free=free,
                n_pad=n_pad,
                part=pp[order_ks],
                feature=ff[order_ks],
                count=counts[pp[order_ks], ff[order_ks]],
                start=starts[pp[order_ks], ff[order_ks]],
                arrays=arrays,
            )
        )
    ss, dof = _pooled(groups, n_parts)
    return BatchFit(
        profile=profile,
        parts=parts,
        pooled_ss=ss,
        pooled_dof=dof,
        sigma_rule=(declared if sigma is None else float(sigma), declared_dof, sigma is not None),
        reference_sigma=ref,
        method="lsq" if method == "lsq" else f"robust/{loss}",
        loss=loss_used,
        fix=fix,
        groups=tuple(groups),
        centres=centres,
        lines=lines,
        order=order,
        ball_radius=float(ball_radius),
        file=file,
    )


def _inlier_ss(g: _Group, rows=slice(None)) -> tuple[np.ndarray, np.ndarray]:
    """Per problem of a group: residual sum of squares and dof of its inliers."""
    valid = np.arange(g.n_pad)[None, :] < g.count[rows, None]
    inl = valid & ~np.asarray(g.arrays["outlier"][rows], dtype=bool)
    r = np.where(inl, np.asarray(g.arrays["residuals"][rows]), 0.0)
    return np.sum(r * r, axis=1), inl.sum(axis=1) - len(g.free)


def _pooled(groups, n_parts: int) -> tuple[np.ndarray, np.ndarray]:
    """Per part: residual sum of squares and dof of its inliers, over its features."""
    ss, dof = np.zeros(n_parts), np.zeros(n_parts, dtype=int)
    for g in groups:
        g_ss, g_dof = _inlier_ss(g)
        np.add.at(ss, g.part, g_ss)
        np.add.at(dof, g.part, g_dof)
    return ss, dof


def _solve_rows(solve, rows, pp, ff, counts, starts, order, centres, geoms, n_pad, bsize,
                rb, scale, sigma):  # fmt: skip
    """Pad `rows` (problem numbers) to `bsize` problems of `n_pad` points and solve."""
    dev = _dispatch(solve, rows, pp, ff, counts, starts, order, centres, geoms, n_pad, bsize,
                    rb, scale, sigma)  # fmt: skip
    return _fetch(dev, rows.size)


def _dispatch(solve, rows, pp, ff, counts, starts, order, centres, geoms, n_pad, bsize,
              rb, scale, sigma):  # fmt: skip
    """Start the solve of `rows` padded to `bsize` problems (asynchronous)."""
    take = np.concatenate([rows, np.repeat(rows[:1], bsize - rows.size)])
    cnt = counts[pp[take], ff[take]]
    st = starts[pp[take], ff[take]]
    j = np.arange(n_pad)
    # padding repeats the problem's first point (as fit_feature does), weight zero
    idx = st[:, None] + np.where(j[None, :] < cnt[:, None], j[None, :], 0)
    pts = centres[order[idx]]
    w = (j[None, :] < cnt[:, None]).astype(float)
    geom = _stack_geometry(geoms, ff[take])
    args = (jnp.asarray(pts), geom, rb, jnp.asarray(w), scale, sigma)
    return _packed(solve)(*args), _unpacker(solve, jax.tree_util.tree_map(jnp.shape, args))


@functools.lru_cache(maxsize=128)
def _packed(solve):
    """`solve` with its 17 result arrays packed into one `(B, K)` float64 array: one
    transfer per batch instead of 17 (integer codes and flags are exact in float64)."""

    def run(*args):
        out = solve(*args)
        b = out.params_flat.shape[0]
        return jnp.concatenate(
            [jnp.reshape(getattr(out, n), (b, -1)).astype(float) for n in _FIELDS], axis=1
        )

    return jax.jit(run)


@functools.lru_cache(maxsize=128)
def _layout(solve, shapes):
    return jax.eval_shape(solve, *jax.tree_util.tree_map(
        lambda s: jax.ShapeDtypeStruct(s, jnp.float64), shapes,
        is_leaf=lambda x: isinstance(x, tuple) and all(isinstance(i, int) for i in x),
    ))  # fmt: skip


def _unpacker(solve, shapes):
    """Field name -> (column slice, per-problem shape, dtype) of `_packed(solve)`."""
    out = _layout(solve, _hashable(shapes))
    cols, k = {}, 0
    for n in _FIELDS:
        a = getattr(out, n)
        size = int(np.prod(a.shape[1:], dtype=int))
        cols[n] = (slice(k, k + size), a.shape[1:], a.dtype)
        k += size
    return cols


def _hashable(tree):
    return tuple(_hashable(x) for x in tree) if isinstance(tree, tuple | list) else tree


def _fetch(dev, m: int) -> dict:
    """The first `m` problems' results as writable NumPy arrays."""
    packed, cols = dev
    arr = np.asarray(jax.device_get(packed))[:m]
    return {
        n: arr[:, sl].reshape((m, *shape)).astype(dtype) for n, (sl, shape, dtype) in cols.items()
    }


def _retry_lm(out, rows, data, kind, free, loss, rtol, atol, max_steps, rb, scale, sigma):
    """`solver="auto"`: problems that Gauss-Newton did not solve are solved again
    with Levenberg-Marquardt (`fit_feature`'s solver), in place; their status is
    then LM's, so a failure is the failure the loop reports."""
    bad = np.flatnonzero(out["status_code"] != int(Status.SUCCESSFUL))
    if bad.size == 0:
        return
    solve = _group_solver(kind, free, loss, "lm", rtol, atol, max_steps)
    for lo in range(0, bad.size, _RETRY_BATCH):
        sub = bad[lo : lo + _RETRY_BATCH]
        again = _solve_rows(solve, rows[sub], *data, _RETRY_BATCH, rb, scale, sigma)
        for name in out:
            out[name][sub] = again[name]


@functools.lru_cache(maxsize=64)
def _geometry_table(profile: Profile) -> tuple[np.ndarray, ...]:
    """The features' nominal geometry (`_geometry_args`) stacked, `(F, ...)` per leaf;
    cached per profile (building it takes ~100 eager JAX operations)."""
    geoms = [_geometry_args(f) for f in profile.features]
    return tuple(np.stack([np.asarray(g[k]) for g in geoms]) for k in range(len(geoms[0])))


def _stack_geometry(table: tuple, which: np.ndarray):
    """Per-problem nominal geometry `(B, ...)` from the stacked table."""
    return tuple(jnp.asarray(leaf[which]) for leaf in table)
