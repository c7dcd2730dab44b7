"""First contact (issue 39): what a new user waits for, on a fresh folder with an empty cache.

    .venv/bin/python benchmarks/bench_first_contact.py            # everything (~20 min)
    .venv/bin/python benchmarks/bench_first_contact.py --no-suite # the CLI only (~3 min)

In one run, with `XDG_CACHE_HOME` a new empty folder (no JAX compilation cache, no
persisted traces; what a new machine has), each against its target:

- the suite's tiers: `make test` (every behaviour) and the slow tier (`pytest -m
  slow`: the full-power statistical checks, the notebooks executed) with the workers
  `make test` uses (one per usable core: `make workers`), wall time and
  the executables JAX built and XLA compiled (the line `tests/conftest.py` prints);
- `piecs-bayes demo` on the demo study cold (first run: it compiles) and warm, and the
  compiled executables the cold run left in the cache;
- the report alone: `report_files` on the demo's job result in a fresh process, the
  cache warm (figures, HTML, PDF), the process set up as `report` and `demo` set it up
  (the report's modules imported and its drawing helper started while the job runs);
  the minimum and the median of `--repeat` runs (one run varies by +-0.5 s here);
- `piecs-bayes fit data/demo/study.toml` warm and `piecs-bayes --help`: the minimum of
  `--repeat` runs.

The suite runs first (it is what `make test` costs a new user: its cache is empty);
the demo then starts from another empty cache.
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _fmt import load, table  # noqa: E402

PY = ROOT / ".venv" / "bin" / "python"
CLI = [str(PY), "-m", "piecs_bayes.cli"]
DEMO = ROOT / "data" / "demo" / "study.toml"
#: the targets of issue 39 (seconds)
TARGETS = {
    "make test": 300.0,
    "slow tier": None,
    "demo cold": 40.0,
    "demo warm": 20.0,
    "report alone (warm, min)": 5.0,
    "fit warm (min)": 1.0,
    "--help (min)": 0.2,
}
_JAX_LINE = re.compile(r"jax: (\d+) executables built, (\d+) compiled by XLA")
_REPORT = """
import sys, time
from piecs_bayes.cli._common import prefetch_imports
from piecs_bayes.export.raster import start_helper
prefetch_imports(), start_helper()  # as `report` and `demo` do while the job runs
from piecs_bayes.jobs import JobOptions, run_job
res = run_job(sys.argv[1], JobOptions(), progress=False)
from piecs_bayes.export.report import report_files
t0 = time.perf_counter()
html, pdf = report_files(res)
print(f"REPORT {time.perf_counter() - t0:.3f} {len(pdf)}")
"""


def _env(cache: Path) -> dict:
    return {**os.environ, "XDG_CACHE_HOME": str(cache), "JAX_PLATFORMS": "cpu",
            "MPLBACKEND": "Agg", "OPENBLAS_NUM_THREADS": "1"}  # fmt: skip


def _timed(cmd, env, cwd=ROOT) -> tuple[float, str]:
    t0 = time.perf_counter()
    proc = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        sys.exit(f"{' '.join(map(str, cmd))} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
    return wall, proc.stdout + proc.stderr


def _workers() -> str:
    """The pytest workers `make test` uses on this machine (`make workers`): one per
    usable core, as many as memory holds."""
    done = subprocess.run(["make", "-s", "workers"], cwd=ROOT, capture_output=True, text=True)
    return done.stdout.strip() if done.returncode == 0 and done.stdout.strip() else "2"


def _compilations(output: str) -> str:
    m = _JAX_LINE.search(output)
    return f"{m.group(1)} built, {m.group(2)} by XLA" if m else "-"


def _cache_entries(cache: Path) -> int:
    jax_dir = cache / "piecs_bayes" / "jax"
    return sum(1 for p in jax_dir.iterdir() if p.is_file()) if jax_dir.is_dir() else 0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--no-suite", action="store_true", help="skip the two test tiers")
    ap.add_argument("--repeat", type=int, default=5,
                    help="runs of the report, fit and --help (minimum)")  # fmt: skip
    args = ap.parse_args()
    rows = []

    def row(name, wall, compiled="-"):
        target = TARGETS[name]
        verdict = "-" if target is None else ("met" if wall <= target else "NOT met")
        rows.append((name, f"{wall:.2f}", "-" if target is None else f"{target:g}", verdict,
                     compiled))  # fmt: skip
        print(f"{name}: {wall:.2f} s", flush=True)

    work = Path(tempfile.mkdtemp(prefix="first_contact_"))
    try:
        if not args.no_suite:
            cache = work / "suite-cache"
            pytest = [str(PY), "-m", "pytest", "-q", "-n", _workers(), "--dist", "worksteal",
                      "-p", "no:cacheprovider"]  # fmt: skip
            wall, out = _timed([*pytest, "-m", "not slow"], _env(cache))
            row("make test", wall, _compilations(out))
            wall, out = _timed([*pytest, "-m", "slow"], _env(cache))
            row("slow tier", wall, _compilations(out))
        cache = work / "cli-cache"
        env = _env(cache)
        wall, _ = _timed([*CLI, "demo", str(DEMO), "-q", "--out", str(work / "demo1")], env)
        row("demo cold", wall, f"{_cache_entries(cache)} in the cache")
        wall, _ = _timed([*CLI, "demo", str(DEMO), "-q", "--out", str(work / "demo2")], env)
        row("demo warm", wall, f"{_cache_entries(cache)} in the cache")
        reports = [re.search(r"REPORT (\S+) (\d+)", _timed([str(PY), "-c", _REPORT,
                                                           str(DEMO)], env)[1]).groups()
                   for _ in range(args.repeat)]  # fmt: skip
        seconds = sorted(float(r[0]) for r in reports)
        mb, median = int(reports[0][1]) / 1e6, seconds[len(seconds) // 2]
        row("report alone (warm, min)", seconds[0], f"PDF {mb:.1f} MB; median {median:.2f} s")
        fits = [_timed([*CLI, "fit", str(DEMO), "-q", "--out", str(work / "fit")], env)[0]
                for _ in range(args.repeat)]  # fmt: skip
        row("fit warm (min)", min(fits))
        helps = [_timed([*CLI, "--help"], env)[0] for _ in range(args.repeat)]
        row("--help (min)", min(helps))
    finally:
        shutil.rmtree(work, ignore_errors=True)
    print()
    print(table(rows, ("what", "wall s", "target s", "", "compilations")))
    print(f"{os.cpu_count()} CPUs; {load()}")


if __name__ == "__main__":
    main()
