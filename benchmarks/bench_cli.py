"""The user's fast path (issue 16): one part's fit against a SciPy loop, and the CLI warm.

    .venv/bin/python benchmarks/bench_cli.py              # both sections (~1 min)
    .venv/bin/python benchmarks/bench_cli.py --only a     # the per-part fit only
    .venv/bin/python benchmarks/bench_cli.py --repeat 5   # more CLI runs

Sections (Markdown tables; every ratio is measured in this one run, the contenders
interleaved round by round (a block of calls each), so a loaded machine slows
all sides alike):

- (a) one robust fit of the demo part (7 features, 54 points, a chip on dia_30):
  `jobs.fit_study` (the CLI's and the main job's fit: the batch kernel, one
  compiled call per part), the per-feature loop it replaced
  (`fit_profile(solver="lm")`), `fit_profiles` on the one part, against a
  `scipy.optimize.least_squares` loop over the features (the same model, Huber
  loss, scale and tolerances as `bench_scale.py` (a)); minimum and median of the
  rounds; results checked equal;
- (b) wall time of `piecs-bayes --help` and of `piecs-bayes fit
  data/demo/study.toml` warm (the persistent caches filled by a first run), the
  minimum of `--repeat` runs, and the import time of `piecs_bayes.cli` and of
  `piecs_bayes.jobs`.
"""

from __future__ import annotations

import argparse
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("MPLBACKEND", "Agg")
ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from _fmt import load, ms, table  # noqa: E402

DEMO = ROOT / "data" / "demo" / "study.toml"
CLI = [sys.executable, "-m", "piecs_bayes.cli"]


def section_a(args) -> dict:
    from dataclasses import replace

    import numpy as np
    from bench_scale import scipy_part

    from piecs_bayes.fit import BatchOptions, fit_profile, fit_profiles, to_part_frame
    from piecs_bayes.io import load_study
    from piecs_bayes.jobs import fit_options, fit_study, load_probe_data, robust_scale

    print(f"\n## (a) One robust part fit vs scipy.optimize.least_squares\n\n{load()}\n")
    study = load_study(DEMO)
    probe = load_probe_data(study)
    centres = to_part_frame(study.transform, probe.points)
    rb, scale = study.probe.ball_radius, robust_scale(study)
    opts = fit_options(study, "robust")
    loop_opts = replace(opts, solver="lm")
    parts = np.full(len(probe), probe.parts[0])
    contenders = {
        "scipy least_squares loop, analytic Jacobian (trf, huber)": lambda: scipy_part(
            study.profile, probe.feature, centres, rb, scale
        ),
        "piecs_bayes jobs.fit_study (the CLI's fit: batch kernel, one call)": lambda: fit_study(
            study, probe
        ),
        "piecs_bayes fit_profile, per-feature loop (before)": lambda: fit_profile(
            study.profile,
            probe.feature,
            centres,
            ball_radius=rb,
            options=loop_opts,
            lines=probe.lines,
        ),
        "piecs_bayes fit_profiles, one part (batch_size=8)": lambda: fit_profiles(
            study.profile,
            parts,
            probe.feature,
            centres,
            ball_radius=rb,
            options=opts,
            batch=BatchOptions(batch_size=8),
            lines=probe.lines,
        ),
    }
    first = {}
    for name, fn in contenders.items():  # compile (or load the persisted traces)
        t0 = time.perf_counter()
        fn()
        first[name] = time.perf_counter() - t0
    times: dict[str, list[float]] = {name: [] for name in contenders}
    for _ in range(args.rounds):
        for name, fn in contenders.items():  # a block of calls each: a user's warm loop
            for _ in range(args.block):
                t0 = time.perf_counter()
                fn()
                times[name].append(time.perf_counter() - t0)
    ref_name = next(iter(contenders))
    t_min_sp, t_med_sp = min(times[ref_name]), statistics.median(times[ref_name])
    rows = []
    for name, ts in times.items():
        lo, med = min(ts), statistics.median(ts)
        rows.append([name, ms(lo), ms(med), f"{t_min_sp / lo:.2f}x", f"{t_med_sp / med:.2f}x"])
    print(table(rows, ["per part (7 features, 54 points)", "min", "median", "speed (min)",
                        "speed (median)"]))  # fmt: skip
    fit = fit_study(study, probe)
    loop = fit_profile(
        study.profile, probe.feature, centres, ball_radius=rb, options=loop_opts, lines=probe.lines
    )
    ref = scipy_part(study.profile, probe.feature, centres, rb, scale)
    d_loop = max(float(np.max(np.abs(fit[k].values - loop[k].values))) for k in fit.fits)
    d_se = max(float(np.max(np.abs(fit[k].std_errors / loop[k].std_errors - 1))) for k in fit.fits)
    d_sp = max(float(np.max(np.abs(fit[k].values - v))) for k, v in ref.items())
    print(
        f"\n{args.rounds} rounds of {args.block} calls each. First calls (compilation or "
        "persisted traces): "
        + ", ".join(f"{n.split(' (')[0]} {t:.2f} s" for n, t in first.items())
        + f".\nResults: |fit_study - loop| <= {d_loop:.1e} mm/rad, standard errors to "
        f"{d_se:.1e} relative; |fit_study - scipy| <= {d_sp:.1e}."
    )
    return {"times": times}


def _wall(cmd, env=None) -> float:
    t0 = time.perf_counter()
    subprocess.run(cmd, check=True, cwd=ROOT, env=env, stdout=subprocess.DEVNULL)
    return time.perf_counter() - t0


def _import_time(module: str) -> float:
    code = f"import time; t = time.perf_counter(); import {module}; print(time.perf_counter() - t)"
    out = subprocess.run([sys.executable, "-c", code], check=True, capture_output=True, text=True)
    return float(out.stdout.strip())


def section_b(args) -> dict:
    print(f"\n## (b) The command line, warm\n\n{load()}\n")
    with tempfile.TemporaryDirectory() as tmp:
        fit_cmd = [*CLI, "fit", str(DEMO), "--out", tmp, "--quiet"]
        t_first = _wall(fit_cmd)  # fills the caches if they are empty
        help_t = [_wall([*CLI, "--help"]) for _ in range(args.repeat)]
        fit_t = [_wall(fit_cmd) for _ in range(args.repeat)]
    imports = {m: min(_import_time(m) for _ in range(args.repeat))
               for m in ("piecs_bayes.cli", "piecs_bayes.jobs")}  # fmt: skip
    rows = [
        ["piecs-bayes --help", ms(min(help_t)), ms(statistics.median(help_t))],
        [
            "piecs-bayes fit data/demo/study.toml (warm)",
            ms(min(fit_t)),
            ms(statistics.median(fit_t)),
        ],  # fmt: skip
        *[[f"import {m}", ms(t), ""] for m, t in imports.items()],
    ]
    print(table(rows, ["command", f"min of {args.repeat}", "median"]))
    print(f"\nFirst `fit` of this run (caches as found): {t_first:.2f} s.")
    return {"help": help_t, "fit": fit_t, "imports": imports}


def main(argv=None) -> None:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", default="a,b", help="sections, comma-separated (a, b)")
    p.add_argument("--rounds", type=int, default=5, help="(a) rounds of every contender")
    p.add_argument("--block", type=int, default=10, help="(a) calls per contender and round")
    p.add_argument("--repeat", type=int, default=3, help="(b) runs of each command")
    args = p.parse_args(argv)
    only = set(args.only.split(","))
    if "a" in only:
        section_a(args)
    if "b" in only:
        section_b(args)


if __name__ == "__main__":
    main()
