"""Part-to-part tracking of one feature characteristic over a production run.

The parts of a run are cut one after the other by the same program; `values[k]` is the
measured normal deviation of part $k$ (mm, + = material left) with its standard
uncertainty `u[k]` from the part's own fit (NaN: a part not measured). The model is a
local linear trend with switching ([`TrackModel`][]: level, drift per part for tool
wear, part-to-part scatter, level steps at declared tool changes (which also restart
the wear) or undeclared ones, odd parts). [`track`][] filters and smooths a run into a
[`Track`][] (one-step-ahead predictives from earlier parts only, level, probabilities
that a part is odd or starts a step); with `model=None` it averages the fixed grid
[`HYPER_GRID`][] (prior `GRID_LOG_PRIOR`) by the evidence of the parts before each part.
[`fit_track_model`][] returns the grid's most probable model; [`fit_transfer`][] the
finish-to-semifinish transfer coefficient. The arithmetic is in `_filter`.

The model, its prior grid and why: docs/feedback.md, "The model".
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass, fields

import numpy as np

from .. import _config
from ..errors import InputError
from ._filter import mixture_filter, smoother
from ._mixture import logsumexp, mixture_cdf, mixture_quantile

optimize = _config.LazyModule("scipy.optimize")
special = _config.LazyModule("scipy.special")


_UM = 1e-3


@dataclass(frozen=True)
class TrackModel:
    """Hyper-parameters of the tracking model (mm and mm per part; see the module doc).

    - `level_sd`: random walk of the level per part ($\\sigma_\\ell$).
    - `drift_sd`: random walk of the drift per part ($\\sigma_d$, mm/part per part).
    - `scatter_sd`: part-to-part scatter not carried over ($\\sigma_e$), on top of each
      part's measurement uncertainty.
    - `step_sd`: sd of a level step at a tool change ($\\sigma_s$).
    - `step_prob`: prior probability of an undeclared step at a part.
    - `outlier_prob`: prior probability that a part is odd.
    - `outlier_scale`: sd added to an odd part's observation ($\\sigma_o$).
    - `drift0_sd`: prior sd of the drift of the first part ($\\sigma_{d0}$, mm/part).
    - `drift0_mean`: its prior mean ($\\mu_{d0}$, mm/part; + = material left grows).
    - `level0_sd`: prior sd of the level of part 0; `None`: diffuse.
    - `wear_reset`: the share of the wear of the old edge a declared tool change
      removes ($\\rho$: 1, a new edge starts unworn; 0, the change is a step only).
    - `drift_decay`: $\\phi$ in $d_{k+1} = \\phi d_k + v_k$, in (0, 1]: 1 a wear rate
      that persists; below 1 a transient (a warm-up, a new edge's fast initial wear)
      whose rate decays by $\\phi$ per part.
    """

    level_sd: float
    drift_sd: float
    scatter_sd: float
    step_sd: float = 0.010
    step_prob: float = 0.02
    outlier_prob: float = 0.02
    outlier_scale: float = 0.030
    drift0_sd: float = 0.001
    drift0_mean: float = 0.0
    level0_sd: float | None = None
    wear_reset: float = 1.0
    drift_decay: float = 1.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if v is None and f.name == "level0_sd":
                continue
            if isinstance(v, bool) or not isinstance(v, int | float) or not math.isfinite(v):
                raise InputError(f"track model {f.name!r} must be a finite number, got {v!r}")
            if (v < 0 and f.name != "drift0_mean") or (f.name == "level0_sd" and v == 0):
                raise InputError(f"track model {f.name!r} must be >= 0 (> 0), got {v!r}")
        if not 0 < self.drift_decay <= 1:
            raise InputError(f"track model 'drift_decay' must be in (0, 1], got "
                             f"{self.drift_decay!r}")  # fmt: skip
        if self.step_prob + self.outlier_prob >= 1:
            raise InputError("track model: step_prob + outlier_prob must be < 1")

    def as_dict(self) -> dict:
        """The fields as a flat dict (mm), for JSON."""
        return {f.name: getattr(self, f.name) for f in fields(self)}


GRID_SCATTER = (0.3, 0.6, 1.1, 2.0, 3.5, 6.0, 10.0, 16.0)  # µm
U_REF = 1.0 * _UM
"""The measurement uncertainty (mm) the grid's walks are relative to: a model of the
grid with EWMA weight $\\lambda$ has the level walk
$\\sigma_\\ell^2 = \\lambda^2/(1-\\lambda)\\,(\\sigma_e^2 + u_{ref}^2)$, so that on parts
measured with $u = u_{ref}$ its steady-state Kalman gain is $\\lambda$."""
_WEAR = 0.3  # µm/part: the scale of a wear rate (half-normal)
_DRIFTS = {  # (drift0_mean µm/part, drift0_sd µm/part, drift_sd µm/part², drift_decay)
    "none": (0.0, 0.0, 0.0, 1.0),
    "wear": (_WEAR * math.sqrt(2 / math.pi), _WEAR * math.sqrt(1 - 2 / math.pi), 0.0, 1.0),
    "either": (0.0, _WEAR, 0.0, 1.0),  # a drift of either sign (thermal)
    "new edge": (1.2, 0.8, 0.05, 0.95),  # fast wear, slowing
    "transient": (0.0, 6.0, 0.0, 0.6),  # a transient of either sign (warm-up)
}
GRID_DYNAMICS = (  # (EWMA weight of the level walk, drift, drift-walk ratio), weight
    # every EWMA: lambda 0 (a fixed level) to 0.95 (full feedback's limit), relative to
    # the noise; the drifts where a level walk leaves them to be told apart; and two
    # local linear trends (double EWMA: a drift that wanders, relative to the noise)
    # weights: GRID_PRIOR_WEIGHTS, trained (benchmarks/bench_feedback.py --train-prior)
    (0.0, "none", 0.0), (0.0, "wear", 0.0), (0.0, "either", 0.0), (0.0, "new edge", 0.0),
    (0.0, "transient", 0.0),
    (0.1, "none", 0.0), (0.1, "wear", 0.0), (0.1, "either", 0.0),
    (0.25, "none", 0.0), (0.25, "wear", 0.0), (0.25, "new edge", 0.0),
    (0.5, "none", 0.0), (0.5, "wear", 0.0),
    (0.7, "none", 0.0), (0.85, "none", 0.0), (0.95, "none", 0.0),
    (0.1, "either", 0.01), (0.25, "either", 0.05),
)  # fmt: skip
GRID_ODD_RATES = (0.002, 0.05)  # outlier_prob
GRID_STEP_RATES = (0.005, 0.02)  # step_prob, per measurement
GRID_PRIOR_WEIGHTS: dict[str, tuple[float, ...]] = {
    "scatter": (0.062, 0.062, 0.337, 0.253, 0.073, 0.086, 0.063, 0.062),
    "dynamics": (0.034, 0.401, 0.028, 0.063, 0.072, 0.028, 0.029, 0.028, 0.028, 0.028,
                 0.028, 0.029, 0.048, 0.046, 0.028, 0.028, 0.028, 0.028),
    "odd": (0.719, 0.281),
    "step": (0.75, 0.25),
}  # fmt: skip
"""Prior weights of the grid's factors: `scatter` per `GRID_SCATTER`, `dynamics` per
entry of `GRID_DYNAMICS`, `odd` per outlier rate, `step` per undeclared-step rate:
trained on the benchmark's training runs by maximum marginal likelihood and shrunk
halfway to uniform (`benchmarks/bench_feedback.py --train-prior 100`; docs/feedback.md,
"The model")."""


def ewma_ratio(lam: float) -> float:
    """$\\sigma_\\ell / \\sqrt{\\sigma_e^2 + u^2}$ of the local level whose steady-state
    Kalman gain is the EWMA weight `lam`: $\\lambda / \\sqrt{1 - \\lambda}$."""
    return lam / math.sqrt(1.0 - lam)


def ewma_weight(model: TrackModel) -> float:
    """The EWMA weight of a model's level walk (the inverse of [`ewma_ratio`][]): the
    steady-state gain of its local level on parts measured with `U_REF`."""
    q = model.level_sd**2
    r = model.scatter_sd**2 + U_REF**2
    if q == 0:
        return 0.0
    p = (q + math.sqrt(q * q + 4 * q * r)) / 2
    return p / (p + r)


def grid_points():
    """The points of `HYPER_GRID` in its order: `((scatter µm, weight), (dynamics,
    weight), (odd rate, weight), (step rate, weight))`, the weights those of
    `GRID_PRIOR_WEIGHTS`."""
    return itertools.product(
        zip(GRID_SCATTER, GRID_PRIOR_WEIGHTS["scatter"], strict=True),
        zip(GRID_DYNAMICS, GRID_PRIOR_WEIGHTS["dynamics"], strict=True),
        zip(GRID_ODD_RATES, GRID_PRIOR_WEIGHTS["odd"], strict=True),
        zip(GRID_STEP_RATES, GRID_PRIOR_WEIGHTS["step"], strict=True),
    )


def _model(sc, dyn, po, ps) -> TrackModel:
    lam, drift, walk = dyn
    mu, d0, dsd, phi = _DRIFTS[drift]
    noise = math.hypot(sc * _UM, U_REF)
    return TrackModel(
        level_sd=ewma_ratio(lam) * noise, drift_sd=dsd * _UM + walk * noise,
        scatter_sd=sc * _UM, drift0_sd=d0 * _UM, drift0_mean=mu * _UM, drift_decay=phi,
        outlier_prob=po, outlier_scale=40 * _UM, step_prob=ps, step_sd=10 * _UM,
    )  # fmt: skip


def _grid() -> tuple[TrackModel, ...]:
    return tuple(_model(sc, dyn, po, ps) for (sc, _), (dyn, _), (po, _), (ps, _) in grid_points())


def _grid_log_prior() -> np.ndarray:
    w = [wc * wd * wo * ws for (_, wc), (_, wd), (_, wo), (_, ws) in grid_points()]
    lp = np.log(np.asarray(w) / np.sum(w))
    lp.flags.writeable = False
    return lp


HYPER_GRID: tuple[TrackModel, ...] = _grid()
"""The empirical-Bayes grid of [`TrackModel`][]s (see the module doc)."""

GRID_LOG_PRIOR: np.ndarray = _grid_log_prior()
"""Log prior weights of `HYPER_GRID`: the product of its factors' `GRID_PRIOR_WEIGHTS`
(scatter, dynamics, odd-part rate, undeclared-step rate), normalised."""


@dataclass(frozen=True)
class Track:
    """Tracking of one characteristic over a run (arrays per part, mm; see the module doc).

    - `pred_mean`, `pred_sd`: one-step-ahead predictive of $y_k$ given parts $< k$, its
      regular component (no new odd part or step); NaN for part 0 with a diffuse start.
    - `pred_lo`, `pred_hi`: the central 95 % interval of the full predictive mixture.
    - `pred_weights`, `pred_means`, `pred_sds`: `(n, C)`, that mixture.
    - `level`, `level_sd`: filtered level (given parts $\\le k$).
    - `smooth_level`, `smooth_level_sd`: smoothed level (given the whole run).
    - `p_outlier`, `p_step`: posterior probability that part $k$ is odd (given parts
      $\\le k + 1$) / starts a step (given parts $\\le k + 6$, `STEP_MEMORY`); the last
      parts given those there are.
    - `next_mean`, `next_sd`: the level of the next part (n) as the finish cut will see
      it (times the transfer coefficient), what a decision acts on; `next_part_sd`
      adds the scatter of one part.
    - `steps`: indices of the steps (declared ones and those with `p_step` > 0.5).
    - `model`: the model used (the grid's best when averaged); `weights`: grid weights
      after the run (`None` for a fixed model); `loglik`: log marginal likelihood.
    - `weights_by_part`: `(n + 1, G)` the grid's weights before each part (row k from
      the evidence of parts $< k$; row n is `weights`): which models the run favours
      as it goes (`None` for a fixed model); [`Track.ewma_weight`][] sums them up.
    """

    pred_mean: np.ndarray
    pred_sd: np.ndarray
    pred_lo: np.ndarray
    pred_hi: np.ndarray
    pred_weights: np.ndarray
    pred_means: np.ndarray
    pred_sds: np.ndarray
    level: np.ndarray
    level_sd: np.ndarray
    smooth_level: np.ndarray
    smooth_level_sd: np.ndarray
    p_outlier: np.ndarray
    p_step: np.ndarray
    next_mean: float
    next_sd: float
    next_part_sd: float
    steps: tuple[int, ...]
    tool_changes: tuple[int, ...]
    model: TrackModel
    weights: np.ndarray | None
    loglik: float
    transfer: tuple[float, float] = (1.0, 0.0)
    weights_by_part: np.ndarray | None = None

    @property
    def n(self) -> int:
        return int(self.level.size)

    def ewma_weight(self) -> np.ndarray:
        """`(n + 1,)` the EWMA weight equivalent to the favoured level walk before each
        part: the posterior mean over the grid of the local level's steady-state gain
        $\\lambda$ with $\\sigma_\\ell^2/(\\sigma_e^2 + u_{ref}^2) = \\lambda^2/(1-\\lambda)$
        (`U_REF`; NaN for a fixed model)."""
        if self.weights_by_part is None:
            return np.full(self.n + 1, np.nan)
        lam = np.array([ewma_weight(m) for m in HYPER_GRID])
        return self.weights_by_part @ lam

    def pit(self, values) -> np.ndarray:
        """The predictive cdf at `values` per part (probability integral transform)."""
        v = np.asarray(values, dtype=float)
        return mixture_cdf(v, self.pred_weights, self.pred_means, self.pred_sds)

    def __repr__(self) -> str:
        steps = ", ".join(str(s) for s in self.steps) or "none"
        return (
            f"Track({self.n} parts: next level {self.next_mean * 1e3:+.2f} ± "
            f"{self.next_sd * 1e3:.2f} µm, steps at {steps}, "
            f"{int(np.sum(self.p_outlier > 0.5))} odd parts)"
        )


# --------------------------------------------------------------------------- helpers


def checked_values(values, u, tool_changes, missing: bool = False):
    """`(y, u, declared)` checked; with `missing`, NaN values are parts not measured
    (part 0 must be measured) and their `u` may be NaN too."""
    y = np.asarray(values, dtype=float)
    uu = np.broadcast_to(np.asarray(u, dtype=float), y.shape).astype(float)
    if y.ndim != 1 or y.size < 1:
        raise InputError(f"values must be a 1-D array of at least 1 part, got shape {y.shape}")
    seen = ~np.isnan(y) if missing else np.ones(y.size, dtype=bool)
    if not np.all(np.isfinite(y[seen])):
        raise InputError("values must be finite", value=int(np.sum(~np.isfinite(y[seen]))))
    if not seen[0]:
        raise InputError("the first part must be measured (it sets the level)")
    if not seen.all():  # u of a part not measured: only its predictive's width uses it
        ok = seen | (np.isfinite(uu) & (uu > 0))
        uu = np.where(ok, uu, np.nanmedian(np.where(seen, uu, np.nan)))
    if not (np.all(np.isfinite(uu)) and np.all(uu > 0)):
        raise InputError("u must be finite numbers > 0 (mm)")
    declared = np.zeros(y.size, dtype=bool)
    for t in tool_changes:
        if isinstance(t, bool) or not isinstance(t, int | np.integer) or not 0 <= t < y.size:
            raise InputError(f"tool change {t!r} is not a part index in [0, {y.size})", value=t)
        declared[int(t)] = True
    return y, uu, declared


def model_params(models, reps: int = 1) -> dict:
    """Filter parameters `(reps * G,)` from models (repeated per series, models fastest)."""

    def col(fn):
        return np.tile(np.array([fn(m) for m in models], dtype=float), reps)

    return {
        "scatter2": col(lambda m: m.scatter_sd**2),
        "q_level": col(lambda m: m.level_sd**2),
        "q_drift": col(lambda m: m.drift_sd**2),
        "drift0": col(lambda m: m.drift0_sd**2),
        "drift0_mean": col(lambda m: m.drift0_mean),
        "step2": col(lambda m: m.step_sd**2),
        "p_step": col(lambda m: m.step_prob),
        "p_odd": col(lambda m: m.outlier_prob),
        "odd2": col(lambda m: m.outlier_scale**2),
        "level0": col(lambda m: math.inf if m.level0_sd is None else m.level0_sd**2),
        "wear_reset": col(lambda m: m.wear_reset),
        "drift_decay": col(lambda m: m.drift_decay),
    }


def run_grid(y, u, declared, models, **kw) -> dict:
    """The mixture filter (`_tracking_filter`) on every model for a batch of runs.

    **Arguments:**

    - `y`: `(R, n)` (or `(n,)`) values of R runs (mm).
    - `u`: their standard uncertainties, broadcast to `y` (mm), > 0.
    - `declared`: `(n,)` or `(R, n)` booleans, True at a declared tool change.
    - `models`: G [`TrackModel`][]s.
    - `kw`: passed to the filter (`ahead`, `mixture`).

    **Returns:** the filter's dict with every array shaped `(R, G, ...)`.
    """
    y = np.atleast_2d(y)
    u = np.broadcast_to(np.atleast_2d(u), y.shape)
    r_, n = y.shape
    g = len(models)
    out = mixture_filter(
        np.repeat(y, g, axis=0),
        np.repeat(u**2, g, axis=0),
        model_params(models, r_),
        np.repeat(np.broadcast_to(np.atleast_2d(declared), (r_, n)), g, axis=0),
        **kw,
    )
    return {k: v.reshape((r_, g) + v.shape[1:]) for k, v in out.items()}


def grid_weights(loglik: np.ndarray, log_prior=None) -> np.ndarray:
    """Posterior weights of the grid before each part.

    **Arguments:**

    - `loglik`: `(R, G, n)` log predictive densities of the parts (`run_grid`).
    - `log_prior`: `(G,)` log prior of the grid points (`None`: uniform).

    **Returns:** `(R, G, n + 1)` weights; column k uses the parts before k (column 0 is
    the prior, column n uses the whole run).
    """
    cum = np.concatenate([np.zeros(loglik.shape[:2] + (1,)), np.cumsum(loglik, axis=2)], 2)
    if log_prior is not None:
        cum = cum + np.asarray(log_prior)[None, :, None]
    return np.exp(cum - logsumexp(cum, axis=1, keepdims=True))


def level_average(out: dict, wts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The grid-averaged predictive of the level of each part and of the next part.

    **Arguments:** `out`, the dict of `run_grid`; `wts`, the weights of `grid_weights`.

    **Returns:** `(mean, variance)`, each `(R, n + 1)`: column k the level of part k
    given the parts before it (NaN for a diffuse part 0), column n the next part.
    """
    lm = np.concatenate([out["lm"], out["next_m"][:, :, None]], 2)
    lv = np.concatenate([out["lv"], out["next_v"][:, :, None]], 2)
    m = np.sum(wts * lm, 1)
    v = np.sum(wts * (lv + (lm - m[:, None, :]) ** 2), 1)
    return m, v


def predictive_mixture(out: dict, wts: np.ndarray) -> tuple[np.ndarray, ...]:
    """The grid-averaged one-step-ahead predictive of each part's value, as a mixture.

    **Arguments:** `out`, the dict of `run_grid`; `wts`, the weights of `grid_weights`.

    **Returns:** `(weights, means, sds)`, each `(R, n, G * K)` (K components per model).
    """
    r_, g, n, c = out["pm"].shape
    pw = (out["pw"] * wts[:, :, :n, None]).transpose(0, 2, 1, 3).reshape(r_, n, g * c)
    pm = out["pm"].transpose(0, 2, 1, 3).reshape(r_, n, g * c)
    ps = out["ps"].transpose(0, 2, 1, 3).reshape(r_, n, g * c)
    return pw, pm, ps


# --------------------------------------------------------------------------- public


def fit_track_model(values, u, *, tool_changes=()) -> TrackModel:
    """Hyper-parameters of the tracking model by maximum marginal likelihood.

    **Arguments:**

    - `values`: `(n_parts,)` deviations in production order (mm).
    - `u`: `(n_parts,)` (or one number) their standard uncertainties (mm), > 0.
    - `tool_changes`: indices of the parts cut with a new tool (declared steps).

    **Returns:** the most probable [`TrackModel`][] of `HYPER_GRID`: the largest
    $\\prod_k p(y_k \\mid y_{<k})$ times its prior `GRID_LOG_PRIOR` (see the module
    doc); finite for any run of at least one part.
    """
    y, uu, declared = checked_values(values, u, tool_changes, missing=True)
    out = run_grid(y, uu, declared, HYPER_GRID)
    total = out["loglik"][0].sum(1) + GRID_LOG_PRIOR
    return HYPER_GRID[int(np.argmax(total))]


def transfer_of(transfer) -> tuple[float, float]:
    if isinstance(transfer, tuple | list):
        beta, u_beta = (float(t) for t in transfer)
    else:
        beta, u_beta = float(transfer), 0.0
    if not (math.isfinite(beta) and math.isfinite(u_beta) and u_beta >= 0):
        raise InputError(f"transfer must be beta or (beta, u_beta), got {transfer!r}")
    return beta, u_beta


def track(values, u, *, model: TrackModel | None = None, tool_changes=(), transfer=1.0) -> Track:
    """Filter, smooth and predict one characteristic over a run of parts.

    **Arguments:**

    - `values`: `(n_parts,)` deviations in production order (mm), as cut without
      feedback correction (subtract any correction applied); NaN for a part not
      measured (sampled inspection: a prediction step; part 0 must be measured).
    - `u`: `(n_parts,)` (or one number) their standard uncertainties (mm), > 0.
    - `model`: the hyper-parameters; `None` averages `HYPER_GRID` with weights from
      the parts before each part (empirical Bayes, see the module doc).
    - `tool_changes`: indices of the parts cut with a new tool (declared steps).
    - `transfer`: $\\beta$ or $(\\beta, u_\\beta)$ from [`fit_transfer`][]: the share of
      the tracked deviation the finish cut shows; scales `next_mean`, `next_sd`.

    **Returns:** a [`Track`][].
    """
    y, uu, declared = checked_values(values, u, tool_changes, missing=True)
    beta, u_beta = transfer_of(transfer)
    models = HYPER_GRID if model is None else (model,)
    out = run_grid(y, uu, declared, models)
    n = y.size
    wts = grid_weights(out["loglik"], GRID_LOG_PRIOR if model is None else None)
    lmean, lvar = level_average(out, wts)
    fin = wts[0, :, n]
    best = models[int(np.argmax(fin))]
    # regular component of the predictive: level + scatter + measurement, per grid point
    scat2 = np.array([m.scatter_sd**2 for m in models])[:, None]
    lv_reg = out["lv"][0] + scat2 + uu[None, :] ** 2
    pm = lmean[0, :n]
    pv = np.nansum(wts[0, :, :n] * (lv_reg + (out["lm"][0] - pm) ** 2), 0)
    pv = np.where(np.isnan(pm), np.nan, pv)
    # filtered level: weights from parts <= k
    wf = wts[0, :, 1:]
    fm = np.sum(wf * out["fm"][0], 0)
    fv = np.sum(wf * (out["fv"][0] + (out["fm"][0] - fm) ** 2), 0)
    p_odd = np.sum(fin[:, None] * out["p_lag"][0, :, :, 1], 0)
    p_step = np.sum(fin[:, None] * out["p_lag"][0, :, :, 2], 0)
    g = len(models)
    sm, sv = smoother(
        np.repeat(y[None], g, 0), np.repeat(uu[None] ** 2, g, 0), model_params(models),
        np.repeat(declared[None], g, 0), out["p_lag"][0, :, :, 1], out["p_lag"][0, :, :, 2],
    )  # fmt: skip
    smean = np.sum(fin[:, None] * sm, 0)
    svar = np.sum(fin[:, None] * (sv + (sm - smean) ** 2), 0)
    pw, pmx, psx = (a[0] for a in predictive_mixture(out, wts))
    lo = mixture_quantile(0.025, pw, pmx, psx)
    hi = mixture_quantile(0.975, pw, pmx, psx)
    nm, nv = float(lmean[0, n]), float(lvar[0, n])
    scatter_next = float(np.sum(fin * scat2[:, 0]))
    steps = tuple(sorted(set(np.flatnonzero(declared).tolist()) | set(
        np.flatnonzero(p_step > 0.5).tolist())))  # fmt: skip
    return Track(
        pred_mean=_ro(pm), pred_sd=_ro(np.sqrt(pv)), pred_lo=_ro(lo), pred_hi=_ro(hi),
        pred_weights=_ro(pw), pred_means=_ro(pmx), pred_sds=_ro(psx),
        level=_ro(fm), level_sd=_ro(np.sqrt(fv)),
        smooth_level=_ro(smean), smooth_level_sd=_ro(np.sqrt(svar)),
        p_outlier=_ro(p_odd), p_step=_ro(p_step),
        next_mean=beta * nm,
        next_sd=math.sqrt(beta**2 * nv + u_beta**2 * nm**2),
        next_part_sd=math.sqrt(beta**2 * (nv + scatter_next) + u_beta**2 * nm**2),
        steps=tuple(int(s) for s in steps),
        tool_changes=tuple(int(t) for t in np.flatnonzero(declared)),
        model=best,
        weights=None if model is not None else _ro(fin),
        weights_by_part=None if model is not None else _ro(wts[0].T),
        loglik=float(logsumexp(out["loglik"][0].sum(1) + (0.0 if model is not None
                                                                    else GRID_LOG_PRIOR))),
        transfer=(beta, u_beta),
    )  # fmt: skip


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


def fit_transfer(semifinish, finish, u_semi, u_finish) -> tuple[float, float]:
    """The transfer coefficient $\\beta$: finish deviation $= \\beta\\,\\times$ semifinish.

    Errors in both variables with known uncertainties (Deming's / York's line through
    the origin): $\\hat\\beta$ minimises
    $\\chi^2(\\beta) = \\sum_i (f_i - \\beta s_i)^2 / (u_{f,i}^2 + \\beta^2 u_{s,i}^2)$,
    which is the maximum likelihood estimate when the true semifinish deviations are
    free parameters; $u_\\beta^2 = 2 / \\chi^{2\\prime\\prime}(\\hat\\beta)$, inflated by
    the Birge ratio $\\chi^2_\\min/(n-1)$ when that exceeds 1 (scatter beyond the stated
    uncertainties). The finish deviations are those the finish cut made of the
    semifinish deviation, without the applied correction.

    **Arguments:**

    - `semifinish`, `finish`: `(n,)` deviations of the same parts (mm), n >= 2.
    - `u_semi`, `u_finish`: `(n,)` (or one number each) their standard uncertainties.

    **Returns:** `(beta, u_beta)`.
    """
    s = np.asarray(semifinish, dtype=float).ravel()
    f = np.asarray(finish, dtype=float).ravel()
    us = np.broadcast_to(np.asarray(u_semi, dtype=float), s.shape)
    uf = np.broadcast_to(np.asarray(u_finish, dtype=float), f.shape)
    if s.shape != f.shape or s.size < 2:
        raise InputError("semifinish and finish must be two arrays of the same >= 2 parts")
    if not (np.all(np.isfinite(s)) and np.all(np.isfinite(f))):
        raise InputError("semifinish and finish deviations must be finite")
    if not (np.all(us > 0) and np.all(uf > 0) and np.all(np.isfinite(us + uf))):
        raise InputError("u_semi and u_finish must be finite numbers > 0")
    if np.sum((s / us) ** 2) < 1e-12:
        raise InputError("the semifinish deviations are all zero: beta is not defined")

    def chi2(b):
        return float(np.sum((f - b * s) ** 2 / (uf**2 + b**2 * us**2)))

    b0 = float(np.sum(f * s / uf**2) / np.sum(s * s / uf**2))
    span = 10.0 * (abs(b0) + 1.0)
    res = optimize.minimize_scalar(chi2, bounds=(b0 - span, b0 + span), method="bounded",
                                   options={"xatol": 1e-12})  # fmt: skip
    b = float(res.x)
    h = 1e-4 * (abs(b) + 1e-3)
    curv = (chi2(b + h) - 2 * chi2(b) + chi2(b - h)) / h**2
    u_b = math.sqrt(2.0 / curv) if curv > 0 else math.inf
    birge = chi2(b) / (s.size - 1)
    return b, u_b * math.sqrt(max(birge, 1.0))
