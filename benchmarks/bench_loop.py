"""The loop on the machine, many times: coverage of the characteristic's intervals.

    .venv/bin/python benchmarks/bench_loop.py              # 1,000 loops
    .venv/bin/python benchmarks/bench_loop.py --loops 200

Each loop: the shipped plan's LinuxCNC gauging program (data/demo/gauge) run on the
simulated machine on the truth part (data/demo/truth.json) with the probe's
repeatability and a ball radius off by a draw from its declared uncertainty; the
PROBEOPEN text read against the plan; all loops fitted in one batch at the study's
settings (robust Huber, pooled sigma with the declared prior). Counts how often the
95 % interval of each feature's characteristic (normal deviation at start, mid-point
and end; Student-t at the Welch-Satterthwaite dof, with the ball radius as the one
systematic source) covers the truth's, and prints the rate per feature and overall,
with the time per loop of the simulated machine and of the batch fit.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import numpy as np  # noqa: E402

from piecs_bayes.fit import coverage_factor, effective_dof, fit_profiles  # noqa: E402
from piecs_bayes.io import load_study, read_control_probe, read_plan_points  # noqa: E402
from piecs_bayes.jobs import fit_options  # noqa: E402
from piecs_bayes.simulate import simulate_gauge  # noqa: E402
from piecs_bayes.uncertainty import characteristic_arrays, normal_deviation  # noqa: E402

GAUGE = ROOT / "data" / "demo" / "gauge"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--loops", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    study = load_study(GAUGE / "study.toml")
    plan = read_plan_points(study.probe_plan)
    body = json.loads((ROOT / "data" / "demo" / "truth.json").read_text())["deviations"]
    truth = {f.id: np.array([body[f.id][p] for p in f.param_names]) for f in study.profile}
    program = (GAUGE / "gauging.ngc").read_text()
    u_ball = study.probe.ball_radius_u
    rng = np.random.default_rng(args.seed)
    parts, feats, pts = [], [], []
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(args.loops):
            r = study.probe.ball_radius + rng.normal(0.0, u_ball)
            real = replace(study, probe=replace(study.probe, ball_radius=r))
            run = simulate_gauge(program, real, truth, repeatability=study.probe.repeatability,
                                 seed=args.seed * 100_003 + i)  # fmt: skip
            f = Path(tmp) / "probe_points.txt"
            f.write_text(run.text)
            data = read_control_probe(f, "linuxcnc", plan, part=f"p{i:04d}")
            parts.append(data.part)
            feats.append(data.feature)
            pts.append(data.points)
            if (i + 1) % 100 == 0:
                print(f"  {i + 1} loops, {time.perf_counter() - t0:.0f} s", flush=True)
    t_sim = (time.perf_counter() - t0) / args.loops
    t0 = time.perf_counter()
    batch = fit_profiles(study.profile, np.concatenate(parts), np.concatenate(feats),
                         np.concatenate(pts), ball_radius=study.probe.ball_radius,
                         options=fit_options(study, "robust"))  # fmt: skip
    t_fit = (time.perf_counter() - t0) / args.loops
    sources = {"ball_radius": u_ball}
    hits, total = {}, {}
    for at in ("start", "mid", "end"):
        for f in study.profile.features:
            mean, u_fit, u_sys, t = characteristic_arrays(batch, f.id, at=at, sources=sources)
            u = np.hypot(u_fit, u_sys)
            dof = effective_dof(u, u_fit, np.asarray(batch.sigma_dof, float))
            k = coverage_factor(dof, 0.95)
            true = float(normal_deviation(f, truth[f.id], float(np.atleast_1d(t)[0])))
            ok = np.abs(mean - true) <= k * u
            hits[f.id] = hits.get(f.id, 0) + int(ok.sum())
            total[f.id] = total.get(f.id, 0) + int(np.isfinite(mean).sum())
    n = sum(total.values())
    print()
    print("| feature | coverage of the 95 % intervals (start, mid, end) |")
    print("|---|---:|")
    for fid in hits:
        print(f"| {fid} | {hits[fid] / total[fid]:.3f} |")
    print(f"| all ({n} intervals over {args.loops} loops) | {sum(hits.values()) / n:.4f} |")
    print(f"simulated machine {t_sim * 1e3:.0f} ms per loop; batch fit {t_fit * 1e3:.1f} ms a part")


if __name__ == "__main__":
    main()
