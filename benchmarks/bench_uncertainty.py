"""Larger calibration runs for the generic Bayesian / propagation machinery.

    .venv/bin/python benchmarks/bench_uncertainty.py [--sims 2000] [--quick]

Prints (Markdown):

1. band coverage of a 3-parameter quadratic profile (known truth, least-squares
   fits): simultaneous and pointwise, linearised and Monte Carlo, known and
   estimated sigma, with binomial 95 % intervals of the coverage;
2. Newcomb's posterior vs the closed form and the sampler's cost: wall time and
   effective samples per second, vectorised (jit + vmap, `vectorize=True`) vs a
   jitted per-walker call;
3. JCGM 101 clause 9 Monte Carlo results at M = 10^6 next to the PUB/REPRO lines.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import emcee  # noqa: E402
import jax  # noqa: E402
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy import stats  # noqa: E402

from piecs_bayes.fit.mcmc import SamplerOptions, gaussian_loglik, sample_posterior
from piecs_bayes.uncertainty import (  # noqa: E402
    bands_from_samples,
    bands_linear,
    coverage_interval,
    propagate_mc,
)

REF = Path(__file__).resolve().parent.parent.parent / "shared" / "reference"


def _wilson(k, n):
    lo, hi = stats.binomtest(int(k), n).proportion_ci(0.95, method="wilson")
    return f"{k / n:.3f} [{lo:.3f}, {hi:.3f}]"


def bands(n_sims: int) -> None:
    rng = np.random.default_rng(2024)
    z, grid = np.linspace(-1, 1, 30), np.linspace(-1, 1, 101)
    x, g = np.vander(z, 3, increasing=True), np.vander(grid, 3, increasing=True)
    beta, sigma, dof = np.array([0.010, -0.004, 0.006]), 0.002, z.size - 3
    xtx_inv = np.linalg.inv(x.T @ x)
    chol = np.linalg.cholesky(sigma**2 * xtx_inv)
    truth = g @ beta
    counts = {k: 0 for k in ["lin_s", "lin_p", "t_s", "t_p", "mc_s", "mc_p"]}
    crit = {}
    t0 = time.perf_counter()
    for _ in range(n_sims):
        y = x @ beta + rng.normal(0, sigma, z.size)
        bh = xtx_inv @ x.T @ y
        s2 = np.sum((y - x @ bh) ** 2) / dof
        b = bands_linear(g @ bh, g @ (sigma**2 * xtx_inv) @ g.T, n_sim=2**14)
        bt = bands_linear(g @ bh, g @ (s2 * xtx_inv) @ g.T, dof=dof, n_sim=2**14)
        draws = (bh + rng.standard_normal((4000, 3)) @ chol.T) @ g.T
        bm = bands_from_samples(draws, center=g @ bh)
        for key, band in [("lin", b), ("t", bt), ("mc", bm)]:
            counts[key + "_s"] += band.covers(truth)
            counts[key + "_p"] += band.covers(truth, "pointwise")
            crit.setdefault(key, []).append((band.crit_pointwise.mean(), band.crit_simultaneous))
    dt = time.perf_counter() - t0
    print(f"\n## Band coverage of the whole true curve ({n_sims} fits, {dt:.1f} s)\n")
    print("| bands | critical value pointwise / simultaneous | simultaneous | pointwise |")
    print("|---|---|---|---|")
    labels = {
        "lin": "linearised, known sigma",
        "t": "linearised, estimated sigma (t, 27 dof)",
        "mc": "Monte Carlo draws (4000 / fit)",
    }
    for key, label in labels.items():
        cp, cs = np.mean(crit[key], axis=0)
        print(
            f"| {label} | {cp:.3f} / {cs:.3f} | {_wilson(counts[key + '_s'], n_sims)} "
            f"| {_wilson(counts[key + '_p'], n_sims)} |"
        )


def _newcomb_logpost(theta, y):
    return gaussian_loglik(y - theta[0], jnp.exp(theta[1]))


def sampler() -> None:
    y = np.loadtxt(REF / "bayes" / "newcomb_speed_of_light.txt")
    x0 = np.array([y.mean(), math.log(y.std())])
    yj = jnp.asarray(y)
    print("\n## Newcomb: posterior vs closed form, and sampler cost\n")
    n = y.size
    t = stats.t(n - 1, y.mean(), y.std(ddof=1) / math.sqrt(n))
    print("| run | mean mu | sd mu | 95 % interval | wall s | min ESS | ESS/s | R-hat |")
    print("|---|---|---|---|---|---|---|---|")
    lo, hi = t.interval(0.95)
    print(f"| closed form t_65 | {t.mean():.4f} | {t.std():.4f} | [{lo:.4f}, {hi:.4f}] |||||")
    for nw, ns in [(32, 3000), (64, 3000), (128, 3000)]:
        p = sample_posterior(
            _newcomb_logpost, x0, names=("mu", "log_sigma"), args=yj,
            options=SamplerOptions(nwalkers=nw, nsteps=ns, burn=500, seed=1, progress=False),
        )  # fmt: skip
        lo, hi = p.interval()
        print(
            f"| 4 x {nw} walkers x {ns} steps | {p.mean[0]:.4f} | {p.sd[0]:.4f} | "
            f"[{lo[0]:.4f}, {hi[0]:.4f}] | {p.wall_time:.2f} | {p.ess.min():.0f} | "
            f"{p.ess_per_second:.0f} | {p.rhat.max():.4f} |"
        )
    # per-walker (non-vectorised) call for comparison, one ensemble
    single = jax.jit(_newcomb_logpost)
    s = emcee.EnsembleSampler(32, 2, lambda th: float(single(jnp.asarray(th), yj)))
    p0 = x0 + np.random.default_rng(0).normal(size=(32, 2)) * [1.3, 0.09]
    single(jnp.asarray(p0[0]), yj)
    t0 = time.perf_counter()
    s.run_mcmc(p0, 3000, progress=False)
    dt = time.perf_counter() - t0
    tau = emcee.autocorr.integrated_time(s.get_chain(discard=500), tol=0, quiet=True)
    ess = 2500 * 32 / tau.max()
    print(f"| per-walker calls, 1 x 32 x 3000 | | | | {dt:.2f} | {ess:.0f} | {ess / dt:.0f} | |")


def jcgm() -> None:
    print("\n## JCGM 101 clause 9, M = 10^6 (seed 0)\n")
    rng = np.random.default_rng(0)
    m = 1_000_000
    sq3 = math.sqrt(3)

    def mass(x):
        return (x[0] + x[1]) * (1 + (x[2] - 1.2) * (1 / x[3] - 1 / x[4])) - 100_000.0

    cases = [
        ("9.2.2 normal", lambda x: jnp.sum(x), rng.standard_normal((m, 4)),
         "PUB 0.00 2.00 [-3.92, 3.92]; REPRO -0.0008 2.0002 [-3.9226, 3.9176]"),
        ("9.2.3 rectangular", lambda x: jnp.sum(x), rng.uniform(-sq3, sq3, (m, 4)),
         "PUB 0.00 2.00 [-3.88, 3.88]; REPRO u 2.0003 [-3.8810, 3.8809]"),
        ("9.2.4 one dominant", lambda x: jnp.sum(x),
         rng.uniform(-sq3, sq3, (m, 4)) * np.array([1, 1, 1, 10.0]),
         "REPRO u 10.151 [-17.021, 17.018]"),
        ("9.3 mass", mass, np.column_stack([
            rng.normal(100_000, 0.05, m), rng.normal(1.234, 0.02, m), rng.uniform(1.1, 1.3, m),
            rng.uniform(7000, 9000, m), rng.uniform(7950, 8050, m)]),
         "REPRO 1.23396 0.075488 sym [1.08437, 1.38350] shortest [1.08443, 1.38356]"),
    ]  # fmt: skip
    print("| example | mean | u | symmetric 95 % | shortest 95 % | reference |")
    print("|---|---|---|---|---|---|")
    for name, fn, draws, ref in cases:
        ym, yc, ys = propagate_mc(fn, draws)
        a, b = coverage_interval(ys), coverage_interval(ys, kind="shortest")
        print(
            f"| {name} | {float(ym):.5f} | {math.sqrt(yc[0, 0]):.5f} | [{a[0]:.5f}, {a[1]:.5f}] "
            f"| [{b[0]:.5f}, {b[1]:.5f}] | {ref} |"
        )


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--sims", type=int, default=2000)
    ap.add_argument("--quick", action="store_true", help="200 simulated fits")
    args = ap.parse_args()
    bands(200 if args.quick else args.sims)
    sampler()
    jcgm()


if __name__ == "__main__":
    main()
