"""[`BatchFit`][]: the result of [`fit_profiles`][], per-feature arrays over parts
(values, covariances, statuses, outliers, the pooled probe sigma), each part's
[`ProfileFit`][] rebuilt on demand, and the failures with the loop's messages."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ..errors import AnalysisError, InputError
from ..geometry import Profile
from ._failure import fit_failure
from ._features import FeatureFit, embed_free, surface_and_nominal
from ._profile_result import ProfileFit
from ._sigma import DECLARED_DOF, probe_sigma, sigma_arrays
from .lsq import COV_OK, LsqResult, Status, flat_structure, is_linear, result_from_arrays


@dataclass(frozen=True, eq=False)
class Group:
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
    groups: tuple[Group, ...]
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
    #: `(part index, feature index) -> (surface points, nominal points)` where the
    #: solve computed them (a one-part `fit_profile(solver="auto")`), at least as
    #: many rows as points; the others are computed by `profile_fit`
    surfaces: dict | None = field(default=None, repr=False)
    _index: dict = field(default_factory=dict, repr=False)

    def __post_init__(self):
        ids = self.profile.ids
        # (part, feature) -> (group, row), -1 where not measured
        where = np.full((len(self.parts), len(ids), 2), -1, dtype=np.int64)
        for g_i, g in enumerate(self.groups):
            where[g.part, g.feature, 0] = g_i
            where[g.part, g.feature, 1] = np.arange(len(g.part))
            if not len(g.feature):
                continue
            # each feature's rows, ascending (one sort, not a scan per feature)
            by = np.argsort(g.feature, kind="stable")
            fis, first = np.unique(g.feature[by], return_index=True)
            for fi, rows in zip(fis.tolist(), np.split(by, first[1:]), strict=True):
                self._index.setdefault(ids[fi], []).append((g_i, rows))
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
        bad = self.covariance_code(fid) != COV_OK
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
            ss, dof = inlier_ss(g, rows)
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
        feature in profile order, `fit_failure`), or `None` when every feature
        converged."""
        exc = self._failure(self._part_index(part))
        return None if exc is None else str(exc)

    def _failure(self, i: int) -> AnalysisError | None:
        """The `AnalysisError` of part `i`'s first failed feature (`fit_failure`: the
        feature, part and file named; a degenerate robust fit's down-weighted points by
        line), or None."""
        for j, f in enumerate(self.profile.features):
            g_i, row = (int(v) for v in self._where[i, j])
            if g_i < 0 or f.id not in self._index:
                continue
            g = self.groups[g_i]
            if int(g.arrays["status_code"][row]) > 0:
                start, n = int(g.start[row]), int(g.count[row])
                lines = self.lines[self.order[start : start + n]]
                res = self._result(g, row)
                return fit_failure(f, res, lines, part=self.parts[i], file=self.file)
        return None

    def _part_index(self, part: str | int) -> int:
        if isinstance(part, int | np.integer):
            return int(part)
        try:
            return self.parts.index(part)
        except ValueError:
            raise KeyError(f"no part {part!r}; parts are {', '.join(self.parts[:5])}...") from None

    # ------------------------------------------------------------------ per part
    def _result(self, g: Group, row: int, robust: bool | None = None) -> LsqResult:
        """The `LsqResult` that `least_squares` builds from the same arrays."""
        arr = {k: v[row] for k, v in g.arrays.items()}
        names, unravel = flat_structure(len(g.free))
        return result_from_arrays(
            arr,
            params=np.asarray(arr["params_flat"]),
            loss=self.loss,
            robust=not is_linear(self.loss) if robust is None else robust,
            names=names,
            unravel=unravel,
        )

    def profile_fit(self, part: str | int, *, throw: bool = False) -> ProfileFit:
        """The [`ProfileFit`][] of one part, field for field what `fit_profile` returns.

        With `throw=False` (the default) a feature that did not converge is kept
        (check `fit.converged` per feature, or `part_error`); with `throw=True` it
        raises what `fit_profile` raises: [`AnalysisError`][piecs_bayes.errors.AnalysisError]
        with `part_error`'s message and the failed feature's `LsqResult` (the first
        in profile order), or the probe-sigma rule's `InputError` naming `file`.
        """
        i = self._part_index(part)
        if throw:
            self._raise_failure(i)
        try:
            ps = self.probe_sigma(i)
        except InputError as exc:
            if not throw:
                raise
            raise InputError(str(exc), file=self.file) from None
        factor2 = (ps.value / self.reference_sigma) ** 2  # covariances -> the part's sigma
        robust = not is_linear(self.loss)
        fits, unmeasured = {}, []
        for j, (f, (g_i, row)) in enumerate(
            zip(self.profile.features, self._where[i].tolist(), strict=True)
        ):
            if g_i < 0:
                unmeasured.append(f.id)
                continue
            g = self.groups[g_i]
            n = int(g.count[row])
            start = int(g.start[row])
            pts_idx = self.order[start : start + n]
            centres = self.centres[pts_idx]
            res = self._result(g, row, robust)
            values, cov = embed_free(f.nparams, g.free, res.params, res.covariance)
            if cov is not None:
                cov = cov * factor2  # as `scale_fits` scales the loop's
            known = None if self.surfaces is None else self.surfaces.get((i, j))
            if known is not None:
                surface, nominal = known[0][:n], known[1][:n]
            else:
                surface, nominal = map(
                    np.asarray, surface_and_nominal(f, centres, values, float(self.ball_radius))
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
        return ProfileFit(
            self.profile,
            fits,
            "lsq" if self.method == "lsq" else "robust",
            tuple(unmeasured),
            self.parts[i],
            sigma=ps,
        )

    def _raise_failure(self, i: int) -> None:
        """`fit_profile`'s `AnalysisError` for part `i`'s first failed feature, if any."""
        exc = self._failure(i)
        if exc is not None:
            raise exc

    def rows(self) -> list[dict]:
        """One row per part, feature and parameter (for CSV / DataFrames), in the
        columns of fit.csv: `value`, `std_error` in `unit` (mm, or rad)."""
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
                            "unit": f.param_units[k],
                            "value": float(v[i, k]),
                            "std_error": float(se[i, k]),
                            "n_points": int(n[i]),
                            "n_outliers": int(no[i]),
                            "residual_sd_mm": float(sd[i]),
                            "sigma_mm": float(sig[i]),
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


def inlier_ss(g: Group, rows=slice(None)) -> tuple[np.ndarray, np.ndarray]:
    """Per problem of a group: residual sum of squares and dof of its inliers."""
    valid = np.arange(g.n_pad)[None, :] < g.count[rows, None]
    inl = valid & ~np.asarray(g.arrays["outlier"][rows], dtype=bool)
    r = np.where(inl, np.asarray(g.arrays["residuals"][rows]), 0.0)
    return np.sum(r * r, axis=1), inl.sum(axis=1) - len(g.free)
