"""Feedback policies over simulated production runs (issue 17).

    .venv/bin/python benchmarks/bench_feedback.py [--runs 1000] [--parts 50] [--seed 17]

Each scenario simulates `--runs` runs of `--parts` parts of one feature on a turning
centre (normal deviation, mm; µm below): a setup offset N(0, 4²) at part 0, part-to-part
scatter 1.5 µm, measurement error N(0, u_k²) with u_k ~ U(0.8, 1.2) µm known per part,
tolerance ±10 µm, and

- `noise`: nothing else;
- `slow drift`: tool wear 0.1-0.2 µm per part;
- `fast drift`: tool wear 0.3-0.5 µm per part;
- `tool change`: wear 0.15 µm/part and an undeclared step of ±5-15 µm at a part drawn
  in 15..35;
- `outliers`: wear 0.15 µm/part and odd parts (5 %) off by ±20-50 µm;
- `noise x2-5`: wear 0.15 µm/part and the scatter 2-5 times larger (3-7.5 µm).

Every policy of `compensate._feedback` is replayed on the same deviations (the
counterfactual of its module doc). The anchors are tuned per scenario over
`TUNING_GRIDS` (the setting with the lowest RMS over all runs of the scenario: on the
same data, a hindsight advantage); `bayes` has fixed settings (`BAYES_DECISION`, the
grid-averaged tracking model refitted from the parts before each part). Printed:
pooled RMS deviation (µm) and out-of-tolerance parts per run for every policy, the
bayes RMS relative to the best of `ewma`/`dewma`, a floor no policy can beat (the
true level of every part but the first known before it is cut), and the coverage of the bayes
model's 95 % one-step-ahead predictive intervals (parts 1..n-1).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import numpy as np  # noqa: E402

from piecs_bayes.compensate._feedback import (  # noqa: E402
    POLICIES,
    TUNING_GRIDS,
    replay_runs,
)

UM = 1e-3
TOL = (-10 * UM, 10 * UM)
SCENARIOS = ("noise", "slow drift", "fast drift", "tool change", "outliers", "noise x2-5")


def simulate(scenario: str, runs: int, parts: int, rng) -> tuple[np.ndarray, ...]:
    """`(deviation, u, level)` `(runs, parts)` in mm: uncompensated measured deviations,
    their standard uncertainties and the true level of each part."""
    k = np.arange(parts)[None, :]
    level = rng.normal(0.0, 4.0, (runs, 1)) + np.zeros((runs, parts))
    scatter = np.full((runs, 1), 1.5)
    wear = {"noise": (0.0, 0.0), "slow drift": (0.1, 0.2), "fast drift": (0.3, 0.5)}.get(
        scenario, (0.15, 0.15)
    )
    level = level + rng.uniform(*wear, (runs, 1)) * k
    odd = np.zeros((runs, parts))
    if scenario == "tool change":
        at = rng.integers(15, 36, runs)[:, None]
        size = rng.uniform(5.0, 15.0, (runs, 1)) * rng.choice([-1.0, 1.0], (runs, 1))
        level = level + size * (k >= at)
    if scenario == "outliers":
        hit = rng.random((runs, parts)) < 0.05
        odd = hit * rng.uniform(20.0, 50.0, (runs, parts)) * rng.choice([-1.0, 1.0], (runs, parts))
    if scenario == "noise x2-5":
        scatter = scatter * rng.uniform(2.0, 5.0, (runs, 1))
    u = rng.uniform(0.8, 1.2, (runs, parts))
    dev = level + scatter * rng.standard_normal((runs, parts)) + odd
    dev = dev + u * rng.standard_normal((runs, parts))
    return dev * UM, u * UM, level * UM


def evaluate(dev, u, policy, settings):
    c, flags, pit = replay_runs(dev, u, policy=policy, settings=settings, tolerance=TOL)
    real = dev + c
    rms = float(np.sqrt(np.mean(real**2)))
    oot = float(np.mean(np.sum((real < TOL[0]) | (real > TOL[1]), axis=1)))
    return rms, oot, pit


def scenario_rows(scenario, runs, parts, rng):
    dev, u, level = simulate(scenario, runs, parts, rng)
    rows = {}
    floor = dev.copy()
    floor[:, 1:] -= level[:, 1:]  # a policy that knew the true level of parts 1..n-1
    rows["floor"] = (
        float(np.sqrt(np.mean(floor**2))),
        float(np.mean(np.sum((floor < TOL[0]) | (floor > TOL[1]), 1))),
    )
    for policy in POLICIES:
        t0 = time.perf_counter()
        best = None
        for st in TUNING_GRIDS[policy]:
            rms, oot, pit = evaluate(dev, u, policy, st)
            if best is None or rms < best[0]:
                best = (rms, oot, st, pit)
        rows[policy] = best + (time.perf_counter() - t0,)
    pit = rows["bayes"][3][:, 1:]
    cover = float(np.mean((pit >= 0.025) & (pit <= 0.975)))
    return rows, cover


def _st(st: dict) -> str:
    return ", ".join(f"{k}={v:g}" for k, v in st.items()) or "-"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=1000, help="simulated runs per scenario")
    ap.add_argument("--parts", type=int, default=50, help="parts per run")
    ap.add_argument("--seed", type=int, default=17)
    a = ap.parse_args(argv)
    rng = np.random.default_rng(a.seed)
    t_all = time.perf_counter()
    results = {}
    for sc in SCENARIOS:
        results[sc] = scenario_rows(sc, a.runs, a.parts, rng)
        print(f"[{sc}: {time.perf_counter() - t_all:.0f} s]", file=sys.stderr)
    print(f"## Feedback policies: {a.runs} runs x {a.parts} parts per scenario, tolerance "
          f"±10 µm\n")  # fmt: skip
    head = "| policy | " + " | ".join(SCENARIOS) + " |"
    print("RMS deviation (µm) / out-of-tolerance parts per run:\n")
    print(head)
    print("|" + "---|" * (len(SCENARIOS) + 1))
    for p in POLICIES:
        cells = [f"{results[s][0][p][0] / UM:.2f} / {results[s][0][p][1]:.2f}" for s in SCENARIOS]
        print(f"| {p} | " + " | ".join(cells) + " |")
    cells = [f"{results[s][0]['floor'][0] / UM:.2f} / {results[s][0]['floor'][1]:.2f}"
             for s in SCENARIOS]  # fmt: skip
    print("| *floor: true level known (parts 1..n-1)* | " + " | ".join(cells) + " |")
    ratios = []
    cells_r, cells_c = [], []
    for s in SCENARIOS:
        rows = results[s][0]
        ref = min(rows["ewma"][0], rows["dewma"][0])
        ratios.append(rows["bayes"][0] / ref)
        cells_r.append(f"{ratios[-1]:.3f}")
        cells_c.append(f"{results[s][1]:.3f}")
    print("| bayes / best of ewma, dewma | " + " | ".join(cells_r) + " |")
    print("| bayes 95 % predictive coverage | " + " | ".join(cells_c) + " |")
    print(f"\nMean RMS ratio bayes / best(ewma, dewma): {np.mean(ratios):.3f} "
          f"({(1 - np.mean(ratios)) * 100:+.1f} % lower RMS); coverage over all scenarios "
          f"{np.mean([results[s][1] for s in SCENARIOS]):.3f}.\n")  # fmt: skip
    print("Tuned anchor settings (best RMS on each scenario's runs):\n")
    print("| policy | " + " | ".join(SCENARIOS) + " |")
    print("|" + "---|" * (len(SCENARIOS) + 1))
    for p in ("fixed_gain", "mean_value", "ewma", "dewma"):
        print(f"| {p} | " + " | ".join(_st(results[s][0][p][2]) for s in SCENARIOS) + " |")
    print("\nSeconds per policy (all settings of its grid), summed over scenarios: " + ", ".join(
        f"{p} {sum(results[s][0][p][4] for s in SCENARIOS):.1f}" for p in POLICIES
    ) + f"; total {time.perf_counter() - t_all:.0f} s.")  # fmt: skip


if __name__ == "__main__":
    main()
