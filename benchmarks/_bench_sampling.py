"""Sections (c) and (d) of `bench_scale.py`: samplers of one posterior side by side.

The posterior is the demo part's profile posterior (`bayes_study`'s model, d=20:
the deviations of its 7 features, the transform and ball-radius nuisances, the
repeatability), once in JAX (`profile_log_posterior`) and once in NumPy (per
walker, as a user writes it for emcee; checked equal).

- (c) emcee with the JAX log posterior (jitted, vmapped, `vectorize=True`) and with
  the NumPy one; the lockstep ensembles of `sample_posteriors` (both backends, 1
  and 16 parts);
- (d) NumPyro NUTS (the `bench` extra; skipped when numpyro is missing) on the same
  posterior, every sampler side by side in one table, and the check that they
  sample the same posterior (means and sds per parameter, in Monte Carlo errors).

One ESS estimator for every sampler (`ess_of`): kept steps x walkers (or chains) /
tau, tau from `piecs_bayes.fit.mcmc._core._taus` (emcee's `integrated_time`, c=5,
what `Posterior.tau` of the lockstep sampler is).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
from _common import load
from _fmt import table

from piecs_bayes.fit.mcmc._core import _taus
from piecs_bayes.io import load_study
from piecs_bayes.jobs import fit_study, inliers, load_probe_data

DEMO = Path(__file__).resolve().parent.parent / "data" / "demo" / "study.toml"
#: two samplers disagree when a parameter's mean (or sd) differs by more than this
#: many Monte Carlo standard errors (the largest of 20 |N(0, 1)| is below 4 in
#: 99.9 % of runs)
AGREE_Z = 4.0


def _posterior():
    """The demo part's profile posterior (bayes_study's model), JAX and NumPy forms."""
    from piecs_bayes.fit import BayesOptions, profile_log_posterior

    study = load_study(DEMO)
    probe = load_probe_data(study)
    fit = fit_study(study, probe)
    use = inliers(fit, probe)
    log_prob, lay, priors = profile_log_posterior(
        study.profile, use.feature, options=BayesOptions(
            sources=dict(study.sources), ball_radius=study.probe.ball_radius,
            transform=study.transform, sigma=study.probe.repeatability,
        ), with_approach=use.approach is not None,
    )  # fmt: skip
    args = (jnp.asarray(use.points), None if use.approach is None else jnp.asarray(use.approach))
    x0 = np.zeros(len(lay.names))
    for f, sl in lay.features:
        x0[sl] = fit.deviations[f.id]
    for name, k in lay.nuisance:
        x0[k] = priors[name].mean
    x0[lay.sigma_index] = study.probe.repeatability

    # nominal geometry as plain NumPy, computed once (Feature properties are JAX)
    feats = []
    for f, sl in lay.features:
        idx = np.flatnonzero(use.feature == f.id)
        if f.kind == "line":
            geo = (np.asarray(f.normal, dtype=float), np.asarray(f.midpoint, dtype=float))
        else:
            geo = (np.asarray(f.center, dtype=float), float(f.radius), float(f.sense))
        feats.append((f.kind, sl, idx, geo))
    base = np.asarray(study.transform.as_array())
    pts = np.asarray(use.points)
    tindex = {"x_centre": 0, "z_offset": 1, "scale_x": 2, "scale_z": 3, "rotation": 4}
    npri = []
    for name, k in lay.nuisance:
        p = priors[name]
        if type(p).__name__ != "Normal":
            raise SystemExit(f"the NumPy posterior handles normal priors only, not {p!r}")
        npri.append((name, k, float(p.mu), float(p.sigma)))
    sig_sd = float(priors["repeatability"].sigma)
    log2pi = math.log(2 * math.pi)

    def np_log_prob(th):
        """The same posterior in NumPy (per walker, as a user writes it for emcee)."""
        t = base.copy()
        rb = study.probe.ball_radius
        lp = 0.0
        for name, k, mu, sd in npri:
            v = th[k]
            lp += -0.5 * ((v - mu) / sd) ** 2 - math.log(sd) - 0.5 * log2pi
            if name in tindex:
                t[tindex[name]] += v
            elif name == "ball_radius":
                rb = rb + v
        s = th[lay.sigma_index]
        if s < 0:
            return -np.inf
        lp += -0.5 * (s / sig_sd) ** 2 - math.log(sig_sd) + math.log(2.0) - 0.5 * log2pi
        u = (pts - t[:2]) * (1.0 + t[2:4])
        c, sn = math.cos(t[4]), math.sin(t[4])
        part = np.column_stack([c * u[:, 0] + sn * u[:, 1], -sn * u[:, 0] + c * u[:, 1]])
        ss, n = 0.0, 0
        for kind, sl, idx, geo in feats:
            p, d = part[idx], th[sl]
            if kind == "line":
                nrm, mid = geo
                cc, s2 = math.cos(d[1]), math.sin(d[1])
                rn = np.array([cc * nrm[0] + s2 * nrm[1], -s2 * nrm[0] + cc * nrm[1]])
                r = (p - mid - d[0] * nrm) @ rn - rb
            else:
                cen, rad, sense = geo
                v = p - cen - d[:2]
                r = sense * (np.sqrt(np.sum(v * v, axis=1)) - (rad + d[2])) - rb
            ss += float(r @ r)
            n += len(r)
        return lp - 0.5 * ss / s**2 - n * math.log(s) - 0.5 * n * log2pi

    return log_prob, args, x0, lay.names, np_log_prob


def ess_of(draws) -> tuple[np.ndarray, np.ndarray]:
    """ESS and tau per parameter of kept draws `(S, W, d)` (`W` walkers of one
    ensemble, or `W` chains): `S * W / tau`, tau by `_taus` (the repo's estimator)."""
    x = np.asarray(draws, dtype=float)
    tau = _taus(x[None])[0]
    return x.shape[0] * x.shape[1] / tau, tau


def moments(draws) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Mean, sd and the Monte Carlo SE of the sd per parameter of draws `(S, W, d)`:
    the SE of the variance from the ESS (`ess_of`) of the squared deviations, / 2 sd."""
    x = np.asarray(draws, dtype=float)
    flat = x.reshape(-1, x.shape[-1])
    mean, sd = flat.mean(axis=0), flat.std(axis=0, ddof=1)
    sq = (x - mean) ** 2
    se_var = sq.reshape(flat.shape).std(axis=0, ddof=1) / np.sqrt(ess_of(sq)[0])
    return mean, sd, se_var / (2 * sd)


@dataclass
class Run:
    """One sampler's run: times (s), ESS and moments per parameter."""

    label: str
    short: str  # in the agreement table
    compile: float | None  # None: nothing to compile
    burn: float  # burn-in / warm-up
    sample: float  # the kept draws
    kept: str
    tau: float  # largest over parameters, in steps (draws)
    ess: np.ndarray  # per parameter
    moments: tuple[np.ndarray, np.ndarray, np.ndarray]  # mean, sd, SE of the sd
    n_parts: int = 1
    min_ess: float = math.nan  # mean over parts of the smallest ESS
    pro_rata: bool = False  # burn / sample split of one timed loop, by steps

    def __post_init__(self):
        if math.isnan(self.min_ess):
            self.min_ess = float(np.min(self.ess))

    @classmethod
    def of_draws(cls, label, short, draws, compile, burn, sample):
        ess, tau = ess_of(draws)
        s, w, _ = np.shape(draws)
        return cls(label, short, compile, burn, sample, f"{s} x {w}", float(np.max(tau)), ess,
                   moments(draws))  # fmt: skip

    @property
    def rate(self) -> float:
        """ESS per second of burn-in + sampling (compilation excluded), all parts."""
        return self.min_ess * self.n_parts / (self.burn + self.sample)

    @property
    def rate_sampling(self) -> float:
        return self.min_ess * self.n_parts / self.sample


def agreement(a: Run, b: Run) -> tuple[float, float, float, float]:
    """`(max |mean a - mean b| / MCSE, min and max sd ratio a/b, max |sd a - sd b| / SE)`
    over parameters; MCSE = sqrt(sd_a^2 / ESS_a + sd_b^2 / ESS_b), SE likewise from
    both runs' SE of the sd (`moments`)."""
    (ma, sa, ea), (mb, sb, eb) = a.moments, b.moments
    mcse = np.sqrt(sa**2 / a.ess + sb**2 / b.ess)
    ratio = sa / sb
    return (float(np.max(np.abs(ma - mb) / mcse)), float(np.min(ratio)), float(np.max(ratio)),
            float(np.max(np.abs(sa - sb) / np.hypot(ea, eb))))  # fmt: skip


def section_cd(args):
    import emcee

    from piecs_bayes.fit.mcmc import SamplerOptions, sample_posteriors
    from piecs_bayes.fit.mcmc._core import _neg_hessian, sqrt_psd
    from piecs_bayes.fit.mcmc._lockstep import _parts_walkers
    from piecs_bayes.fit.mcmc._moves import emcee_moves
    from piecs_bayes.fit.mcmc._sampler import _vectorised

    print(f"\n## (c) emcee: JAX vs NumPy log posterior; lockstep ensembles\n\n{load()}\n")
    log_prob, pargs, x0, names, np_lp = _posterior()
    d = len(x0)
    h = np.asarray(_neg_hessian(log_prob)(jnp.asarray(x0), pargs))
    w_, v_ = np.linalg.eigh(0.5 * (h + h.T))
    cov = (v_ / w_) @ v_.T
    root = sqrt_psd(cov)
    rng = np.random.default_rng(0)
    probe_pts = x0 + rng.standard_normal((50, d)) @ root.T
    vec = _vectorised(log_prob)
    lj = np.asarray(vec(jnp.asarray(probe_pts), pargs))
    ln = np.array([np_lp(p) for p in probe_pts])
    same = float(np.max(np.abs(lj - ln)))
    nw = max(64, 4 * d)
    nsteps = 600 if args.quick else 4000
    burn = nsteps // 4
    p0 = x0 + rng.standard_normal((nw, d)) @ root.T
    # the lockstep's mixture (80 % DEMove, 20 % StretchMove), not DESnookerMove: emcee
    # 3.1.6's is biased (sds ~5 % too small here, sigma's mean 5 MCSE off; see fit._moves)
    moves = emcee_moves("de")

    def f_jax(p):
        out = np.asarray(vec(jnp.asarray(p), pargs), dtype=float)
        return np.where(np.isnan(out), -np.inf, out)

    t0 = time.perf_counter()
    f_jax(p0)  # compile
    t_jit = time.perf_counter() - t0
    runs = []
    for label, short, fn, vecz, comp in (
            ("JAX (jit+vmap, vectorize=True)", "JAX", f_jax, True, t_jit),
            ("NumPy (per walker)", "NumPy", np_lp, False, None)):  # fmt: skip
        sampler = emcee.EnsembleSampler(nw, d, fn, vectorize=vecz, moves=moves)
        t0 = time.perf_counter()
        sampler.run_mcmc(p0, burn, progress=False)
        t_burn = time.perf_counter() - t0
        t0 = time.perf_counter()
        sampler.run_mcmc(None, nsteps - burn, progress=False)
        t_samp = time.perf_counter() - t0
        draws = sampler.get_chain(discard=burn)
        runs.append(
            Run.of_draws(f"emcee + {label}", f"emcee + {short}", draws, comp, t_burn, t_samp)
        )
    for backend, n_parts in (("numpy", 1), ("jax", 1), ("jax", 16)):
        xs = np.repeat(x0[None], n_parts, axis=0)
        a = jax.tree_util.tree_map(lambda z, n=n_parts: jnp.repeat(z[None], n, axis=0), pargs)
        cov0 = np.repeat(cov[None], n_parts, 0)
        opts = SamplerOptions(nwalkers=nw, nsteps=nsteps, n_ensembles=1, progress=False,
                              on_fail="ignore", moves="de")  # fmt: skip
        kw = dict(names=names, args=a, cov0=cov0, options=opts, backend=backend)
        t0 = time.perf_counter()
        _parts_walkers(log_prob)(jnp.asarray(np.repeat(xs[:, None], nw // 2, 1)), a)  # compile
        if backend == "jax":  # compile the chain (the same shapes as the timed run)
            sample_posteriors(log_prob, xs, **kw)
        t_first = time.perf_counter() - t0
        t0 = time.perf_counter()
        posts = sample_posteriors(log_prob, xs, **kw)
        t_call = time.perf_counter() - t0
        # Posterior.wall_time: the sampling loop (burn-in included) per part, no compilation;
        # Posterior.tau: `_taus` of the unthinned kept draws (thin="auto" thins after it)
        wall = posts[0].wall_time * n_parts
        ess = [(nsteps - burn) * nw / p.tau for p in posts]
        p = posts[0]
        runs.append(Run(f"sample_posteriors, backend={backend!r}, {n_parts} part(s) in lockstep",
                        f"lockstep {backend}",
                        t_first - (t_call if backend == "jax" else 0.0),
                        wall * burn / nsteps, wall * (nsteps - burn) / nsteps,
                        f"{nsteps - burn} x {nw}" + (f" x {n_parts}" if n_parts > 1 else ""),
                        float(np.max(p.tau)), ess[0], moments(p.chains), n_parts=n_parts,
                        min_ess=float(np.mean([np.min(e) for e in ess])),
                        pro_rata=True))  # fmt: skip
    base = runs[1].rate
    rows = [[r.label, f"{r.burn + r.sample:.1f} s",
             f"{r.tau:.0f}", f"{r.min_ess:.0f}", f"{r.rate:.0f}", f"{r.rate / base:.1f}x"]
            for r in runs]  # fmt: skip
    print(table(rows, [f"sampler (d={d}, {nw} walkers, {nsteps} steps, moves='de')", "wall",
                       "tau (steps)", "min ESS", "ESS/s", "vs NumPy"]))  # fmt: skip
    print(
        f"\nSame posterior: |log p JAX - log p NumPy| <= {same:.1e} at 50 points of the start "
        f"ball. wall: the {nsteps} steps (burn-in {burn} included; compilation excluded: a "
        "first run of the same shapes). ESS = kept steps x walkers / tau (emcee's estimator, "
        "c=5, `_taus`), smallest over parameters; lockstep rows: ESS/s counts the samples of "
        f"all parts. tau from chains shorter than 50 tau is rough (here {nsteps - burn} kept "
        "steps). moves='de': 80 % emcee's DEMove, 20 % StretchMove in every sampler "
        "(`fit._moves.emcee_moves`; emcee 3.1.6's DESnookerMove is biased)."
    )
    return section_d(args, log_prob, pargs, x0, cov, runs, nsteps, burn)


def _nuts(numpyro_infer, potential, d, n_warm, n_samp):
    """numpyro's NUTS kernel (`NUTS.init`, then `NUTS.sample`: what `MCMC.run` iterates)
    in a jitted `lax.scan` of `block` iterations, compiled ahead of time, so that the
    compilation, the warm-up and the sampling are timed apart."""
    kernel = numpyro_infer.NUTS(potential_fn=potential)
    block = math.gcd(n_warm, n_samp)

    def init(seed):
        t0 = time.perf_counter()
        state = kernel.init(jax.random.PRNGKey(seed), n_warm, init_params=jnp.zeros(d))
        return jax.block_until_ready(state), time.perf_counter() - t0

    _, t_init_first = init(1)  # traces and compiles the step-size search
    state, t_init = init(0)

    def run_block(s):
        def one(s, _):
            s = kernel.sample(s, (), {})
            return s, (s.z, s.num_steps, s.diverging)

        return jax.lax.scan(one, s, None, length=block)

    t0 = time.perf_counter()
    step = jax.jit(run_block).lower(state).compile()
    t_compile = time.perf_counter() - t0

    def iterate(state, n):
        outs = []
        for _ in range(n // block):
            state, out = step(state)
            outs.append(out)
        jax.block_until_ready(outs)
        return state, [np.concatenate([np.asarray(o[k]) for o in outs]) for k in range(3)]

    t0 = time.perf_counter()
    state, _ = iterate(state, n_warm)
    t_warm = time.perf_counter() - t0
    t0 = time.perf_counter()
    state, (z, steps, div) = iterate(state, n_samp)
    t_samp = time.perf_counter() - t0
    info = dict(init=t_init, block=block, step_size=float(state.adapt_state.step_size),
                steps=float(np.mean(steps)), divergences=int(np.sum(div)))  # fmt: skip
    return z, t_init_first - t_init + t_compile, t_init + t_warm, t_samp, info


def _seconds(t: float | None) -> str:
    """A compile time: '-' when there is nothing to compile, '< 0.1 s' when the first
    run minus the timed run is within the noise."""
    return "-" if t is None else "< 0.1 s" if t < 0.05 else _s(t)


def _s(t: float) -> str:
    return f"{t:.2f} s" if t < 1 else f"{t:.1f} s"


def section_d(args, log_prob, pargs, x0, cov, runs, nsteps, burn):
    print(f"\n## (d) NumPyro NUTS on the same posterior\n\n{load()}\n")
    try:
        import numpyro
        import numpyro.infer as infer
    except ImportError as e:
        print(f"{e.name or 'numpyro'} is not installed: (d) skipped "
              "(pip install -c constraints.txt -e '.[bench]').")  # fmt: skip
        return None
    # NUTS is not affine invariant: it samples standardised z, theta = x0 + L z (L from
    # the Hessian at the optimum; a constant Jacobian, the same posterior), as a NUTS
    # user would, adapting a diagonal mass matrix and the step size in the warm-up
    d = len(x0)
    chol = np.linalg.cholesky(cov)
    lj, x0j = jnp.asarray(chol), jnp.asarray(x0)

    def potential(z):
        v = -log_prob(x0j + lj @ z, pargs)
        return jnp.where(jnp.isfinite(v), v, jnp.inf)

    n_warm, n_samp = burn, nsteps - burn
    z, t_comp, t_warm, t_samp, info = _nuts(infer, potential, d, n_warm, n_samp)
    nuts = Run.of_draws(f"NumPyro {numpyro.__version__} NUTS (diagonal mass), 1 chain", "NUTS",
                        (x0 + z @ chol.T)[:, None], t_comp, t_warm, t_samp)  # fmt: skip
    # the user's one call, same settings (compilation, warm-up and sampling together)
    mcmc = infer.MCMC(infer.NUTS(potential_fn=potential), num_warmup=n_warm,
                      num_samples=n_samp, progress_bar=False)  # fmt: skip
    t0 = time.perf_counter()
    mcmc.run(jax.random.PRNGKey(1), init_params=jnp.zeros(d))
    t_mcmc = time.perf_counter() - t0
    user = Run.of_draws("NumPyro NUTS, MCMC.run", "NUTS by MCMC.run (other seed)",
                        (x0 + np.asarray(mcmc.get_samples()) @ chol.T)[:, None], None, 0.0,
                        t_mcmc)  # fmt: skip
    base = runs[1]  # emcee + NumPy
    rows = []
    for r in (*runs, nuts):
        pr = "~" if r.pro_rata else ""
        rows.append([r.label, _seconds(r.compile),
                     pr + _s(r.burn), pr + _s(r.sample), r.kept, f"{r.tau:.1f}",
                     f"{r.min_ess:.0f}", f"{r.rate:.0f}", f"{pr}{r.rate_sampling:.0f}",
                     f"{r.rate / base.rate:.1f}x"])  # fmt: skip
    print(table(rows, [f"sampler (same posterior, d={d})", "compile", "burn-in / warm-up",
                       "sampling", "kept draws", "tau (draws)", "min ESS", "ESS/s",
                       "ESS/s sampling only", "vs emcee + NumPy"]))  # fmt: skip
    print(
        "\nCounted: compile = the first calls' tracing and XLA compilation (persistent cache as "
        "found; emcee + JAX: the log posterior; lockstep: first run minus the timed run; NUTS: "
        f"the first `NUTS.init` minus the second, plus `jit(lax.scan of {info['block']} "
        "NUTS.sample)` compiled ahead), never in ESS/s. burn-in / warm-up = the "
        f"{burn} steps (NUTS iterations) before the {nsteps - burn} kept ones (NUTS: its "
        f"init's step-size search, {info['init']:.2f} s, and the step-size and mass "
        "adaptation; ~: the lockstep's one timed loop split by steps). ESS/s = smallest ESS "
        "over parameters / (burn-in + sampling), all parts; 'sampling only' leaves the "
        "burn-in out. ESS: one estimator for all, kept steps x walkers (chains) / tau, tau "
        "by `_taus` (emcee's, c=5)."
    )
    print(
        f"\nNUTS: step size {info['step_size']:.3f} (in standardised coordinates), "
        f"{info['steps']:.1f} leapfrog steps per draw, {info['divergences']} divergences. "
        f"numpyro's `MCMC.run`, same settings, one call: {t_mcmc:.1f} s (compilation, "
        f"warm-up and sampling), min ESS {user.min_ess:.0f}, {user.min_ess / t_mcmc:.0f} ESS/s "
        "all included."
    )
    lock = runs[3]  # sample_posteriors, jax, 1 part
    pairs = [(r, base) for r in (runs[0], runs[2], lock, nuts)] + [(nuts, lock), (user, nuts)]
    rows, worst = [], 0.0
    for a, b in pairs:
        zm, lo, hi, zs = agreement(a, b)
        worst = max(worst, zm, zs)
        ok = "yes" if max(zm, zs) <= AGREE_Z else "NO"
        rows.append([f"{a.short} vs {b.short}", f"{zm:.2f}", f"{lo:.3f} - {hi:.3f}",
                     f"{zs:.2f}", ok])  # fmt: skip
    print()
    print(table(rows, ["same posterior? (20 parameters)", "max |mean diff| / MCSE",
                       "sd ratio (min - max)", "max |sd diff| / SE", "agree"]))  # fmt: skip
    print(
        "\nPer parameter: MCSE of a mean difference sqrt(sd_a^2 / ESS_a + sd_b^2 / ESS_b) (ESS "
        "as above); SE of an sd from the ESS of the squared deviations (same estimator); "
        f"agree: both <= {AGREE_Z:g}. emcee + JAX and + NumPy draw the same random numbers: "
        "the same chain to rounding. lockstep: its stored (thinned) draws. "
        + ("All samplers agree." if worst <= AGREE_Z else "SOME SAMPLERS DISAGREE.")
    )
    return nuts.rate
