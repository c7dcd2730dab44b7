"""Golden outputs: the main job (``make demo``) and ``capability`` on data/batch.

Recorded once from a known-good commit and compared after every move of code (a
refactor must not change a result). Record again, on purpose, with

    .venv/bin/python tests/golden.py --record

The golden files catch a change of a result and nothing else. Bit equality is not a
property of this stack across machines: XLA compiles for the CPU it runs on (vector
width, fused multiply-add, the order of reductions), so the last bits of a sum differ
between an AVX-512 and an SSE4.2 machine, and one changed last bit sends an MCMC chain
down another path. Each kind of number is therefore compared to the precision it has:

- **deterministic numerics** (fits, covariances, decisions, bands, budgets,
  capability, the machine files): equal within ``RTOL`` relative plus ``ATOL``
  absolute plus one unit in the last printed digit (a number printed to 4 decimals
  flips its last digit when its value sits within the tolerance of a rounding
  boundary). Where they come from: the solvers stop when a step is below 1e-10
  relative (+ 1e-12) of the parameters, then polish until the cost is flat at its
  rounding noise, 1e-12 relative (``fit._lsq_core._polish``); a minimum whose cost is
  flat to 1e-12 is located to about sqrt(1e-12) = 1e-6 of a standard error, and the
  standard errors here are at most 1e-3 mm: ``ATOL`` = 1e-9 (mm, rad, or a ratio of
  them; seen between the AVX-512, AVX2 and SSE4.2 builds of one commit: 1.8e-10 mm).
  What is derived from a fit (a Huber weight, a ratio of a residual to the scale) is
  good to a few 1e-7 relative (seen: 2.7e-7); ``RTOL`` = 5e-7, half the smallest
  change the check must catch (1e-6 relative, ``tests/test_golden.py``). Integers
  (counts, line numbers, ids) are exact. The message names the first differing
  number, its place, its size and the bound.
- **Monte Carlo and MCMC outputs** (posterior.csv, the ``*_mc`` tool-path files, the
  Monte Carlo route of toolpath_bounds.json, posterior.nc): equal in distribution,
  not in bits. A statistic computed from draws of effective size ESS has the
  sampling standard error ``c * s / sqrt(ESS)`` (``s`` its spread, ``c`` a factor
  per statistic, ``MC_FACTORS``); the recorded and the new value, two independent
  estimates, must agree within ``MC_Z`` = 4 standard errors of their difference,
  ``4 * c * s * sqrt(1/ESS_recorded + 1/ESS_now)``. ESS is the smallest bulk
  effective sample size of the run's posterior (posterior.nc's ``ess_bulk``), which
  every Monte Carlo output here is pushed from. Sampler diagnostics are estimates
  too: R-hat within 0.01 (the width of its own 1.01 threshold), ESS, autocorrelation
  times and the thinning that follows from them within 25 % (an autocorrelation time
  from 4 x 80 walkers x 6000 steps is good to about 10 %). Convergence flags and
  problem lists are equal.
- **text** (G-code, diffs, tables, report text): the same words, in the same order,
  and the same count of numbers, each number compared by its kind as above; time
  stamps and wall times are masked (they change on every run), nothing else is. In
  the report text a number drawn from the sampler has no column to say so: the
  recording runs the job with ``REPORT_SEEDS`` other seeds and marks each number that
  moved; a marked number may move by ``REPORT_SPREAD`` times the largest move seen
  among the recordings (plus two units in its last printed digit), every other
  number is deterministic.
- **binary containers** (posterior.nc): the groups, variables, dims, shapes, dtypes
  and attributes equal; the draws by their means and standard deviations per element,
  as Monte Carlo numbers; the observed data as deterministic numbers.

``constraints.txt`` pins the package versions for ``make``; with other versions the
test skips and says which differ (a new JAX may change a result on purpose).
"""

from __future__ import annotations

import csv
import io
import json
import math
import re
import sys
from dataclasses import dataclass
from importlib.metadata import version
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
GOLDEN = ROOT / "tests" / "data" / "golden"
DEMO_STUDY = ROOT / "data" / "demo" / "study.toml"
BATCH_STUDY = ROOT / "data" / "batch" / "study.toml"
PACKAGES = ("jax", "jaxlib", "numpy", "scipy", "emcee", "optimistix", "equinox", "arviz")

