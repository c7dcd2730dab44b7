"""Shared test helpers: digit counting (like lmfit's StRD tests), the NIST StRD
nonlinear regression reader and its 27 models written by hand in JAX, circle
problems."""

from __future__ import annotations

import functools
import math
import re
import shutil
from dataclasses import dataclass
from pathlib import Path

import jax.numpy as jnp
import numpy as np

__all__ = [
    "BATCH",
    "batch_study_with",
    "STRD_DIR",
    "STRD_MODELS",
    "STRD_NPARAMS",
    "StrdProblem",
    "fit_strd",
    "algebraic_circle",
    "circle_residuals",
    "matching_digits",
    "read_strd",
]


def matching_digits(a, b) -> float:
    """Number of matching significant digits of `a` against the reference `b`,
    $-\\log_{10}(|a-b|/|b|)$ (lmfit's count), capped at 15; `nan` -> 0."""
    a, b = float(a), float(b)
    if not (math.isfinite(a) and math.isfinite(b)):
        return 0.0
    if a == b:
        return 15.0
    if b == 0.0:
        return max(0.0, min(15.0, -math.log10(abs(a))))
    return max(0.0, min(15.0, -math.log10(abs(a - b) / abs(b))))


# --------------------------------------------------------------------------- #
# NIST StRD nonlinear regression


@dataclass(frozen=True)
class StrdProblem:
    name: str
    x: np.ndarray  # (n,) or (n, k) predictors
    y: np.ndarray  # (n,) response
    start1: np.ndarray
    start2: np.ndarray
    certified: np.ndarray
    certified_sd: np.ndarray
    rss: float
    residual_sd: float
    dof: int


_PARAM = re.compile(r"^\s*b(\d+)\s*=\s*(\S+)\s+(\S+)\s+(\S+)\s+(\S+)\s*$")
_RSS = re.compile(r"Residual Sum of Squares:\s*(\S+)")
_RSD = re.compile(r"Residual Standard Deviation:\s*(\S+)")
_DOF = re.compile(r"Degrees of Freedom:\s*(\d+)")
_DATA_LINES = re.compile(r"Data\s+\(lines\s+(\d+)\s+to\s+(\d+)\)")


def read_strd(path: Path) -> StrdProblem:
    """Read one NIST StRD nonlinear regression file (``*.dat``)."""
    text = Path(path).read_text()
    lines = text.splitlines()
    params = []
    for line in lines:
        m = _PARAM.match(line)
        if m:
            params.append([float(v) for v in m.group(2, 3, 4, 5)])
    params = np.asarray(params)
    first, last = (int(v) for v in _DATA_LINES.search(text).group(1, 2))
    header = lines[first - 2].split()  # e.g. "Data:  y  x" just above the data
    assert header[0] == "Data:" and header[1] == "y", header
    data = np.asarray([[float(v) for v in lines[i].split()] for i in range(first - 1, last)])
    x = data[:, 1] if data.shape[1] == 2 else data[:, 1:]
    return StrdProblem(
        name=Path(path).stem,
        x=x,
        y=data[:, 0],
        start1=params[:, 0],
        start2=params[:, 1],
        certified=params[:, 2],
        certified_sd=params[:, 3],
        rss=float(_RSS.search(text).group(1)),
        residual_sd=float(_RSD.search(text).group(1)),
        dof=int(_DOF.search(text).group(1)),
    )


def _gauss(b, x):
    return (
        b[0] * jnp.exp(-b[1] * x)
        + b[2] * jnp.exp(-((x - b[3]) ** 2) / b[4] ** 2)
        + b[5] * jnp.exp(-((x - b[6]) ** 2) / b[7] ** 2)
    )


def _lanczos(b, x):
    return b[0] * jnp.exp(-b[1] * x) + b[2] * jnp.exp(-b[3] * x) + b[4] * jnp.exp(-b[5] * x)


def _misra1a(b, x):
    return b[0] * (1 - jnp.exp(-b[1] * x))


def _chwirut(b, x):
    return jnp.exp(-b[0] * x) / (b[1] + b[2] * x)


def _rational33(b, x):
    return (b[0] + b[1] * x + b[2] * x**2 + b[3] * x**3) / (
        1 + b[4] * x + b[5] * x**2 + b[6] * x**3
    )


def _enso(b, x):
    w = 2 * jnp.pi * x
    return (
        b[0]
        + b[1] * jnp.cos(w / 12)
        + b[2] * jnp.sin(w / 12)
        + b[4] * jnp.cos(w / b[3])
        + b[5] * jnp.sin(w / b[3])
        + b[7] * jnp.cos(w / b[6])
        + b[8] * jnp.sin(w / b[6])
    )


