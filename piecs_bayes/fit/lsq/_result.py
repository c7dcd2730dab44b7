"""[`LsqResult`][]: the user-facing result of [`least_squares`][], NumPy arrays with
typed fields and boolean diagnostics, printed as text or HTML; built from the
solve's arrays by [`result_from_arrays`][] (also for each problem of a batch)."""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Mapping
from typing import Any

import jax
import numpy as np

from ._types import COV_OK, COV_REASONS, Status

#: condition number (of the column-scaled weighted Jacobian) above which the
#: covariance is flagged as not accurate: its relative error is ~ eps * cond^2.
COND_ACCURATE = 1e6


@dataclasses.dataclass(frozen=True, eq=False)
class LsqResult:
    """Result of [`least_squares`][]. Immutable; arrays are NumPy.

    **Attributes:**

    - `params`: fitted parameters, a pytree like `y0`.
    - `status`: a [`Status`][]; `message` is its text.
    - `residuals`: raw (unweighted) residuals at the solution, `(n,)`.
    - `weights`: effective weights, user weight times robust weight, `(n,)`.
    - `robust_weights`: $\\rho'(z_i)$ of the final stage (ones for the linear loss).
    - `rss`: $\\sum_i w_i r_i^2$ at the solution. `cost`: the minimised objective.
    - `n`: points with non-zero weight. `dof`: `n - p`.
    - `residual_sd`: $\\sqrt{\\mathrm{RSS}/\\mathrm{dof}}$ (linear loss) or
      $1.4826\\,\\mathrm{MAD}$ of the weighted residuals (robust losses).
    - `covariance`: `(p, p)` in `ravel_pytree` order (see `param_names`), or `None`
      with the reason in `covariance_reason`.
    - `param_names`: names of the flat parameters, from the pytree keys.
    - `jacobian`: `(n, p)` Jacobian of the raw residuals at the solution.
    - `steps`: solver steps (all stages together).
    - `loss`, `scale`: the loss and the scale used (`nan` for the linear loss).
    - `condition_number`: of the column-scaled weighted Jacobian.
    - `outliers`: indices of the flagged points; `outlier_weights`: their robust
      weights.

    Properties: `converged`, `covariance_accurate`, `std_errors` (pytree like
    `y0`), `correlation`.
    """

    params: Any
    status: Status
    residuals: np.ndarray
    weights: np.ndarray
    robust_weights: np.ndarray
    rss: float
    cost: float
    n: int
    dof: int
    residual_sd: float
    covariance: np.ndarray | None
    covariance_reason: str | None
    param_names: tuple[str, ...]
    jacobian: np.ndarray
    steps: int
    loss: str
    scale: float
    condition_number: float
    outliers: tuple[int, ...]
    outlier_weights: np.ndarray
    params_flat: np.ndarray
    _unravel: Callable = dataclasses.field(repr=False)

    @property
    def message(self) -> str:
        return self.status.message

    @property
    def converged(self) -> bool:
        return self.status is Status.SUCCESSFUL

    @property
    def covariance_accurate(self) -> bool:
        """Covariance exists, the solve converged and the column-scaled Jacobian is
        well conditioned (condition number below 1e6)."""
        return (
            self.covariance is not None
            and self.converged
            and bool(self.condition_number < COND_ACCURATE)
        )

    @property
    def std_errors_flat(self) -> np.ndarray | None:
        if self.covariance is None:
            return None
        return np.sqrt(np.clip(np.diag(self.covariance), 0.0, None))

    @property
    def std_errors(self):
        se = self.std_errors_flat
        return None if se is None else jax.tree_util.tree_map(np.asarray, self._unravel(se))

    @property
    def correlation(self) -> np.ndarray | None:
        se = self.std_errors_flat
        if se is None:
            return None
        safe = np.where(se > 0, se, np.nan)
        return self.covariance / np.outer(safe, safe)

    def __repr__(self) -> str:
        return _result_text(self)

    def _repr_html_(self) -> str:
        return _result_html(self)


