"""The batch path's stated u against the simulator's truth (issue 41).

Feedback and capability studies take, per part and feature, the characteristic (the
normal deviation at the mid-point) and its u from `jobs.capability_values`. On
simulated runs with known truth (`simulate.write_batch`), `(measured - truth) / u` must
scatter as a standard normal: its sd inside the 95 % range of the sd of `n` standard
normals, $1 \\pm 1.96/\\sqrt{2(n-1)}$.

- `known_sigma = true` (the simulator's 1.5 um): the z-scores as they are.
- The default (the pooled sigma with the declared one as prior, `docs/uncertainty.md`
  section 1): u carries the part's estimated sigma, so each z-score is a Student-t
  (sd 1.02 at the demo's points); it is taken to the normal first,
  $\\Phi^{-1}(F_t(z))$. Here the declared prior is exact (the simulator's sigma)
  and only the $\\nu_p$ residual dof scatter: $\\tilde s^2/\\sigma^2$ has mean 1 and
  variance $2\\nu_p/\\nu^2$, the t's dof is $\\nu^2/\\nu_p$ ($\\nu = \\nu_0 + \\nu_p$), not
  the $\\nu$ that the stated intervals take for a prior that is itself uncertain.

Power: the sample sd of `n` standard normals has sd $1/\\sqrt{2(n-1)}$; the z-scores of
one part share its sigma, so a run scatters a little more (0.05-0.06 against 0.045 at
252). At `n` = 504 (two runs of 36 parts) the range is 0.938-1.062: a u that
understates the scatter by 9 % fails about 4 times in 5, by 16 % (data/batch before
issue 41) 199 times in 200. The slow tier, ten runs a case (`n` = 2,520,
0.972-1.028), catches 4 % about 4 times in 5.

Before issue 41 the robust fits' covariance held the final weights fixed and stated u
2 % below the M-estimator's scatter (`fit.lsq.losses.fixed_weight_factor`): over 60
runs of the data/batch process the default gave sd 1.032 (1.017 over 20 runs after),
data/batch itself 1.157 (1.135 after), the largest of the 60.
"""

from __future__ import annotations

import json
import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
from helpers import BATCH
from scipy import stats

from piecs_bayes.io import load_study
from piecs_bayes.jobs import capability_values, load_probe_data, source_sds
from piecs_bayes.simulate import write_batch
from piecs_bayes.uncertainty import deviation_and_jacobian


def sd_range(n: int) -> tuple[float, float]:
    """The 95 % range of the sample sd of `n` standard normals (normal approximation)."""
    half = 1.96 / math.sqrt(2.0 * (n - 1))
    return 1.0 - half, 1.0 + half


def z_scores(folder: Path, *, known_sigma: bool) -> np.ndarray:
    """`(measured - truth) / u` of every part and feature of the run in `folder`, as
    standard normals under the stated model (Student-t taken to the normal)."""
    study = load_study(folder / "study.toml")
    study = replace(study, fit=replace(study.fit, known_sigma=known_sigma))
    truth = {p["part"]: p["deviations"] for p in json.loads(
        (folder / "truth.json").read_text(encoding="utf-8"))["parts"]}  # fmt: skip
    probe = load_probe_data(study)
    values, us, pids, _, _ = capability_values(  # a robust fit that fails: least squares
        study, probe, method=study.fit.method, at="mid", sources=source_sds(study)
    )
    out = []
    for f in study.profile.features:
        params = [[truth[p][f.id][n] for n in f.param_names] for p in pids[f.id]]
        exact = deviation_and_jacobian(f, np.asarray(params), [0.5])[0][:, 0]
        out.append((np.asarray(values[f.id]) - exact) / np.asarray(us[f.id]))
    z = np.concatenate(out)
    if known_sigma:
        return z
    per_part = len(probe) / len(probe.parts)  # every simulated part has the same points
    nu_p = per_part - sum(f.nparams for f in study.profile.features)
    nu = study.probe.repeatability_dof + nu_p
    return stats.norm.ppf(stats.t.cdf(z, nu * nu / nu_p))


def _runs(tmp_path, points, seeds):
    z = {True: [], False: []}
    for seed in seeds:
        folder = tmp_path / f"run{seed}"
        write_batch(folder, seed=seed, points=points)
        for known in z:
            z[known].append(z_scores(folder, known_sigma=known))
    return {k: np.concatenate(v) for k, v in z.items()}


def _check(z: np.ndarray, what: str):
    lo, hi = sd_range(z.size)
    sd = float(np.std(z, ddof=1))
    assert lo <= sd <= hi, f"{what}: sd {sd:.3f} of {z.size} z-scores, expected {lo:.3f}-{hi:.3f}"


def test_sd_range():
    assert sd_range(252) == pytest.approx((0.9125, 1.0875), abs=1e-4)


def test_data_batch_at_the_simulated_sigma():
    """data/batch (seed 7), its 252 values at the simulator's sigma: 1.082 (1.104 before
    issue 41; 0.9125-1.0875)."""
    _check(z_scores(BATCH, known_sigma=True), "data/batch, known sigma")


@pytest.mark.xfail(strict=True, raises=AssertionError, reason=(
    "data/batch's own draw, not the model: at the default (pooled sigma) sd 1.135, "
    "1.111 as normals (1.157 before issue 41), above 0.9125-1.0875; its probe noise "
    "gives 1.082 even by least squares at the true sigma (+1.8 sds) and its residuals "
    "pool to 1.444 um against the simulated 1.5 (-1.9 sds); the largest of 60 runs "
    "of its process, which give 1.017 (the Student-t's 1.02)"))  # fmt: skip
def test_data_batch_at_the_default():
    _check(z_scores(BATCH, known_sigma=False), "data/batch, pooled sigma")


#: runs of the data/batch process: probing density, seeds
FAST = {"sparse, 5 points": (5, (1, 2)), "dense, 32 points": (32, (1, 2))}
SLOW = {
    "demo points": (None, tuple(range(1, 11))),
    "sparse, 5 points": (5, tuple(range(1, 11))),
    "dense, 64 points": (64, tuple(range(1, 11))),
}


@pytest.mark.parametrize("case", FAST)
def test_simulated_runs(tmp_path, case):
    points, seeds = FAST[case]
    for known, z in _runs(tmp_path, points, seeds).items():
        _check(z, f"{case}, {'known' if known else 'pooled'} sigma")


@pytest.mark.slow
@pytest.mark.parametrize("case", SLOW)
def test_simulated_runs_full_power(tmp_path, case):
    points, seeds = SLOW[case]
    for known, z in _runs(tmp_path, points, seeds).items():
        _check(z, f"{case}, {'known' if known else 'pooled'} sigma")
