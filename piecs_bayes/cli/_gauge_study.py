"""``piecs-bayes gauge-study ...``: is the measuring system capable of the tolerance?

- ``gauge-study type1 FILE [--out DIR]``: the type-1 study of the file's reference
  part (bias, s, Cg, Cgk with intervals, resolution, verdict) and the measuring
  system's VDA 5 budget (Q_MS); writes ``gauge_type1.json`` and the run chart
  ``gauge_type1_run_chart.png``.
- ``gauge-study grr FILE [--out DIR]``: the gauge R&R by ANOVA (interaction test,
  variance components with intervals, %GRR, ndc, the average-and-range cross-check)
  and, with a type-1 study in the file, the budget of system and process (Q_MS, Q_MP);
  writes ``gauge_grr.json`` and ``gauge_grr.png``.
- ``gauge-study program FILE [--out DIR]``: the type-1 program of ``[type1.program]``
  and ``type1_plan.json``; its control file is then ``[type1] probe_file``.

FILE: a gauge-study file (docs/formats.md "Gauge study"). Bad input exits 2 with one
line; a gauge that is not capable is a result (0).
"""

from __future__ import annotations

import argparse
from pathlib import Path

from ._common import finish, out_dir

EXAMPLE = "piecs-bayes gauge-study type1 data/gauge/gauge.toml --out reports/gauge"


def register(subparsers) -> None:
    """Add the ``gauge-study`` command group to the CLI's subparsers."""
    p = subparsers.add_parser(
        "gauge-study",
        help="Is the measuring system (the machine's probe) capable of the tolerance? "
        "Type-1 study, gauge R&R, VDA 5 budget.",
        description="Measuring-system analysis of a gauge-study file (docs/formats.md).",
        epilog=f"example:\n  {EXAMPLE}",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    sub = p.add_subparsers(dest="gauge_command", metavar="STUDY")
    sub.required = True
    for name, help_, func in (
        (
            "type1",
            "Type-1 study on the reference part: bias, s, Cg, Cgk, resolution; the "
            "measuring system's VDA 5 budget (Q_MS).",
            cmd_type1,
        ),
        (
            "grr",
            "Gauge R&R by ANOVA (parts x appraisers x trials): components, %GRR, ndc, "
            "the average-and-range cross-check; with a type-1 study also Q_MS and Q_MP.",
            cmd_grr,
        ),
        (
            "program",
            "The type-1 study run by the machine: the gauging program that touches the "
            "reference [type1.program] repeats times, and type1_plan.json to read the "
            "control's probe file back ([type1] probe_file).",
            cmd_program,
        ),
    ):
        s = sub.add_parser(
            name,
            help=help_.replace("%", "%%"),
            description=help_,
            epilog=f"example:\n  piecs-bayes gauge-study {name} "
            "data/gauge/gauge.toml --out reports/gauge",
            formatter_class=argparse.RawDescriptionHelpFormatter,
        )
        s.add_argument("file", type=Path, help="gauge-study file (TOML)")
        s.add_argument(
            "--out",
            type=Path,
            default=None,
            help="output folder (default: reports/<slug of the [gauge] name>)",
        )
        s.add_argument("--no-figures", action="store_true", help="do not write the PNG figure")
        s.add_argument("--quiet", "-q", action="store_true", help="print only errors")
        s.add_argument(
            "--debug",
            action="store_true",
            default=argparse.SUPPRESS,
            help="show the traceback of an error instead of one line",
        )
        s.set_defaults(func=func)


def _run(args, console, kind: str) -> int:
    from ..export.figures import grr_figure, type1_run_chart_figure
    from ..export.tables import gauge_json, gauge_text
    from ..jobs import gauge_rr_study, gauge_type1_study

    job = gauge_type1_study if kind == "type1" else gauge_rr_study
    result = job(args.file)
    console.step(f"read {result.study!r}")
    out = out_dir(args, result.study)
    console.say(gauge_text(result))
    written = [_write_text(out / f"gauge_{kind}.json", gauge_json(result), result.study)]
    if not args.no_figures:
        name = result.study.name
        fig = (
            type1_run_chart_figure(result.type1, title=name)
            if kind == "type1"
            else grr_figure(result.grr, title=name)
        )
        png = "gauge_type1_run_chart.png" if kind == "type1" else "gauge_grr.png"
        written.append(_write_png(out / png, fig, result.study))
    finish(console, out, written)
    return 0


def _write_text(path: Path, text: str, study) -> Path:
    from ..io import write_text_atomic

    return write_text_atomic(path, text, protect=study.inputs)


def _write_png(path: Path, fig, study) -> Path:
    import io

    from ..io import write_bytes_atomic

    buf = io.BytesIO()
    fig.savefig(buf, format="png")
    return write_bytes_atomic(path, buf.getvalue(), protect=study.inputs)


def cmd_type1(args, console) -> int:
    return _run(args, console, "type1")


def cmd_grr(args, console) -> int:
    return _run(args, console, "grr")


def cmd_program(args, console) -> int:
    from ..io import write_text_atomic
    from ..jobs import gauge_type1_program

    study, files = gauge_type1_program(args.file)
    console.step(f"read {study!r}")
    out = out_dir(args, study)
    p = study.type1.program
    console.say(
        f"type-1 program: {p.repeats} touches of the {p.surface} at "
        f"{'Z' if p.characteristic == 'diameter' else 'X'} {p.at:g} mm with a "
        f"{p.ball_diameter:g} mm ball, {p.controller}; run it, then name the control's "
        "file as [type1] probe_file (and plan) and run `gauge-study type1`"
    )
    written = [write_text_atomic(out / n, t, protect=study.inputs) for n, t in files.items()]
    finish(console, out, written)
    return 0