def result_from_arrays(
    arr: Mapping[str, np.ndarray],
    *,
    params: Any,
    loss: str,
    robust: bool,
    names: tuple[str, ...],
    unravel: Callable,
) -> LsqResult:
    """The [`LsqResult`][] of one problem from its `LsqArrays` fields (NumPy, by
    name), its fitted `params` pytree, the loss's name, whether it is robust, the
    flat parameters' `names` and the `unravel` of `params_flat`."""
    status = Status(int(arr["status_code"]))
    cov_code = int(arr["covariance_code"])
    cov = None if cov_code != COV_OK else np.array(arr["covariance"])
    flagged = np.flatnonzero(arr["outlier"])
    outliers = tuple(flagged.tolist())
    return LsqResult(
        params=params,
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
        covariance_reason=None if cov is not None else COV_REASONS[cov_code],
        param_names=names,
        jacobian=arr["jacobian"],
        steps=int(arr["steps"]),
        loss=loss,
        scale=float(arr["scale"]) if robust else float("nan"),
        condition_number=float(arr["condition"]),
        outliers=outliers,
        outlier_weights=arr["robust_weights"][flagged],
        params_flat=arr["params_flat"],
        _unravel=unravel,
    )


def _key_name(k) -> str:
    tu = jax.tree_util
    if isinstance(k, tu.DictKey):
        return str(k.key)
    if isinstance(k, tu.GetAttrKey):
        return k.name
    if isinstance(k, tu.SequenceKey):
        return str(k.idx)
    if isinstance(k, tu.FlattenedIndexKey):
        return str(k.key)
    return str(k)


def param_names(y0) -> tuple[str, ...]:
    """Names of the flat parameters, in `ravel_pytree` order."""
    leaves, _ = jax.tree_util.tree_flatten_with_path(y0)
    names: list[str] = []
    for path, leaf in leaves:
        base = ".".join(_key_name(k) for k in path) or "y"
        size = int(np.size(leaf))
        if np.ndim(leaf) == 0:
            names.append(base)
        else:
            names += [f"{base}[{','.join(map(str, ix))}]" for ix in np.ndindex(np.shape(leaf))][
                :size
            ]
    return tuple(names)


# --------------------------------------------------------------------------- rendering


def _summary_items(res: LsqResult) -> list[tuple[str, str]]:
    items = [
        ("status", res.status.name + ("" if res.converged else f" ({res.message})")),
        ("loss", res.loss + ("" if res.loss == "linear" else f" (scale {res.scale:.4g})")),
        ("n", str(res.n)),
        ("dof", str(res.dof)),
        ("rss", f"{res.rss:.6g}"),
        ("residual_sd", f"{res.residual_sd:.4g}"),
        ("steps", str(res.steps)),
        ("covariance_accurate", str(res.covariance_accurate)),
    ]
    if res.covariance_reason is not None:
        items.append(("covariance", f"None: {res.covariance_reason}"))
    if res.loss != "linear":
        items.append(("outliers", str(list(res.outliers))))
    return items


def _param_rows(res: LsqResult) -> list[tuple[str, str, str]]:
    se = res.std_errors_flat
    rows = []
    for i, name in enumerate(res.param_names):
        err = "-" if se is None else f"{se[i]:.4g}"
        rows.append((name, f"{res.params_flat[i]:.10g}", err))
    return rows


def _result_text(res: LsqResult) -> str:
    head = ", ".join(f"{k}={v}" for k, v in _summary_items(res))
    rows = [("parameter", "value", "std error"), *_param_rows(res)]
    widths = [max(len(r[j]) for r in rows) for j in range(3)]
    lines = [f"LsqResult({head})"]
    for r in rows:
        lines.append(
            "  "
            + "  ".join(
                c.rjust(w) if j else c.ljust(w)
                for j, (c, w) in enumerate(zip(r, widths, strict=True))
            )
        )
    return "\n".join(lines)


def _result_html(res: LsqResult) -> str:
    from html import escape

    summary = "".join(
        f"<tr><th style='text-align:left'>{escape(k)}</th><td>{escape(v)}</td></tr>"
        for k, v in _summary_items(res)
    )
    params = "".join(
        f"<tr><td>{escape(n)}</td><td>{escape(v)}</td><td>{escape(e)}</td></tr>"
        for n, v, e in _param_rows(res)
    )
    return (
        "<div><b>LsqResult</b><table>" + summary + "</table>"
        "<table><tr><th>parameter</th><th>value</th><th>std error</th></tr>"
        + params
        + "</table></div>"
    )
