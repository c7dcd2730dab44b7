"""``piecs-bayes feedback``: feedback over a production run.

- ``feedback STUDY --out DIR [--finish FILE ...] [--no-figures] [--no-report]``:
  fit every part of the run (production order = the study's probe files), track
  every feature from part to part, replay the feedback policies (``feedback.POLICIES``:
  the anchors, among them the controllers' own rules ``siemens``, ``renishaw``,
  ``heidenhain``, and ``bayes``; each anchor in two labelled comparisons: ``(a)`` the
  machine's one setting, ``SHOP_SETTINGS``, and ``(b)`` tuned on the run), write
  ``feedback.json``, ``feedback_parts.csv``, ``feedback_policies.csv``,
  ``feedback_next_part.csv`` (``feedback_finish.csv``), the figures and
  ``feedback_report.html``, and print the summary and the next part's correction.

Settings: the study's ``[feedback]`` table (declared tool changes, policies,
finished-part files, ``inspect_every``, ``delay``). Errors: bad input exits 2, a
failed analysis exits 1 (mapped by ``cli.main``).
"""

from __future__ import annotations

import glob
from pathlib import Path

from ._common import add_common, finish, out_dir, subcommand

EXAMPLE = (
    "piecs-bayes feedback data/batch/study.toml --out reports/feedback\n"
    '  piecs-bayes feedback data/batch/study.toml --finish "data/batch/finish/*.csv" '
    "--out reports/feedback-finish"
)


def register(subparsers) -> None:
    """Add ``feedback`` to the CLI's subparsers."""
    p = subcommand(
        subparsers,
        "feedback",
        "Feedback over a production run: track each feature part to part, replay the "
        "feedback policies, recommend the next part's correction.",
    )
    p.epilog = (
        f"example:\n  {EXAMPLE}\n\nSettings: the study's [feedback] table (tool_changes, "
        "policies, finish_files, characteristic, inspect_every, delay). Anchors are shown "
        "in two comparisons: (a) one setting for the machine (SHOP_SETTINGS), (b) tuned on "
        "this run (hindsight)."
    )
    p.add_argument("study", type=Path, help="study file (TOML)")
    p.add_argument(
        "--finish",
        nargs="+",
        default=None,
        metavar="FILE",
        help="finished-part CSVs (paths or patterns relative to the current folder; "
        "default: the study's feedback.finish_files); see docs/formats.md",
    )
    p.add_argument("--no-figures", action="store_true", help="do not write the PNG figures")
    p.add_argument("--no-report", action="store_true", help="do not write feedback_report.html")
    add_common(p)
    p.set_defaults(func=cmd_feedback)


def _finish_files(patterns) -> list[Path] | None:
    from ..errors import InputError

    if patterns is None:
        return None
    files: list[Path] = []
    for pat in patterns:
        if any(c in pat for c in "*?["):
            found = sorted(Path(f) for f in glob.glob(pat))
            if not found:
                raise InputError(f"--finish {pat!r} matches no file", value=pat)
        else:
            found = [Path(pat)]
        files += [f for f in found if f not in files]
    return files


def cmd_feedback(args, console) -> int:
    from ..export.report import write_feedback
    from ..export.tables import feedback_text
    from ..io import load_study
    from ..jobs import feedback_study, load_probe_data

    study = load_study(args.study)
    console.step(f"read {study!r}")
    probe = load_probe_data(study)
    console.step(f"read {len(probe)} probe points of {len(probe.parts)} parts")
    files = _finish_files(args.finish)
    result = feedback_study(study, probe=probe, finish=files, progress=console.step)
    out = out_dir(args, study)
    protect = [study.path, *study.probe_files, *(files or ())]
    protect += list(study.sections.get("feedback", {}).get("finish_files", ()))
    console.step("writing tables, figures and the report")
    written = write_feedback(
        result, out, protect=protect, figures=not args.no_figures, report=not args.no_report
    )
    console.say(feedback_text(result))
    finish(console, out, written)
    return 0
