"""Speed and scale, side by side with what a user would otherwise write (issue 8).

    .venv/bin/python benchmarks/bench_scale.py                  # everything (~10 min)
    .venv/bin/python benchmarks/bench_scale.py --only a,b --parts 2000
    .venv/bin/python benchmarks/bench_scale.py --quick          # small sizes, a smoke run

Sections (Markdown tables; every ratio is measured in this one run, so a loaded
machine slows both sides alike):

- (a) one robust part fit (the demo part, 7 features, a chip on dia_30) against a
  `scipy.optimize.least_squares` loop over its features: same model (ball-centre
  signed distances), same Huber loss and scale, same tolerances (1e-10);
  results checked equal;
- (b) a fleet of `--parts` parts (default 10,000): `fit_profiles` against the same
  SciPy loop (timed on `--scipy-sample` parts and extrapolated, as it says), and
  the whole capability computation; peak memory (RSS) of a process that does only
  this;
- (c) emcee with the JAX log posterior (jitted, vmapped, `vectorize=True`) against
  emcee with a NumPy log posterior of the same posterior (checked equal), in
  effective samples per second; the lockstep ensembles of `sample_posteriors` for
  1 and 16 parts;
- (d) NumPyro NUTS (the `bench` extra) on the same posterior, every sampler side by
  side (compilation, warm-up and sampling timed apart, one ESS estimator) and
  checked to sample the same posterior (skipped when numpyro is missing); (c) and
  (d) live in `_bench_sampling.py`;
- (e) `piecs-bayes fit data/demo/study.toml`: cold (empty cache), warm (persistent
  compilation cache), without the cache; import times;
- (f) cost against points per feature (8 to 4,096, per fit and per point, beside the
  SciPy loop on the same parts) and against number of parts (tables and a
  log-log plot written to `--plot`, default `reports/bench_scaling.png`).
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(Path(__file__).resolve().parent))

import numpy as np  # noqa: E402
from _bench_sampling import DEMO, section_cd  # noqa: E402
from _common import load, machine_line, simulate_fleet, timeit  # noqa: E402
from _fmt import ms, table  # noqa: E402

import piecs_bayes  # noqa: E402,F401
from piecs_bayes.fit import (  # noqa: E402
    BatchOptions,
    FitOptions,
    fit_profile,
    fit_profiles,
    to_part_frame,
)

#: the fleet's robust fit (Huber, the demo probe's 1.5 um repeatability)
ROBUST = FitOptions(method="robust", loss="huber", scale=1.345 * 0.0015)
from piecs_bayes.io import load_study  # noqa: E402
from piecs_bayes.jobs import fit_study, load_probe_data, robust_scale  # noqa: E402
from piecs_bayes.simulate import DEMO_TRANSFORM  # noqa: E402

TOL = 1e-10


# --------------------------------------------------------------------------- SciPy peer


def _scipy_feature(f, pts, rb, scale, *, jac=True):
    """The feature fit a SciPy user writes: same residuals, Huber loss and scale."""
    from scipy.optimize import least_squares

    if f.kind == "line":
        mid, nrm = np.asarray(f.midpoint), np.asarray(f.normal)

        def res(y):
            c, s = np.cos(y[1]), np.sin(y[1])
            rn = np.array([c * nrm[0] + s * nrm[1], -s * nrm[0] + c * nrm[1]])
            return (pts - mid - y[0] * nrm) @ rn - rb

        def jacf(y):
            c, s = np.cos(y[1]), np.sin(y[1])
            rn = np.array([c * nrm[0] + s * nrm[1], -s * nrm[0] + c * nrm[1]])
            drn = np.array([-s * nrm[0] + c * nrm[1], -c * nrm[0] - s * nrm[1]])
            return np.column_stack([np.full(len(pts), -(nrm @ rn)), (pts - mid - y[0] * nrm) @ drn])

        x0 = np.zeros(2)
    else:
        cen, rad, sense = np.asarray(f.center), float(f.radius), float(f.sense)

        def res(y):
            v = pts - cen - y[:2]
            return sense * (np.sqrt(np.sum(v * v, axis=1)) - (rad + y[2])) - rb

        def jacf(y):
            v = pts - cen - y[:2]
            r = np.sqrt(np.sum(v * v, axis=1))
            return sense * np.column_stack([-v[:, 0] / r, -v[:, 1] / r, -np.ones(len(pts))])

        x0 = np.zeros(3)
    out = least_squares(
        res,
        x0,
        jac=jacf if jac else "2-point",
        loss="huber",
        f_scale=scale,
        ftol=TOL,
        xtol=TOL,
        gtol=TOL,
    )
    return out.x


def scipy_part(profile, features, centres, rb, scale, *, jac=True):
    return {
        f.id: _scipy_feature(f, centres[features == f.id], rb, scale, jac=jac)
        for f in profile.features
        if np.any(features == f.id)
    }


# --------------------------------------------------------------------------- (a)


def section_a(args):
    print(f"\n## (a) One robust part fit vs scipy.optimize.least_squares\n\n{load()}\n")
    study = load_study(DEMO)
    probe = load_probe_data(study)
    centres = to_part_frame(study.transform, probe.points)
    rb, scale = study.probe.ball_radius, robust_scale(study)
    kw = dict(ball_radius=rb, options=FitOptions(method="robust", loss="huber", scale=scale),
              lines=probe.lines)  # fmt: skip
    parts = np.full(len(probe), "part01")

    def ours_batch():
        return fit_profiles(study.profile, parts, probe.feature, centres,
                            batch=BatchOptions(batch_size=8), **kw)  # fmt: skip

    t0 = time.perf_counter()
    fit = fit_study(study, probe)
    t_compile_loop = time.perf_counter() - t0
    t0 = time.perf_counter()
    batch = ours_batch()
    t_compile_batch = time.perf_counter() - t0
    n = 5 if args.quick else 20
    t_loop = timeit(lambda: fit_study(study, probe), repeat=n)
    t_batch = timeit(ours_batch, repeat=n)
    t_sp = timeit(lambda: scipy_part(study.profile, probe.feature, centres, rb, scale), repeat=n)
    t_sp2 = timeit(
        lambda: scipy_part(study.profile, probe.feature, centres, rb, scale, jac=False), repeat=n
    )
    ref = scipy_part(study.profile, probe.feature, centres, rb, scale)
    d_abs = max(float(np.max(np.abs(fit[k].values - v))) for k, v in ref.items())
    d_se = max(float(np.max(np.abs(fit[k].values - v) / fit[k].std_errors)) for k, v in ref.items())
    d_b = max(float(np.max(np.abs(batch.values(k)[0] - fit[k].values))) for k in fit.fits)
    rows = [
        ["scipy least_squares loop, analytic Jacobian (trf, huber)", t_sp],
        ["scipy least_squares loop, default 2-point Jacobian", t_sp2],
        ["piecs_bayes fit_study / fit_profile (per-feature API)", t_loop],
        ["piecs_bayes fit_profiles, one part (batch_size=8)", t_batch],
    ]
    rows = [[label, ms(t), f"{t_sp / t:.2f}x"] for label, t in rows]
    print(table(rows, ["per part (7 features, 54 points)", "time", "speed vs scipy"]))
    print(
        f"\nFirst call (compilation, persistent cache as found): fit_study {t_compile_loop:.1f} s, "
        f"fit_profiles {t_compile_batch:.1f} s. Results: |piecs_bayes - scipy| <= {d_abs:.1e} "
        f"mm/rad = {d_se:.1e} standard errors; |batch - fit_study| <= {d_b:.1e}."
    )
    return {"t_scipy": t_sp, "t_loop": t_loop, "t_batch": t_batch}


# --------------------------------------------------------------------------- (b)


def _child_b(n_parts: int) -> dict:
    """Runs in a fresh process: simulate, fit, characterise; reports times and peak RSS."""
    from piecs_bayes.jobs import capability_job  # noqa: F401
    from piecs_bayes.uncertainty import characteristic_arrays  # noqa: F401

    fleet = simulate_fleet(n_parts, seed=1)
    centres = to_part_frame(DEMO_TRANSFORM, fleet["points"])
    rss0 = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    kw = dict(ball_radius=1.0, options=ROBUST)
    warm = np.isin(fleet["part"], np.unique(fleet["part"])[:256])
    # first run: compiles everything it meets (the kernel, and the engine's LM for the
    # retries of the problems the kernel did not solve); the second is timed
    t0 = time.perf_counter()
    fit_profiles(fleet["profile"], fleet["part"], fleet["feature"], centres, **kw)
    t_compile = time.perf_counter() - t0
    t0 = time.perf_counter()
    batch = fit_profiles(fleet["profile"], fleet["part"], fleet["feature"], centres, **kw)
    t_fit = time.perf_counter() - t0
    t_compile -= t_fit
    t0 = time.perf_counter()
    for fid in batch.feature_ids:
        characteristic_arrays(batch, fid, at="mid")
    t_char = time.perf_counter() - t0
    lm_n = min(n_parts, 1000)
    lm_sel = np.isin(fleet["part"], np.unique(fleet["part"])[:lm_n])
    lm = dict(kw, options=replace(ROBUST, solver="lm"))
    fit_profiles(fleet["profile"], fleet["part"][warm], fleet["feature"][warm], centres[warm],
                 **lm)  # fmt: skip
    t0 = time.perf_counter()
    fit_profiles(fleet["profile"], fleet["part"][lm_sel], fleet["feature"][lm_sel],
                 centres[lm_sel], **lm)  # fmt: skip
    t_lm = (time.perf_counter() - t0) * n_parts / lm_n
    lines = [f for f in batch.feature_ids if batch.profile[f].kind == "line"]
    err = np.concatenate([np.abs(batch.values(f) - fleet["truth"][f])[:, 0] for f in lines])
    truth_err = float(np.nanpercentile(err, 99))
    return {
        "n_parts": n_parts,
        "t_compile": t_compile,
        "t_fit": t_fit,
        "t_char": t_char,
        "t_lm": t_lm,
        "lm_n": lm_n,
        "failures": len(batch.failures),
        "outliers": int(sum(batch.n_outliers(f).sum() for f in batch.feature_ids)),
        "truth_err": truth_err,
        "rss_fit_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        "rss_before_fit_mb": rss0 / 1024,
    }


def _child_b_stream(n_parts: int, chunk: int = 10_000) -> dict:
    """Runs in a fresh process: the same fleet made and fitted `chunk` parts at a time
    (what `capability` does with `fit.CHUNK_PARTS`), only each part's characteristic
    values kept; reports the time and the peak RSS."""
    from piecs_bayes.uncertainty import characteristic_arrays

    kw = dict(ball_radius=1.0, options=ROBUST)
    values, t_fit, t0_all = [], 0.0, time.perf_counter()
    for k, lo in enumerate(range(0, n_parts, chunk)):
        fleet = simulate_fleet(min(chunk, n_parts - lo), seed=100 + k)
        centres = to_part_frame(DEMO_TRANSFORM, fleet["points"])
        t0 = time.perf_counter()
        batch = fit_profiles(fleet["profile"], fleet["part"], fleet["feature"], centres, **kw)
        values.append([characteristic_arrays(batch, f, at="mid")[0] for f in batch.feature_ids])
        t_fit += time.perf_counter() - t0
        del batch, fleet, centres
    return {
        "n_parts": n_parts,
        "chunk": chunk,
        "t_fit": t_fit,
        "t_all": time.perf_counter() - t0_all,
        "rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
    }


def section_b(args):
    n = args.parts
    print(f"\n## (b) {n} parts batched vs a scipy loop\n\n{load()} (start)\n")
    out = subprocess.run(
        [sys.executable, __file__, "--child-b", str(n)], capture_output=True, text=True
    )
    if out.returncode:
        print(out.stderr[-3000:])
        raise SystemExit("(b) child failed")
    res = json.loads(out.stdout.strip().splitlines()[-1])
    fleet = simulate_fleet(args.scipy_sample, seed=1)
    centres = to_part_frame(DEMO_TRANSFORM, fleet["points"])
    t0 = time.perf_counter()
    ref = {}
    for p in np.unique(fleet["part"]):
        m = fleet["part"] == p
        ref[p] = scipy_part(fleet["profile"], fleet["feature"][m], centres[m], 1.0, 1.345 * 0.0015)
    t_sp = (time.perf_counter() - t0) / args.scipy_sample
    kw = dict(ball_radius=1.0, options=ROBUST)
    batch = fit_profiles(fleet["profile"], fleet["part"], fleet["feature"], centres, **kw)
    diff = max(
        float(np.max(np.abs(batch.values(f)[batch.parts.index(p)] - v)))
        for p, r in ref.items()
        for f, v in r.items()
    )
    sp_total = t_sp * n
    rows = [
        [f"scipy loop (timed on {args.scipy_sample} parts, x{n / args.scipy_sample:g})",
         ms(sp_total), ms(t_sp), "1.0x"],
        ["fit_profiles, solver='auto' (batch kernel, LM retries)", ms(res["t_fit"]),
         ms(res["t_fit"] / n), f"{sp_total / res['t_fit']:.1f}x"],
        [f"fit_profiles, solver='lm' (timed on {res['lm_n']} parts, scaled)", ms(res["t_lm"]),
         ms(res["t_lm"] / n), f"{sp_total / res['t_lm']:.1f}x"],
        ["+ characteristics of all features (capability values)", ms(res["t_char"]),
         ms(res["t_char"] / n), ""],
    ]  # fmt: skip
    out_s = subprocess.run(
        [sys.executable, __file__, "--child-b-stream", str(n)], capture_output=True, text=True
    )
    if out_s.returncode:
        print(out_s.stderr[-3000:])
        raise SystemExit("(b) streamed child failed")
    res_s = json.loads(out_s.stdout.strip().splitlines()[-1])
    rows.append([f"streamed: made and fitted {res_s['chunk']} parts at a time, values kept "
                 f"(peak RSS {res_s['rss_mb']:.0f} MiB)", ms(res_s["t_fit"]),
                 ms(res_s["t_fit"] / n), f"{sp_total / res_s['t_fit']:.1f}x"])  # fmt: skip
    res["stream"] = res_s
    print(table(rows, [f"{n} parts x 7 features, robust", "total", "per part", "speed"]))
    print(
        f"\nCompilation (first run minus second, cache as found): {res['t_compile']:.1f} s, "
        f"not included. {res['failures']} fits failed (reported by status); "
        f"{res['outliers']} outliers flagged (chips and 3-sigma noise); 99th percentile of "
        f"|line offset - truth| {res['truth_err'] * 1e3:.2f} um (probe noise 1.5 um); "
        f"batch vs scipy on the sample: <= {diff:.1e} "
        f"mm/rad. Peak RSS of a process that simulates {n} parts and fits them: "
        f"{res['rss_fit_mb']:.0f} MiB (of which {res['rss_before_fit_mb']:.0f} MiB before the "
        f"fits: Python, JAX, the simulated data). {load()} (end)"
    )
    return res


# --------------------------------------------------------------------------- (e)


def _cli(cache: str | None, out: str) -> float:
    env = dict(os.environ)
    env.pop("PIECS_BAYES_NO_CACHE", None)
    if cache is None:
        env["PIECS_BAYES_NO_CACHE"] = "1"
    else:
        env["XDG_CACHE_HOME"] = cache
    exe = str(Path(sys.executable).with_name("piecs-bayes"))
    t0 = time.perf_counter()
    subprocess.run([exe, "fit", str(DEMO), "--out", out, "-q"], check=True, env=env)
    return time.perf_counter() - t0


def _import_time(module: str) -> float:
    out = subprocess.run(
        [sys.executable, "-X", "importtime", "-c", f"import {module}"],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    last = [ln for ln in out.stderr.splitlines() if ln.rstrip().endswith(f"| {module}")]
    return int(last[-1].split("|")[1]) / 1e6 if last else float("nan")


def section_e(args):
    print(f"\n## (e) `piecs-bayes fit data/demo/study.toml`: cold and warm\n\n{load()}\n")
    with tempfile.TemporaryDirectory() as tmp:
        cache = str(Path(tmp) / "cache")
        out = str(Path(tmp) / "out")
        jax_dir = Path(cache) / "piecs_bayes" / "jax"
        cold = _cli(cache, out)
        after_cold = sorted(p.name for p in jax_dir.iterdir())
        warm = [_cli(cache, out) for _ in range(3)]
        after_warm = sorted(p.name for p in jax_dir.iterdir())
        none = _cli(None, out)
        n_files = len(after_warm)
        size = sum(p.stat().st_size for p in jax_dir.iterdir())
        stable = (
            "no new entry"
            if after_warm == after_cold
            else (f"{len(set(after_warm) - set(after_cold))} NEW entries (unstable cache keys)")
        )
    rows = [
        ["cold (empty cache directory)", f"{cold:.2f} s", "1.0x"],
        ["warm (median of 3)", f"{sorted(warm)[1]:.2f} s", f"{cold / sorted(warm)[1]:.1f}x"],
        ["no persistent cache (PIECS_BAYES_NO_CACHE=1)", f"{none:.2f} s", f"{cold / none:.1f}x"],
    ]
    print(table(rows, ["wall time, whole process", "time", "vs cold"]))
    imp = {m: _import_time(m) for m in ("piecs_bayes.cli", "piecs_bayes.jobs", "jax")}
    print(
        f"\nCache: {n_files} entries, {size / 1e6:.1f} MB; the warm runs wrote {stable}. "
        "Import (python -X importtime, cumulative): "
        + ", ".join(f"{m} {t:.2f} s" for m, t in imp.items())
        + "."
    )
    return {"cold": cold, "warm": sorted(warm)[1], "none": none}


# --------------------------------------------------------------------------- (f)


def section_f(args):
    print(f"\n## (f) How the batch fit's cost grows\n\n{load()}\n")
    kw = dict(ball_radius=1.0, options=ROBUST)
    n_ref = 256 if args.quick else 1024
    by_points = _pointstable(args, kw)
    sizes = (10, 100, 1000) if args.quick else (10, 100, 1000, 10000)
    fleet = simulate_fleet(max(sizes), seed=3)
    c = to_part_frame(DEMO_TRANSFORM, fleet["points"])
    names = np.unique(fleet["part"])
    by_parts = []
    for n in sizes:
        sel = np.isin(fleet["part"], names[:n])
        args_n = (fleet["profile"], fleet["part"][sel], fleet["feature"][sel], c[sel])
        fit_profiles(*args_n, **kw)
        t = timeit(lambda a=args_n: fit_profiles(*a, **kw), repeat=2 if n < 10000 else 1)
        sample = names[: min(n, 20)]

        def scipy_loop(sample=sample):
            for p in sample:
                m = fleet["part"] == p
                scipy_part(fleet["profile"], fleet["feature"][m], c[m], 1.0, 1.345 * 0.0015)

        t_sp = timeit(scipy_loop, repeat=1) * n / len(sample)
        by_parts.append((n, t, t_sp))
    rows = [[n, ms(t), ms(t / n), ms(ts), f"{ts / t:.1f}x"] for n, t, ts in by_parts]
    print(table(rows, ["parts (demo points)", "fit_profiles", "per part", "scipy loop", "speed"]))
    slope_p = np.polyfit(np.log([r[0] for r in by_points]), np.log([r[1] for r in by_points]), 1)[0]
    slope_n = np.polyfit(np.log([r[0] for r in by_parts]), np.log([r[1] for r in by_parts]), 1)[0]
    print(
        f"\nLog-log slopes: time ~ points^{slope_p:.2f}, time ~ parts^{slope_n:.2f} (batches of "
        "256 problems: below ~40 parts one padded batch per group costs the same)."
    )
    _plot(args.plot, by_points, by_parts, n_ref)


def _pointstable(args, kw):
    """Cost per fit against points per feature (every demo feature probed with k
    points; ~2^18 points per k, at least 16 parts), side by side with the SciPy
    loop on a few of the same parts: `[(k, seconds per fit)]`."""
    ks = (8, 32, 128, 512, 1024, 4096)
    out, rows = [], []
    for k in ks:
        n_parts = max(16, min(256 if args.quick else 1024, (1 << (16 if args.quick else 18)) // k))
        fleet = simulate_fleet(n_parts, seed=2, points=k)
        c = to_part_frame(DEMO_TRANSFORM, fleet["points"])
        a = (fleet["profile"], fleet["part"], fleet["feature"], c)
        t0 = time.perf_counter()
        fit = fit_profiles(*a, **kw)
        first = time.perf_counter() - t0
        t = timeit(lambda a=a: fit_profiles(*a, **kw), repeat=2) / (n_parts * 7)
        sample = np.unique(fleet["part"])[: 2 if args.quick else 5]

        def scipy_loop(sample=sample, fleet=fleet, c=c):
            for p in sample:
                m = fleet["part"] == p
                scipy_part(fleet["profile"], fleet["feature"][m], c[m], 1.0, 1.345 * 0.0015)

        t_sp = timeit(scipy_loop, repeat=1) / (len(sample) * 7)
        _per_part(sample[:1], fleet, c, kw)  # its compilation (or persisted trace)
        t_pp = timeit(lambda s=sample, f=fleet, c=c: _per_part(s, f, c, kw), repeat=3)
        t_pp /= len(sample) * 7
        lm = sum(int(np.sum(fit.steps(f.id) >= 100)) for f in fleet["profile"])
        out.append((k, t))
        rows.append((k, n_parts, t, t_pp, t_sp, first - t * n_parts * 7, lm, fit.ok.mean()))
    t32 = dict(out)[32] / 32
    p32 = next(r[3] for r in rows if r[0] == 32) / 32
    cells = [
        [k, n, ms(t), f"{t / k * 1e6:.3f} us", f"{t / k / t32:.2f}", ms(tp),
         f"{tp / k * 1e6:.3f} us", f"{tp / k / p32:.2f}", ms(ts), f"{ts / k * 1e6:.2f} us",
         f"{ts / t:.0f}x", f"{comp:.1f} s", lm, f"{ok:.0%}"]
        for k, n, t, tp, ts, comp, lm, ok in rows
    ]  # fmt: skip
    print(table(cells, ["points per feature", "parts", "batch per fit", "per point",
                         "per point / at 32", "per-part path per fit", "per point",
                         "per point / at 32", "scipy per fit", "scipy per point",
                         "batch speed", "compile (bucket)", "fits with >= 100 steps",
                         "ok"]))  # fmt: skip
    print("\nPer-part path: `fit_profile(solver='auto')` (what `fit_study` and the CLI run: "
          "every feature of one part in one compiled call), part by part on the SciPy "
          "loop's parts, declared sigma 1.5 um.")  # fmt: skip
    slope = np.polyfit(np.log([k for k, _ in out[1:]]), np.log([t for _, t in out[1:]]), 1)[0]
    print(f"\nCost per fit ~ points^{slope:.2f} from 32 to {ks[-1]} points (robust Huber, "
          "batch kernel; every demo feature probed with k points).\n")  # fmt: skip
    return out


def _per_part(sample, fleet, c, kw):
    """The per-part path on each part of `sample` (one compiled call per part)."""
    for p in sample:
        m = fleet["part"] == p
        fit_profile(fleet["profile"], fleet["feature"][m], c[m], ball_radius=kw["ball_radius"],
                    options=replace(kw["options"], declared=0.0015, solver="auto"))  # fmt: skip


def _plot(path, by_points, by_parts, n_ref):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(1, 2, figsize=(10, 4))
    k, t = zip(*by_points, strict=True)
    a1.loglog(k, t, "o-", label="fit_profiles (batch kernel)")
    a1.set_xlabel("points per feature")
    a1.set_ylabel("wall time per fit (s)")
    a1.legend()
    n, t, ts = zip(*by_parts, strict=True)
    a2.loglog(n, t, "o-", label="fit_profiles (batched)")
    a2.loglog(n, ts, "s--", label="scipy loop (extrapolated from 20 parts)")
    a2.set_xlabel("parts (7 features, 54 points each)")
    a2.set_ylabel("wall time (s)")
    a2.legend()
    for a in (a1, a2):
        a.grid(True, which="both", alpha=0.3)
    fig.suptitle(f"piecs_bayes batch fits, robust (Huber); {load()}", fontsize=9)
    fig.tight_layout()
    Path(path).parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    print(f"\nPlot: {path}")


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--only", default="a,b,c,e,f", help="sections, e.g. a,b (c includes d)")
    p.add_argument("--parts", type=int, default=10_000, help="(b) fleet size")
    p.add_argument("--scipy-sample", type=int, default=200, help="(b) parts timed with scipy")
    p.add_argument("--plot", default=str(ROOT / "reports" / "bench_scaling.png"))
    p.add_argument("--quick", action="store_true", help="small sizes: a smoke run")
    p.add_argument("--child-b", type=int, default=None, help=argparse.SUPPRESS)
    p.add_argument("--child-b-stream", type=int, default=None, help=argparse.SUPPRESS)
    args = p.parse_args(argv)
    if args.child_b_stream is not None:
        print(json.dumps(_child_b_stream(args.child_b_stream)))
        return
    if args.child_b is not None:
        print(json.dumps(_child_b(args.child_b)))
        return
    if args.quick:
        args.parts = min(args.parts, 1000)
        args.scipy_sample = min(args.scipy_sample, 50)
    print(f"# piecs_bayes speed and scale\n\n{machine_line()}")
    only = set(args.only.split(","))
    if "a" in only:
        section_a(args)
    if "b" in only:
        section_b(args)
    if "c" in only or "d" in only:
        section_cd(args)
    if "e" in only:
        section_e(args)
    if "f" in only:
        section_f(args)
    print(f"\nDone; {load()}")


if __name__ == "__main__":
    main()
