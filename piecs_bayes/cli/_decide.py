"""``piecs-bayes decide`` and ``piecs-bayes capability``: is compensation justified,
and what is the process capable of.

- ``decide STUDY --out DIR``: fit one part, decide per feature (compensate with a
  gain, do not compensate, measure more) and write ``decisions.json`` and
  ``decisions.csv``; the table is printed.
- ``capability STUDY [--glob PATTERN] [--scheduler ADDRESS] --out DIR``: fit every
  part of a run (batched; on a Dask cluster with ``--scheduler``), write
  ``capability.json``, ``capability.csv`` (one row per feature and index),
  ``capability_summary.csv`` (one row per feature) and ``capability_parts.csv``
  (values and control-chart flags per part); the tables are printed.

Errors: bad input exits 2, a failed analysis exits 1 (mapped by ``cli.main``).
"""

from __future__ import annotations

from pathlib import Path

from . import _types as T
from ._common import add_common, fit_from_args, out_dir, subcommand, write

EXAMPLES = {
    "decide": "piecs-bayes decide data/demo/study.toml --out reports/decide",
    "capability": "piecs-bayes capability data/batch/study.toml --out reports/capability\n"
    '  piecs-bayes capability data/batch/study.toml --glob "part0*.csv" --out reports/first9',
}


def register(subparsers) -> None:
    """Add ``decide`` and ``capability`` to the CLI's subparsers."""
    p = subcommand(
        subparsers,
        "decide",
        "Decide per feature whether compensation is justified (verdict table, JSON and CSV).",
    )
    p.epilog = f"example:\n  {EXAMPLES['decide']}\n\nSettings: the study's [decision] table."
    p.add_argument("study", type=Path, help="study file (TOML)")
    p.add_argument(
        "--method", choices=("lsq", "robust"), default=None, help="default: the study's fit.method"
    )
    p.add_argument("--part", default=None, help="part id when the probe data holds several parts")
    p.add_argument(
        "--at",
        choices=("worst", "mid", "start", "end"),
        default=None,
        help="where the deviation is taken (default: the study's decision.characteristic, "
        "else the worst of the feature's ends and mid-point)",
    )
    add_common(p)
    p.set_defaults(func=cmd_decide)

    p = subcommand(
        subparsers,
        "capability",
        "Capability study over many parts: Cp, Cpk, Pp, Ppk with intervals, stability, "
        "capability after compensation.",
    )
    p.epilog = f"example:\n  {EXAMPLES['capability']}\n\nSettings: the study's [capability] table."
    p.add_argument("study", type=Path, help="study file (TOML)")
    p.add_argument(
        "--glob",
        default=None,
        help="probe files relative to the study's folder (default: the study's probe_files); "
        "one file per part or a 'part' column; production order = sorted file names",
    )
    p.add_argument(
        "--method", choices=("lsq", "robust"), default=None, help="default: the study's fit.method"
    )
    p.add_argument(
        "--scheduler",
        default=None,
        metavar="ADDRESS",
        help="Dask scheduler (e.g. tcp://10.0.0.5:8786): send chunks of parts to that "
        "cluster (its workers need piecs_bayes installed); default: fit in this process",
    )
    p.add_argument(
        "--chunk-parts",
        type=T.positive_int,
        default=None,
        metavar="N",
        help="parts per batch fit (per task with --scheduler; default: fit.CHUNK_PARTS)",
    )
    add_common(p)
    p.set_defaults(func=cmd_capability)


def cmd_decide(args, console) -> int:
    from ..export.tables import decisions_csv, decisions_json, decisions_text
    from ..jobs import decide_study

    study, probe, fit = fit_from_args(args, console)
    table = decide_study(study, fit, characteristic=args.at)
    console.step(f"decided {len(table.decisions)} features")
    out = out_dir(args, study)
    written: list[Path] = []
    write(out, "decisions.json", decisions_json(table), study, console, written)
    write(out, "decisions.csv", decisions_csv(table), study, console, written)
    console.say(decisions_text(table))
    for p in written:
        console.say(f"wrote {p}")
    return 0


def cmd_capability(args, console) -> int:
    from ..errors import InputError
    from ..export.tables import capability_csvs, capability_json, capability_text
    from ..io import load_study
    from ..jobs import capability_study, load_probe_data

    study = load_study(args.study)
    console.step(f"read {study!r}")
    files = None
    if args.glob is not None:
        files = sorted(study.path.parent.glob(args.glob))
        if not files:
            raise InputError(
                f"--glob {args.glob!r} matches no file in {study.path.parent}", value=args.glob
            )
    probe = load_probe_data(study, files)
    n = len(probe.parts)
    console.step(f"read {len(probe)} probe points of {n} parts")
    where = f" on {args.scheduler}" if args.scheduler else ""

    def progress(i, total, part):  # called after each chunk of parts
        console.step(f"fitted {i}/{total} parts ({part}){where}")

    result = capability_study(
        study,
        probe,
        method=args.method,
        seed=args.seed,
        progress=progress,
        scheduler=args.scheduler,
        chunk_parts=args.chunk_parts,
    )
    out = out_dir(args, study)
    written: list[Path] = []
    write(out, "capability.json", capability_json(result), study, console, written)
    for name, text in capability_csvs(result).items():
        write(out, name, text, study, console, written)
    console.say(capability_text(result))
    for p in written:
        console.say(f"wrote {p}")
    return 0