#: files compared through a recorded text or summary instead of their bytes
REPORTS = {"report.html": "report.html.txt", "report.pdf": "report.pdf.txt"}
CONTAINERS = {"posterior.nc": "posterior.nc.json"}
BINARY = set(REPORTS) | set(CONTAINERS)
#: recorded fixture -> the output it stands for
_SOURCE = {v: k for k, v in {**REPORTS, **CONTAINERS}.items()}

RTOL = 5e-7
ATOL = 1e-9
MC_Z = 4.0
#: seeds of the extra recordings that mark the report's Monte Carlo numbers
REPORT_SEEDS = (101, 202, 303, 404)
REPORT_SPREAD = 5.0

_MASKS = (
    (re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d(?:\.\d+)?(?:[+-]\d\d:\d\d|Z)?"), "<time>"),
    (re.compile(r"<caption>Wall time per step</caption>.*?</table>", re.S), "<walltimes>"),
    (re.compile(r"\d+(?:\.\d+)? ?s( sampling|,|\))"), r"<s>\1"),
    (re.compile(r"\d+(?:\.\d+)? effective samples"), "<n> effective samples"),
    # the PDF's fixed-width table: its column widths follow the widest wall time
    (re.compile(r"Wall time per step\n.*?(?=\npiecs_bayes report|\n\n|\Z)", re.S), "<walltimes>"),
    # ... and where the PDF draws it as a table: a step name and its seconds per line
    (
        re.compile(
            r"^(read|fit|bayes|decisions|path|uncertainty|program|errspec|capability)"
            r"\s+\d+\.\d+\s*$",
            re.M,
        ),
        r"\1 <s>",
    ),
)

#: the PDF's page footer ("piecs_bayes report · <study> · part <id> · <time> page 3 of 13")
_FOOTER = re.compile(r"^piecs_bayes report · .*page \d+ of \d+\s*$", re.M)
#: figures embedded in the HTML: compared by their alt text and caption (their pixels
#: are drawn from Monte Carlo results and a renderer's anti-aliasing)
_IMAGE = re.compile(r'src="data:image/[^"]*"')
_NUMBER = re.compile(r"[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


# ---------------------------------------------------------------- running the jobs


def _run(argv: list[str], shown: str) -> None:
    """Run the CLI in this process as ``piecs-bayes ARGV``. The report records the
    command line: it is given as ``shown`` (the command a user types, e.g. `make
    demo`'s), not pytest's nor the temporary output folder, whose length would
    change how the PDF wraps the line."""
    import os

    from piecs_bayes.cli import main

    saved, cwd = sys.argv, os.getcwd()
    sys.argv = shown.split()
    os.chdir(ROOT)  # paths as `make demo` gives them, relative to the repository
    try:
        rc = main(argv)
    finally:
        sys.argv = saved
        os.chdir(cwd)
    assert rc == 0, f"piecs-bayes {' '.join(argv)} exited {rc}"


def run_demo(out: Path, seed: int | None = None) -> Path:
    """Exactly ``make demo`` (same study, same default seed), into ``out``."""
    study = str(DEMO_STUDY.relative_to(ROOT))
    extra = [] if seed is None else ["--seed", str(seed)]
    _run(
        ["demo", study, "--out", str(out), "--quiet", *extra],
        f"piecs-bayes demo {study} --out reports/demo",
    )
    return out


def run_capability(out: Path, seed: int | None = None) -> Path:
    study = str(BATCH_STUDY.relative_to(ROOT))
    extra = [] if seed is None else ["--seed", str(seed)]
    _run(
        ["capability", study, "--out", str(out), "--quiet", *extra],
        f"piecs-bayes capability {study}",
    )
    return out


JOBS = {"demo": run_demo, "capability": run_capability}


# ---------------------------------------------------------------- numbers by kind


@dataclass(frozen=True)
class Deterministic:
    """A number a solver or a closed form gives: ``rtol`` relative + ``atol`` (and one
    unit in the last printed digit, added where it is compared)."""

    rtol: float = RTOL
    atol: float = ATOL

    def tolerance(self, a: float, b: float) -> float:
        return self.rtol * max(abs(a), abs(b)) + self.atol


DETERMINISTIC = Deterministic()
#: a number of the report text: displayed rounded (to 2-3 significant digits), and
#: many of them drawn by the sampler without a column to say so; they are held to 5 %
#: (+ one unit in the last printed digit) and, where a recording saw them move with
#: the seed, to that spread. Every one of them is also in a CSV, JSON or netCDF
#: output, compared there at full precision by its kind.
DISPLAYED = Deterministic(rtol=0.05, atol=0.0)


@dataclass(frozen=True)
class MonteCarlo:
    """A statistic of draws: ``MC_Z`` standard errors ``c * s / sqrt(ESS)`` of the
    difference of two independent estimates (``s``: the statistic's spread)."""

    c: float
    s: float
    what: str

    def tolerance(self, ess: tuple[float, float]) -> float:
        return MC_Z * self.c * abs(self.s) * math.sqrt(1.0 / ess[0] + 1.0 / ess[1])


#: ``c`` per statistic, for draws near normal (``s``: the draws' standard deviation):
#: a mean 1; a standard deviation 1/sqrt(2) for normal draws, taken as 1 (excess
#: kurtosis up to 2); a 2.5 % or 97.5 % quantile sqrt(p(1-p))/phi(z_p) = 2.7, taken
#: as 3; a simultaneous band limit (centre +- crit * sd) sqrt(1 + crit^2/2 +
#: se(crit)^2 ESS) ~ 3 for crit ~ 3, taken as 4; a correlation (1 - rho^2) with s = 1;
#: a covariance sqrt(1 + rho^2) for normal draws with s = sqrt(c_ii c_jj), taken as
#: 2 sqrt((1 + rho^2) / 2) (a variance is an sd squared: twice the sd's relative
#: error, with the sd's allowance for kurtosis; an independent seed moved a
#: variance by 4.1 normal-theory standard errors); a critical value of
#: the maximum over the path 2 with s = 1 (the density of max |Z| at its 95 % quantile
#: is ~0.15, sqrt(0.05 * 0.95) / 0.15 = 1.5)
MC_FACTORS = {
    "mean": 1.0,
    "sd": 1.0,
    "quantile": 3.0,
    "simultaneous": 4.0,
    "corr": 1.0,
    "cov": 2.0,
    "crit": 2.0,
}

#: (file, column) -> (statistic, column whose value is the spread ``s``; None: itself)
_MC_COLUMNS = {
    "posterior.csv": {
        "mean": ("mean", "sd"),
        "sd": ("sd", None),
        "q2.5": ("quantile", "sd"),
        "q97.5": ("quantile", "sd"),
    },
    "toolpath_band_mc.csv": {
        "offset_mm": ("mean", "u_offset_mm"),
        "u_offset_mm": ("sd", None),
        "pointwise_lower_mm": ("quantile", "u_offset_mm"),
        "pointwise_upper_mm": ("quantile", "u_offset_mm"),
        "simultaneous_lower_mm": ("simultaneous", "u_offset_mm"),
        "simultaneous_upper_mm": ("simultaneous", "u_offset_mm"),
    },
    "toolpath_bounds_mc.csv": {
        "x_radius_mm": ("mean", "u_x_radius_mm"),
        "z_mm": ("mean", "u_z_mm"),
        "u_x_radius_mm": ("sd", None),
        "u_z_mm": ("sd", None),
        "corr_xz": ("corr", "corr_xz"),
    },
}


def _mc_json(path: tuple, value: float, root) -> MonteCarlo | None:
    """The Monte Carlo route of toolpath_bounds.json, by its place in the file."""
    if path[:2] != ("methods", "monte_carlo"):
        return None
    mc = root["methods"]["monte_carlo"]
    key = path[2]
    if key == "vertices":
        i, j = path[3], path[4]
        return MonteCarlo(MC_FACTORS["mean"], math.sqrt(mc["vertex_cov"][i][j][j]), "mean")
    if key == "vertex_cov":
        i, j, k = path[3], path[4], path[5]
        c = mc["vertex_cov"][i]
        s = math.sqrt(abs(c[j][j] * c[k][k]))
        rho2 = value**2 / (s * s) if s > 0 else 0.0
        return MonteCarlo(MC_FACTORS["cov"] * math.sqrt((1 + rho2) / 2), s, "covariance")
    if key == "band" and path[3] == "crit_simultaneous":
        return MonteCarlo(MC_FACTORS["crit"], 1.0, "critical value")
    if key == "band" and path[3] == "max_half_width_simultaneous":
        crit = mc["band"]["crit_simultaneous"]
        return MonteCarlo(MC_FACTORS["simultaneous"], value / crit, "band half-width")
    if key == "deviation_sd":
        return MonteCarlo(MC_FACTORS["sd"], value, "sd")
    return None


def _unit(token: str) -> float:
    """One unit in the last printed digit of a decimal number; 0 for an integer."""
    mant, _, exp = token.lower().partition("e")
    if "." not in mant:
        return 0.0 if not exp else 10.0 ** int(exp)
    decimals = len(mant.split(".")[1])
    return 10.0 ** (int(exp or 0) - decimals)


def _is_integer(token: str) -> bool:
    return token.lstrip("+-").isdigit()


def _fmt(x: float) -> str:
    return f"{x:.10g}"


class _Mismatch(Exception):
    pass


def _numbers_agree(want: str, got: str, kind, where: str, ess) -> None:
    a, b = float(want), float(got)
    if a == b or (math.isnan(a) and math.isnan(b)):
        return
    unit = max(_unit(want), _unit(got))
    if isinstance(kind, MonteCarlo):
        tol, what = kind.tolerance(ess) + unit, f"Monte Carlo {kind.what}"
    elif isinstance(kind, float):  # a report number marked as drawn (tolerance given)
        tol, what = kind, "drawn report number"
    elif _is_integer(want) and _is_integer(got):
        tol, what = 0.0, "deterministic integer"
    else:
        tol, what = kind.tolerance(a, b) + unit, "deterministic"
    if not abs(a - b) <= tol:
        rel = abs(a - b) / max(abs(a), abs(b))
        raise _Mismatch(
            f"{where}: expected {want}, got {got} ({what}: differs by {_fmt(abs(a - b))},"
            f" {rel:.1e} relative; allowed {_fmt(tol)})"
        )


def _split(text: str) -> tuple[list[str], list[str]]:
    """The words between the numbers, and the numbers."""
    return _NUMBER.split(text), _NUMBER.findall(text)


def _text_agrees(want: str, got: str, kind, where: str, ess=None, marks=None) -> None:
    """Same words in the same order, numbers compared by ``kind`` (or by ``marks``:
    number index -> tolerance, for the report's drawn numbers)."""
    if want == got:
        return
    ww, wn = _split(want)
    gw, gn = _split(got)
    if ww != gw:
        i = next(
            (k for k, (x, y) in enumerate(zip(ww, gw, strict=False)) if x != y),
            min(len(ww), len(gw)),
        )
        line = "".join(ww[:i] + wn[:i]).count("\n") + 1
        x = ww[i] if i < len(ww) else "<end>"
        y = gw[i] if i < len(gw) else "<end>"
        raise _Mismatch(f"{where} (line {line}): words differ: expected {x[:80]!r}, got {y[:80]!r}")
    for k, (a, b) in enumerate(zip(wn, gn, strict=True)):
        here = kind
        if marks is not None and str(k) in marks:
            here = marks[str(k)] + 2 * max(_unit(a), _unit(b))
        line = "".join(ww[: k + 1]).count("\n") + sum(n.count("\n") for n in wn[:k]) + 1
        _numbers_agree(a, b, here, f"{where} (line {line}, number {k + 1})", ess)


def _compare_csv(name: str, want: str, got: str, ess, base) -> None:
    # comment lines (a probe file's "# ..." title) are compared as text
    wc = [x for x in want.splitlines() if x.startswith("#")]
    gc = [x for x in got.splitlines() if x.startswith("#")]
    if wc != gc:
        _text_agrees("\n".join(wc), "\n".join(gc), base, f"{name} comments", ess)
    want = "\n".join(x for x in want.splitlines() if not x.startswith("#"))
    got = "\n".join(x for x in got.splitlines() if not x.startswith("#"))
    wr, gr = list(csv.reader(io.StringIO(want))), list(csv.reader(io.StringIO(got)))
    if not wr or not gr or wr[0] != gr[0]:
        raise _Mismatch(f"{name}: header differs: {wr[:1]} vs {gr[:1]}")
    if len(wr) != len(gr):
        raise _Mismatch(f"{name}: {len(wr) - 1} rows recorded, {len(gr) - 1} written")
    header, rules = wr[0], _MC_COLUMNS.get(name, {})
    for r, (wrow, grow) in enumerate(zip(wr[1:], gr[1:], strict=True), start=2):
        if len(wrow) != len(grow):
            raise _Mismatch(f"{name} line {r}: {len(wrow)} fields recorded, {len(grow)} written")
        if len(wrow) != len(header):
            raise _Mismatch(f"{name} line {r}: {len(wrow)} fields, the header has {len(header)}")
        for col, a, b in zip(header, wrow, grow, strict=True):
            kind = base
            if col in rules and _NUMBER.fullmatch(a or "x"):
                stat, spread = rules[col]
                s = float(wrow[header.index(spread)]) if spread else float(a)
                if stat == "corr":
                    c, s = 1.0 - float(a) ** 2, 1.0
                else:
                    c = MC_FACTORS[stat]
                kind = MonteCarlo(c, s, stat)
            _text_agrees(a, b, kind, f"{name} line {r}, column {col}", ess)


def _compare_json(name: str, want, got, ess, base, path=(), root=None) -> None:
    root = want if root is None else root
    where = f"{name} {'.'.join(map(str, path)) or '(top)'}"
    if isinstance(want, dict):
        if not isinstance(got, dict) or list(want) != list(got):
            missing = sorted(set(want) - set(got or {}))
            extra = sorted(set(got or {}) - set(want))
            raise _Mismatch(f"{where}: keys differ (missing {missing}, new {extra})")
        for k in want:
            _compare_json(name, want[k], got[k], ess, base, (*path, k), root)
    elif isinstance(want, list):
        if not isinstance(got, list) or len(want) != len(got):
            raise _Mismatch(f"{where}: {len(want)} items recorded, {len(got)} written")
        for i, (a, b) in enumerate(zip(want, got, strict=True)):
            _compare_json(name, a, b, ess, base, (*path, i), root)
    elif isinstance(want, bool) or want is None:
        if want != got:
            raise _Mismatch(f"{where}: expected {want!r}, got {got!r}")
    elif isinstance(want, int | float):
        if isinstance(got, bool) or not isinstance(got, int | float):
            raise _Mismatch(f"{where}: expected the number {want!r}, got {got!r}")
        if isinstance(want, int) and isinstance(got, int):
            if want != got:
                raise _Mismatch(f"{where}: expected {want}, got {got} (an integer)")
            return
        kind = _mc_json(path, float(want), root) if name == "toolpath_bounds.json" else None
        _numbers_agree(repr(float(want)), repr(float(got)), kind or base, where, ess)
    elif isinstance(want, str):
        if not isinstance(got, str):
            raise _Mismatch(f"{where}: expected text, got {got!r}")
        _text_agrees(masked(want), masked(got), base, where, ess)
    else:  # pragma: no cover - json gives no other types
        raise TypeError(type(want))


def compare_text_file(
    name: str, want: str, got: str, ess=(math.inf, math.inf), base: Deterministic = DETERMINISTIC
) -> list[str]:
    """Differences of one text output against its recorded text (empty: equal): CSV by
    column, JSON by key, other text by words and numbers; ``base`` the tolerance of
    the deterministic numbers, ``ess`` the effective sample sizes (recorded, now) of
    the Monte Carlo ones."""
    try:
        if name.endswith(".csv"):
            _compare_csv(name, want, got, ess, base)
        elif name.endswith(".json"):
            _compare_json(name, json.loads(want), json.loads(got), ess, base)
        else:
            _text_agrees(masked(want), masked(got), base, name, ess)
    except _Mismatch as e:
        return [str(e)]
    return []


# ---------------------------------------------------------------- reports, containers


def masked(text: str) -> str:
    for pattern, repl in _MASKS:
        text = pattern.sub(repl, text)
    return text


def _pdf_text(path: Path) -> str:
    from pypdf import PdfReader

    return "\n\f".join(page.extract_text() or "" for page in PdfReader(path).pages)


def report_text(path: Path) -> str:
    """What is compared of a report: the HTML without its embedded pictures; the PDF's
    text without page footers, whitespace collapsed (where a line wraps and a page
    breaks follows the widths of masked numbers: a 100 s step widens the wall-time
    table), one paragraph per line. Time stamps and wall times masked."""
    if path.suffix == ".html":
        return masked(_IMAGE.sub('src="<figure>"', path.read_text(encoding="utf-8")))
    text = _FOOTER.sub("", masked(_pdf_text(path)))
    # masked again once the lines are joined: a slow run's wider numbers move a line
    # break between a number and its unit ("102.4 s\nsampling")
    return masked(" ".join(text.split()))


def _draw_summary(values) -> dict:
    import numpy as np

    v = np.asarray(values, dtype=np.float64)
    flat = v.reshape(v.shape[0] * v.shape[1], -1) if v.ndim >= 2 else v.reshape(-1, 1)
    return {
        "mean": [float(x) for x in flat.mean(axis=0)],
        "sd": [float(x) for x in flat.std(axis=0, ddof=1)],
    }


#: posterior.nc attributes that time the run, and those that are sampler estimates
_NC_TIMINGS = {"created_at", "wall_time_s"}
_NC_ESTIMATES = {
    "rhat": ("abs", 0.01),
    "ess_bulk": ("rel", 0.25),
    "tau_steps": ("rel", 0.25),
    "thin": ("rel", 0.25),
}
_NC_DETERMINISTIC_GROUPS = {"observed_data", "constant_data"}


def container_summary(path: Path) -> dict:
    """posterior.nc as compared: every group's attributes, dims, and variables (dims,
    shape, dtype, attributes) and their values: draws (chain, draw, ...) as mean and
    sd per element, everything else as its values."""
    import h5netcdf
    import numpy as np

    def attrs(obj) -> dict:
        return {
            k: (v.tolist() if hasattr(v, "tolist") else v)
            for k, v in sorted(obj.attrs.items())
            if k not in _NC_TIMINGS and k != "_FillValue"
        }

    def group(g) -> dict:
        out = {"attrs": attrs(g), "dims": {k: d.size for k, d in g.dimensions.items()}}
        out["variables"] = {}
        for name, var in g.variables.items():
            entry = {
                "dims": list(var.dimensions),
                "shape": list(var.shape),
                "dtype": str(var.dtype),
                "attrs": attrs(var),
            }
            data = var[...]
            if list(var.dimensions) == ["draw"]:
                pass  # the draw numbers 0..n-1: their count is in the shape
            elif var.dimensions[:2] == ("chain", "draw"):
                entry["draws"] = _draw_summary(data)
            elif np.issubdtype(np.asarray(data).dtype, np.number):
                entry["values"] = np.asarray(data, dtype=float).ravel().tolist()
            else:
                entry["values"] = [str(x) for x in np.asarray(data).ravel()]
            out["variables"][name] = entry
        out["groups"] = {n: group(sub) for n, sub in sorted(g.groups.items())}
        return out

    with h5netcdf.File(path, "r") as f:
        return group(f)


def container_ess(summary: dict) -> float:
    """The smallest bulk ESS of the posterior (its ``ess_bulk`` attribute)."""
    ess = summary["attrs"].get("ess_bulk")
    values = ess if isinstance(ess, list) else [ess]
    return float(min(values)) if ess is not None else math.inf


def _compare_container(want: dict, got: dict, ess, where: str = "posterior.nc") -> None:
    if list(want["dims"]) != list(got["dims"]) or any(
        not _same_size(d, n, got["dims"][d]) for d, n in want["dims"].items()
    ):
        raise _Mismatch(f"{where}: dims differ: {want['dims']} vs {got['dims']}")
    _compare_attrs(want["attrs"], got["attrs"], where)
    if list(want["variables"]) != list(got["variables"]):
        raise _Mismatch(
            f"{where}: variables differ: {list(want['variables'])} vs {list(got['variables'])}"
        )
    deterministic = where.rsplit("/", 1)[-1] in _NC_DETERMINISTIC_GROUPS
    for name, w in want["variables"].items():
        g, here = got["variables"][name], f"{where}/{name}"
        for key in ("dims", "dtype"):
            if w[key] != g[key]:
                raise _Mismatch(f"{here}: {key} differs: {w[key]} vs {g[key]}")
        if len(w["shape"]) != len(g["shape"]) or any(
            not _same_size(d, a, b)
            for d, a, b in zip(w["dims"], w["shape"], g["shape"], strict=True)
        ):
            raise _Mismatch(f"{here}: shape differs: {w['shape']} vs {g['shape']}")
        if w["dims"] == ["draw"]:
            continue  # the draw numbers 0..n-1: their count is compared above
        _compare_attrs(w["attrs"], g["attrs"], here)
        if "draws" in w:
            for k, (m0, m1, s0, s1) in enumerate(
                zip(
                    w["draws"]["mean"],
                    g["draws"]["mean"],
                    w["draws"]["sd"],
                    g["draws"]["sd"],
                    strict=True,
                )
            ):
                kind = DETERMINISTIC if deterministic else MonteCarlo(1.0, s0, "mean")
                _numbers_agree(repr(m0), repr(m1), kind, f"{here} element {k} mean", ess)
                kind = DETERMINISTIC if deterministic else MonteCarlo(1.0, s0, "sd")
                _numbers_agree(repr(s0), repr(s1), kind, f"{here} element {k} sd", ess)
        elif w["values"] != g["values"]:
            if len(w["values"]) != len(g["values"]):
                raise _Mismatch(f"{here}: values differ in length")
            for k, (a, b) in enumerate(zip(w["values"], g["values"], strict=True)):
                if isinstance(a, str) or isinstance(b, str):
                    if a != b:
                        raise _Mismatch(f"{here}[{k}]: expected {a!r}, got {b!r}")
                else:
                    _numbers_agree(repr(a), repr(b), DETERMINISTIC, f"{here}[{k}]", ess)
    if list(want["groups"]) != list(got["groups"]):
        raise _Mismatch(f"{where}: groups differ: {list(want['groups'])} vs {list(got['groups'])}")
    for name in want["groups"]:
        _compare_container(want["groups"][name], got["groups"][name], ess, f"{where}/{name}")


def _same_size(dim: str, a: int, b: int) -> bool:
    """A dimension's size is equal, but for the kept draws: their count follows the
    thinning, which follows the estimated autocorrelation time (within 25 %)."""
    return a == b or (dim == "draw" and abs(a - b) <= _NC_ESTIMATES["thin"][1] * a)


def _compare_attrs(want: dict, got: dict, where: str) -> None:
    if list(want) != list(got):
        raise _Mismatch(f"{where}: attributes differ: {sorted(set(want) ^ set(got))}")
    for k, a in want.items():
        b = got[k]
        if k in _NC_ESTIMATES:
            how, bound = _NC_ESTIMATES[k]
            xa, xb = (a if isinstance(a, list) else [a]), (b if isinstance(b, list) else [b])
            if len(xa) != len(xb):
                raise _Mismatch(f"{where} attribute {k}: {len(xa)} values vs {len(xb)}")
            for x, y in zip(xa, xb, strict=True):
                d = abs(float(x) - float(y))
                if d > (bound if how == "abs" else bound * abs(float(x))):
                    raise _Mismatch(
                        f"{where} attribute {k} (a sampler estimate): expected {x}, got {y},"
                        f" beyond {bound:g}{'' if how == 'abs' else ' relative'}"
                    )
        elif isinstance(a, str) and isinstance(b, str):
            _text_agrees(a, b, DETERMINISTIC, f"{where} attribute {k}")
        elif isinstance(a, list) and isinstance(b, list) and len(a) == len(b):
            for x, y in zip(a, b, strict=True):
                if isinstance(x, str) or isinstance(y, str):
                    if x != y:
                        raise _Mismatch(f"{where} attribute {k}: expected {x!r}, got {y!r}")
                else:
                    _numbers_agree(repr(x), repr(y), DETERMINISTIC, f"{where} attribute {k}", None)
        elif isinstance(a, float) and isinstance(b, float):
            _numbers_agree(repr(a), repr(b), DETERMINISTIC, f"{where} attribute {k}", None)
        elif a != b:
            raise _Mismatch(f"{where} attribute {k}: expected {a!r}, got {b!r}")


# ---------------------------------------------------------------- compare, record


def compare(name: str, actual: Path) -> list[str]:
    """Every difference between the recorded outputs of ``name`` and folder ``actual``,
    each naming the file, the place and the size of the first difference found."""
    expected = GOLDEN / name
    manifest = json.loads((expected / "manifest.json").read_text())
    problems = []
    summaries = {}
    for fname in CONTAINERS:
        if (actual / fname).exists():
            summaries[fname] = container_summary(actual / fname)
    ess_now = min((container_ess(s) for s in summaries.values()), default=math.inf)
    ess = (manifest.get("ess", math.inf), ess_now)
    for fname in manifest["files"]:
        source = _SOURCE.get(fname, fname)
        got = actual / source
        if not got.exists():
            problems.append(f"{source}: not written")
            continue
        want = (expected / fname).read_text(encoding="utf-8")
        try:
            if source in CONTAINERS:
                _compare_container(json.loads(want), summaries[source], ess)
            elif source in REPORTS:
                marks = manifest.get("report_marks", {}).get(fname, {})
                _text_agrees(want, report_text(got), DISPLAYED, source, ess, marks)
            else:
                problems += compare_text_file(fname, want, got.read_text(encoding="utf-8"), ess)
        except _Mismatch as e:
            problems.append(str(e))
    known = set(manifest["files"]) | BINARY
    extra = sorted(p.name for p in actual.iterdir() if p.name not in known)
    if extra:
        problems.append(f"files not in the golden set: {extra}")
    return problems


def fixtures(folder: Path) -> dict[str, str]:
    """The recorded form of every output of a run: text files as they are, reports
    as their compared text, containers as their summary."""
    out = {}
    for p in sorted(folder.iterdir()):
        if p.name in REPORTS:
            out[REPORTS[p.name]] = report_text(p)
        elif p.name in CONTAINERS:
            out[CONTAINERS[p.name]] = json.dumps(container_summary(p), indent=0) + "\n"
        else:
            out[p.name] = p.read_text(encoding="utf-8")
    return out


def report_marks(base: dict[str, str], others: list[dict[str, str]]) -> dict:
    """For each report text: number index -> ``REPORT_SPREAD`` times the largest move
    among the recordings of other seeds, for every number that moved."""
    marks = {}
    for fname in REPORTS.values():
        if fname not in base:
            continue
        words, numbers = _split(base[fname])
        moves = [0.0] * len(numbers)
        for other in others:
            w, n = _split(other[fname])
            if w != words:
                raise RuntimeError(f"{fname}: another seed changed the report's words")
            for k, (a, b) in enumerate(zip(numbers, n, strict=True)):
                moves[k] = max(moves[k], abs(float(a) - float(b)))
        marks[fname] = {str(k): REPORT_SPREAD * m for k, m in enumerate(moves) if m > 0}
    return marks


def record(name: str, folder: Path, others: list[Path]) -> None:
    """Record the run in ``folder`` as the golden outputs of ``name``; ``others``: runs
    of the same job with other seeds (they mark the report's drawn numbers)."""
    dest = GOLDEN / name
    dest.mkdir(parents=True, exist_ok=True)
    for old in dest.iterdir():
        old.unlink()
    files = fixtures(folder)
    for fname, text in files.items():
        (dest / fname).write_text(text, encoding="utf-8")
    manifest = {"versions": versions(), "files": sorted(files)}
    summaries = [json.loads(files[v]) for v in CONTAINERS.values() if v in files]
    if summaries:
        manifest["ess"] = min(container_ess(s) for s in summaries)
    manifest["report_marks"] = report_marks(files, [fixtures(o) for o in others])
    (dest / "manifest.json").write_text(json.dumps(manifest, indent=1) + "\n")


def versions() -> dict:
    return {p: version(p) for p in PACKAGES}


def version_mismatch(name: str) -> str | None:
    manifest = json.loads((GOLDEN / name / "manifest.json").read_text())
    now = versions()
    diff = {p: (v, now.get(p)) for p, v in manifest["versions"].items() if now.get(p) != v}
    if diff:
        return ", ".join(f"{p} {a} recorded, {b} installed" for p, (a, b) in diff.items())
    return None


if __name__ == "__main__" and "--record" in sys.argv:
    import os
    import tempfile

    os.environ.setdefault("MPLBACKEND", "Agg")
    os.environ.setdefault("JAX_PLATFORMS", "cpu")
    with tempfile.TemporaryDirectory() as tmp:
        for job, run in JOBS.items():
            base = run(Path(tmp) / job)
            others = [run(Path(tmp) / f"{job}-{s}", seed=s) for s in REPORT_SEEDS]
            record(job, base, others)
    print(f"recorded golden outputs under {GOLDEN}")
