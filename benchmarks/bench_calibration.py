"""Coverage of the stated 95 % intervals over simulated parts with known truth.

For each configuration (the demo's point counts, and a sparse probing with 3-8
points per feature and the fillet probed with 5 points over 68 degrees), with
the probe sigma pooled (the default) and declared known: the rate at which the
linearised (GUM) and the Monte Carlo (posterior) intervals of every feature
parameter and every vertex, and the simultaneous band of the whole path, hold
the truth. Each part has its own probe noise and its own draw of the declared
machine sources.

    .venv/bin/python benchmarks/bench_calibration.py [--parts 1000] [--no-bayes]

Prints one table per configuration and a summary; the issue asks for every
rate within 93.5-96.5 % at 1,000 parts (binomial sd 0.7 %).
"""

from __future__ import annotations

import argparse
import time

from piecs_bayes.jobs import coverage_check
from piecs_bayes.jobs.simulate import (
    DEMO_ERRORS,
    DEMO_POINTS,
    DEMO_TRANSFORM,
    demo_profile,
    process_deviations,
)

SOURCES = {"ball_radius": 0.0005, "x_centre": 0.001, "scale_z": 5e-6}
SPARSE = {
    "face_end": 3,
    "dia_24": 8,
    "taper": 4,
    "dia_30": 5,
    "fillet": 5,
    "shoulder": 6,
    "dia_44": 7,
}
CONFIGS = {"demo points": (DEMO_POINTS, 0.1), "sparse (3-8 points)": (SPARSE, 0.12)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--parts", type=int, default=1000)
    ap.add_argument("--no-bayes", action="store_true", help="linearised route only")
    ap.add_argument("--steps", type=int, default=3000, help="MCMC steps per part")
    ap.add_argument("--walkers", type=int, default=64, help="walkers of the one ensemble per part")
    ap.add_argument(
        "--sigma", choices=("both", "pooled", "known"), default="both", help="which sigma rules"
    )
    ap.add_argument("--config", choices=("all", *CONFIGS), default="all", help="which probing")
    args = ap.parse_args(argv)
    profile = demo_profile()
    truth = process_deviations(profile, DEMO_ERRORS)
    summary = []
    for name, (points, margin) in CONFIGS.items():
        if args.config not in ("all", name):
            continue
        for known in {"both": (False, True), "pooled": (False,), "known": (True,)}[args.sigma]:
            t0 = time.perf_counter()
            res = coverage_check(
                profile, truth, n_parts=args.parts, points=points, margin=margin,
                transform=DEMO_TRANSFORM, source_sd=SOURCES, known_sigma=known,
                bayes=not args.no_bayes, bayes_steps=args.steps, bayes_walkers=args.walkers,
                seed=2026,
            )  # fmt: skip
            wall = time.perf_counter() - t0
            label = f"{name}, {'known sigma' if known else 'pooled sigma (default)'}"
            print(f"\n== {label} ({wall:.0f} s; probe sigma dof {res.sigma_dof})")
            print(res.table(), flush=True)
            for route, r in res.rates.items():
                summary.append((label, route, r))
    print("\n| configuration | route | parameters | vertices | band |\n|---|---|---|---|---|")
    for label, route, r in summary:
        print(
            f"| {label} | {route} | {100 * r['parameters']:.1f} % | "
            f"{100 * r['vertices']:.1f} % | {100 * r['band']:.1f} % |"
        )
    bad = [
        (label, route, k, v)
        for label, route, r in summary
        for k, v in r.items()
        if not 0.935 <= v <= 0.965
    ]
    print("\nall within 93.5-96.5 %" if not bad else f"\noutside 93.5-96.5 %: {bad}")
    return 0 if not bad else 1


if __name__ == "__main__":
    raise SystemExit(main())
