"""Shared pieces of the benchmarks: simulated fleets of parts, timing, machine state.

`simulate_fleet(n)` makes `n` demo shafts the way `piecs_bayes.simulate.write_batch`
makes its 36 (process errors -> exact deviations -> probe triggers with 1.5 um
noise), vectorised over parts so that 10,000 parts take seconds: the triggers of
each feature are computed for every part at once with `jax.vmap` of the
feature's own `point_at` / `outward_normal`. 2 % of the parts get a chip under
the stylus (one trigger pushed out 0.15 mm), so robust fits have work to do.
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from dataclasses import replace

import jax
import jax.numpy as jnp
import numpy as np
from _fmt import load  # noqa: F401  (re-exported for the benchmarks)

from piecs_bayes.geometry import part_to_machine
from piecs_bayes.simulate import (
    DEMO_POINTS,
    DEMO_TRANSFORM,
    ProcessErrors,
    demo_profile,
    process_deviations,
)

__all__ = ["machine_line", "simulate_fleet", "timeit", "load"]


def machine_line() -> str:
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return (
        f"{os.cpu_count()} CPU cores ({cpu}), Python {platform.python_version()}, "
        f"jax {jax.__version__} on {jax.default_backend()}; {load()}"
    )


def timeit(fn, *, repeat: int = 5, number: int = 1) -> float:
    """Median seconds per call of `fn()` over `repeat` rounds of `number` calls."""
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        for _ in range(number):
            fn()
        times.append((time.perf_counter() - t0) / number)
    return statistics.median(times)


def _deviations(profile, rng, n):
    base = ProcessErrors(deflection=0.00008, nose_radius_error=0.002, chuck_z=-100.0)
    out = {f.id: np.empty((n, f.nparams)) for f in profile.features}
    for k in range(n):
        err = replace(
            base,
            tool_offset_x=rng.normal(0.0, 0.004),
            tool_offset_z=rng.normal(0.0, 0.004),
            wear_rate=abs(rng.normal(0.0, 2e-6)),
        )
        for fid, d in process_deviations(profile, err).items():
            out[fid][k] = d
    return out


def simulate_fleet(
    n_parts: int,
    *,
    seed: int = 0,
    points: dict | int | None = None,
    noise_sd: float = 0.0015,
    chip_rate: float = 0.02,
    ball_radius: float = 1.0,
):
    """`n_parts` simulated demo shafts as flat arrays (like `ProbeData`).

    **Returns:** `dict(part, feature, points (machine, radius X), truth)` with
    `truth[fid]` the `(n_parts, k)` true deviations.
    """
    rng = np.random.default_rng(seed)
    profile = demo_profile()
    points = DEMO_POINTS if points is None else points
    n_distinct = min(n_parts, 200)  # process errors: 200 distinct parts, cycled
    devs = _deviations(profile, rng, n_distinct)
    pick = np.arange(n_parts) % n_distinct
    parts, feats, pts = [], [], []
    for f in profile.features:
        k = points.get(f.id, 0) if isinstance(points, dict) else int(points)
        if k <= 0:
            continue
        t = jnp.linspace(0.1, 0.9, k)

        def surface(dev, f=f, t=t):
            s = f.point_at(t, dev)
            return s, f.outward_normal(s, dev)

        s, nrm = map(np.asarray, jax.jit(jax.vmap(surface))(jnp.asarray(devs[f.id][pick])))
        c = s + ball_radius * nrm + rng.normal(0.0, noise_sd, size=s.shape)
        chip = rng.random(n_parts) < chip_rate / len(profile.features)
        j = rng.integers(0, k, size=n_parts)
        c[chip, j[chip]] += 0.15 * nrm[chip, j[chip]]
        parts.append(np.repeat(np.arange(n_parts), k))
        feats.append(np.full(n_parts * k, f.id))
        pts.append(c.reshape(-1, 2))
    part = np.concatenate(parts)
    order = np.argsort(part, kind="stable")  # part by part, features in profile order
    machine = np.asarray(part_to_machine(jnp.asarray(np.vstack(pts)[order]), DEMO_TRANSFORM))
    width = len(str(n_parts))
    names = np.array([f"part{i + 1:0{width}d}" for i in range(n_parts)])
    return {
        "profile": profile,
        "part": names[part[order]],
        "feature": np.concatenate(feats)[order],
        "points": machine,
        "truth": {fid: d[pick] for fid, d in devs.items()},
    }