#: model(b, x) -> prediction of y (Nelson predicts log y, see `strd_residuals`).
STRD_MODELS = {
    "Bennett5": lambda b, x: b[0] * (b[1] + x) ** (-1 / b[2]),
    "BoxBOD": _misra1a,
    "Chwirut1": _chwirut,
    "Chwirut2": _chwirut,
    "DanWood": lambda b, x: b[0] * x ** b[1],
    "ENSO": _enso,
    "Eckerle4": lambda b, x: (b[0] / b[1]) * jnp.exp(-0.5 * ((x - b[2]) / b[1]) ** 2),
    "Gauss1": _gauss,
    "Gauss2": _gauss,
    "Gauss3": _gauss,
    "Hahn1": _rational33,
    "Kirby2": lambda b, x: (b[0] + b[1] * x + b[2] * x**2) / (1 + b[3] * x + b[4] * x**2),
    "Lanczos1": _lanczos,
    "Lanczos2": _lanczos,
    "Lanczos3": _lanczos,
    "MGH09": lambda b, x: b[0] * (x**2 + x * b[1]) / (x**2 + x * b[2] + b[3]),
    "MGH10": lambda b, x: b[0] * jnp.exp(b[1] / (x + b[2])),
    "MGH17": lambda b, x: b[0] + b[1] * jnp.exp(-x * b[3]) + b[2] * jnp.exp(-x * b[4]),
    "Misra1a": _misra1a,
    "Misra1b": lambda b, x: b[0] * (1 - (1 + b[1] * x / 2) ** (-2)),
    "Misra1c": lambda b, x: b[0] * (1 - (1 + 2 * b[1] * x) ** (-0.5)),
    "Misra1d": lambda b, x: b[0] * b[1] * x * ((1 + b[1] * x) ** (-1)),
    "Nelson": lambda b, x: b[0] - b[1] * x[:, 0] * jnp.exp(-b[2] * x[:, 1]),
    "Rat42": lambda b, x: b[0] / (1 + jnp.exp(b[1] - b[2] * x)),
    "Rat43": lambda b, x: b[0] / ((1 + jnp.exp(b[1] - b[2] * x)) ** (1 / b[3])),
    "Roszman1": lambda b, x: b[0] - b[1] * x - jnp.arctan(b[2] / (x - b[3])) / jnp.pi,
    "Thurber": _rational33,
}


STRD_DIR = Path(__file__).resolve().parents[1].parent / "shared" / "reference" / "strd"

STRD_NPARAMS = {
    **dict.fromkeys(["BoxBOD", "DanWood", "Misra1a", "Misra1b", "Misra1c", "Misra1d"], 2),
    **dict.fromkeys(["Bennett5", "Chwirut1", "Chwirut2", "Eckerle4", "MGH10", "Nelson"], 3),
    "Rat42": 3,
    **dict.fromkeys(["MGH09", "Rat43", "Roszman1"], 4),
    **dict.fromkeys(["Kirby2", "MGH17"], 5),
    **dict.fromkeys(["Lanczos1", "Lanczos2", "Lanczos3"], 6),
    **dict.fromkeys(["Hahn1", "Thurber"], 7),
    **dict.fromkeys(["Gauss1", "Gauss2", "Gauss3"], 8),
    "ENSO": 9,
}
#: every data set is padded to this many points (zero weights), so that all the
#: data sets with the same number of parameters share one compiled fit
STRD_PAD = 256


@functools.cache
def strd_group_fn(p: int):
    """One residual function for all StRD models with `p` parameters:
    `fn(b, (model_index, x (STRD_PAD, 2), y (STRD_PAD,)))`. Returns `(fn, names)`, `names[model_index]` the data set."""
    names = tuple(sorted(n for n, k in STRD_NPARAMS.items() if k == p))

    def branch(name):
        model = STRD_MODELS[name]
        if name == "Nelson":
            return lambda b, x: model(b, x)
        return lambda b, x: model(b, x[:, 0])

    branches = [branch(n) for n in names]

    def fn(b, a):
        # every model is evaluated and one picked: cheaper to compile than
        # lax.switch, and NaNs of the unpicked models do not propagate (select)
        idx, x, y = a
        out = branches[0](b, x)
        for k, branch in enumerate(branches[1:], start=1):
            out = jnp.where(idx == k, branch(b, x), out)
        return out - y

    return fn, names


def fit_strd(problem: StrdProblem, start, **kwargs):
    """Fit one StRD problem with `piecs_bayes.fit.least_squares` (`throw=False`),
    padded to `STRD_PAD` points with zero weights (Nelson is fitted on log y, as
    certified)."""
    from piecs_bayes.fit.lsq import least_squares

    p = len(problem.certified)
    fn, names = strd_group_fn(p)
    n = len(problem.y)
    x = np.ones((STRD_PAD, 2))
    x[:n] = problem.x.reshape(n, -1)
    x[n:] = x[n - 1]  # padding: finite model values, weight zero
    y = np.zeros(STRD_PAD)
    y[:n] = np.log(problem.y) if problem.name == "Nelson" else problem.y
    w = np.zeros(STRD_PAD)
    w[:n] = 1.0
    args = (jnp.asarray(names.index(problem.name)), jnp.asarray(x), jnp.asarray(y))
    kwargs.setdefault("throw", False)
    return least_squares(fn, jnp.asarray(start, float), args, weights=w, **kwargs)


