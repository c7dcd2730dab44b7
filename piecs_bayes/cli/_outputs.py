"""Results tables of one part written by the commands (fit, bounds, posterior), and
the fit printed on the console."""

from __future__ import annotations

from ._common import write


def bayes_from_args(args, study, probe, fit, console):
    from ..jobs import bayes_study

    console.step("sampling the posterior (MCMC)")
    bayes = bayes_study(
        study, fit, probe, part=fit.part, nsteps=args.steps, seed=args.seed,
        progress=not args.quiet,
    )  # fmt: skip
    post = bayes.posterior
    console.step(
        f"posterior: {len(bayes.names)} parameters, "
        f"{'converged' if post.converged else 'NOT converged'}, "
        f"{post.ess_per_second:.0f} effective samples/s"
    )
    return bayes


def write_bayes(out, study, bayes, console, written):
    from ..export.tables import posterior_csv

    console.step("writing the posterior: posterior.csv (summary) and posterior.nc (draws)")
    write(out, "posterior.csv", posterior_csv(bayes), study, console, written)
    from ..io import write_file_atomic

    # the full InferenceData: dims, units, observed data, log likelihood, prior
    path = write_file_atomic(out / "posterior.nc", bayes.to_netcdf, protect=[study.path])
    written.append(path)
    console.step(f"wrote posterior.nc ({path.stat().st_size / 1e6:.1f} MB)")


def write_fit(out, study, fit, console, written):
    from ..export.tables import fit_csv, fit_json, residuals_csv

    write(out, "fit.json", fit_json(fit, study=study), study, console, written)
    write(out, "fit.csv", fit_csv(fit), study, console, written)
    write(out, "residuals.csv", residuals_csv(fit), study, console, written)


def print_fit(fit, console):
    console.say(
        f"{'feature':<12}{'parameter':<11}{'value':>14}{'std.unc.':>12}  outliers (file lines)"
    )
    for f in fit:
        lines = ", ".join(str(int(f.lines[i])) for i in f.outliers) or "-"
        se = f.std_errors if f.std_errors is not None else [float("nan")] * len(f.values)
        for k, (name, v, s) in enumerate(zip(f.param_names, f.values, se, strict=True)):
            unit = "rad" if name == "rotation" else "mm"
            console.say(
                f"{f.id if k == 0 else '':<12}{name:<11}{v:>+12.6f} {unit:<4}{s:>9.6f}  "
                + (lines if k == 0 else "")
            )
    if fit.unmeasured:
        console.say(f"not measured (left as drawn): {', '.join(fit.unmeasured)}")


def write_bounds(out, study, probe, fit, bayes, gain, console, written):
    from ..jobs import toolpath_uncertainty

    unc = toolpath_uncertainty(study, fit, probe, bayes=bayes, gain=gain)
    for tpu in unc.values():
        if tpu is not None:
            console.step(f"tool-path bounds: {tpu!r}")
    write_unc(out, study, unc, console, written)
    return unc


def write_unc(out, study, unc, console, written):
    from ..export.tables import band_csv, bounds_csv, bounds_json, budget_csv

    for key, tpu in unc.items():
        if tpu is None:
            continue
        suffix = "" if key == "linearised" else "_mc"
        write(out, f"toolpath_bounds{suffix}.csv", bounds_csv(tpu), study, console, written)
        write(
            out, f"toolpath_band{suffix}.csv", band_csv(tpu, study.profile), study, console, written
        )
    write(
        out,
        "uncertainty_budget.csv",
        budget_csv(unc["linearised"], study.profile),
        study,
        console,
        written,
    )
    write(out, "toolpath_bounds.json", bounds_json(unc, study.profile), study, console, written)