def strd_residuals(name: str):
    """Residual function `fn(b, (x, y))` for StRD data set `name` (observed minus
    model is irrelevant for least squares; this is model minus observed)."""
    model = STRD_MODELS[name]
    if name == "Nelson":
        return lambda b, a: model(b, a[0]) - jnp.log(a[1])
    return lambda b, a: model(b, a[0]) - a[1]


# --------------------------------------------------------------------------- #
# Circles


def circle_residuals(p, xy):
    """Geometric (orthogonal) distances of points `xy` (n, 2) to the circle
    `p = {"xc", "yc", "r"}`."""
    return jnp.hypot(xy[:, 0] - p["xc"], xy[:, 1] - p["yc"]) - p["r"]


def algebraic_circle(xy) -> tuple[float, float, float]:
    """Kasa's algebraic circle fit (linear least squares on $x^2+y^2+Dx+Ey+F=0$,
    centroid-reduced): returns `(xc, yc, r)`, r the mean distance to the centre."""
    xy = np.asarray(xy, float)
    m = xy.mean(axis=0)
    u, v = (xy - m).T
    a = np.array([[u @ u, u @ v], [u @ v, v @ v]])
    rhs = 0.5 * np.array([u @ (u * u + v * v), v @ (u * u + v * v)])
    uc, vc = np.linalg.solve(a, rhs)
    xc, yc = uc + m[0], vc + m[1]
    r = float(np.mean(np.hypot(xy[:, 0] - xc, xy[:, 1] - yc)))
    return float(xc), float(yc), r


def run_cli(capsys, argv) -> tuple[int, str]:
    """`piecs-bayes ARGV` in this process: `(exit code, stdout + stderr)` (argparse's
    usage errors exit 2 through SystemExit)."""
    from piecs_bayes.cli import main

    try:
        rc = main([str(a) for a in argv])
    except SystemExit as exc:
        rc = exc.code
    out = capsys.readouterr()
    return rc, out.out + out.err


def gauge_ready(init_text: str, *, small: bool = False) -> str:
    """A study written by `init` made ready to plan and gauge: its commented `[probe]`
    tool and feed and `[program]` nose radius filled in, the probe's repeatability
    1.5 um; for a small part (the corpus: R1 fillets, 2 mm steps, a 0.25 mm ball)
    0.1 mm of stock, 0.3 mm of clearance and 0.05 mm of end clearance (in an inch
    study 0.004, 0.012 and 0.002 in)."""
    text = init_text.replace("# tool = 9 ", "tool = 9   ").replace("# feed = ", "feed = ")
    text = text.replace("# nose_radius = ", "nose_radius = ")
    inch = 'units = "in"' in text
    text = text.replace("[probe]\n", f"[probe]\nrepeatability = {0.00006 if inch else 0.0015}\n", 1)
    if small:
        stock, clearance, end = (0.004, 0.012, 0.002) if inch else (0.1, 0.3, 0.05)
        text = text.replace("[program]\n", f"[program]\nstock = {stock}\n", 1)
        text += f"\n[plan]\nclearance = {clearance}\nend_clearance = {end}\n"
    return text


def lobing_probe():
    """A lobing touch-trigger probe with its calibration, as the probe calibration tests
    use it: r0 4 um above a 1 mm ball, a 2-lobe term of 0.58 um and a 3-lobe term of
    1.5 um; the covariance of a 24-direction sphere calibration with 1.5 um
    repeatability and a certificate u(R) of 0.25 um."""
    from piecs_bayes.io import ProbeCalibration

    s, n = 0.0015, 24
    return ProbeCalibration(
        (2, 3), [1.004, 0.0005, -0.0003, 0.0015 * math.cos(0.3), 0.0015 * math.sin(0.3)],
        np.diag([s**2 / n + 0.00025**2] + [2 * s**2 / n] * 4), date="2026-11-30", feed=200.0,
        probe="T9",
    )  # fmt: skip


BATCH = Path(__file__).resolve().parent.parent / "data" / "batch"


def batch_study_with(folder: Path, table: str, parts: str = "part*.csv") -> Path:
    """A copy of data/batch in `folder` (the part files matching `parts`) whose
    study.toml ends with a `[feedback]` table of `table`'s lines; its path."""
    for p in BATCH.glob(parts):
        shutil.copy(p, folder / p.name)
    text = (BATCH / "study.toml").read_text(encoding="utf-8")
    assert "[feedback]" not in text
    path = folder / "study.toml"
    path.write_text(text + "\n[feedback]\n" + table + "\n", encoding="utf-8")
    return path


def three_sds(n: int) -> tuple[float, float]:
    """The window of 3 binomial sds about 95 % for a coverage rate over `n` trials."""
    half = 3.0 * math.sqrt(0.95 * 0.05 / n)
    return 0.95 - half, 0.95 + half


def window_pass_rate(window: tuple[float, float], n: int, p: float) -> float:
    """How often a rate over `n` trials of true coverage `p` falls in `window`: the
    exact binomial probability of the passing counts."""
    from scipy.stats import binom

    lo, hi = window
    k_lo, k_hi = math.ceil(lo * n - 1e-9), math.floor(hi * n + 1e-9)
    return float(binom.cdf(k_hi, n, p) - binom.cdf(k_lo - 1, n, p))
