"""``piecs-bayes init PROGRAM --out STUDY``: a new study from the finish program.

The study's ``[profile]`` is the program's finish contour (the moves of a
G41/G42 run strictly between its lead-in and its exit move, one feature each),
with readable ids, ``tolerance_on`` by form and ISO 2768-1 general tolerances
marked for replacement; see ``piecs_bayes.jobs._init`` and docs/formats.md
("Study from the part program"). An existing STUDY is written over only with
``--force``; the program never. A contour that cannot be a study (no G41/G42, a
rapid or a thread in it, several runs without ``--run``) exits 2 naming the line.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from . import _types as T

_CLASSES = ("ISO2768-f", "ISO2768-m", "ISO2768-c", "ISO2768-v")


def _tolerance_class(text: str) -> str:
    """``ISO2768-m`` (or just ``m``): one of the ISO 2768-1 classes."""
    t = text.strip()
    short = t[len("ISO2768-") :] if t.upper().startswith("ISO2768-") else t
    if short.lower() not in ("f", "m", "c", "v"):
        raise argparse.ArgumentTypeError(f"expected one of {', '.join(_CLASSES)}, got {text!r}")
    return short.lower()


def register(subparsers) -> None:
    """Add ``init`` to the CLI's subparsers."""
    p = subparsers.add_parser(
        "init",
        help="Write a new study whose [profile] is the finish contour of a part program.",
        description="Write a study file whose [profile] is the finish contour of a lathe "
        "program (the moves between G41/G42 and G40, read with the package's interpreter): "
        "one feature per move between the lead-in and the exit move, readable ids, "
        "tolerance_on by form, ISO 2768 general tolerances to replace with the drawing's.",
        epilog="example:\n  piecs-bayes init data/demo/finish.ngc --out work/study.toml",
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    p.add_argument("program", type=Path, help="the finish part program (.ngc/.nc)")
    p.add_argument("--out", type=Path, required=True, help="the study file to write (.toml)")
    p.add_argument(
        "--kind",
        choices=("external", "internal"),
        default=None,
        help="check the program's G41/G42 against it (default: the program's compensation "
        "side decides: the material is left of travel under G42, right under G41)",
    )
    p.add_argument(
        "--x-mode",
        choices=("diameter", "radius"),
        default="diameter",
        help="how the study writes X (default diameter)",
    )
    p.add_argument(
        "--tolerance-class",
        type=_tolerance_class,
        default="m",
        metavar="{" + ",".join(_CLASSES) + "}",
        help="ISO 2768-1 class of the general tolerances written (default ISO2768-m)",
    )
    p.add_argument(
        "--run",
        type=T.positive_int,
        default=None,
        help="which compensation run (1-based) is the finish contour, when there are several",
    )
    p.add_argument(
        "--tool-table",
        type=Path,
        default=None,
        help="LinuxCNC tool table: [program] nose_radius from the finish tool's diameter",
    )
    p.add_argument(
        "--tool-units",
        choices=("mm", "in"),
        default="mm",
        help="units of the tool table's lengths (default mm)",
    )
    p.add_argument(
        "--nose-radius",
        type=T.positive_mm,
        default=None,
        help="a program without G41/G42 is the tool's path (CAM output): its nose radius "
        "(mm); with --tip, the part contour is taken back from the path",
    )
    p.add_argument(
        "--tip",
        type=int,
        choices=range(10),
        default=None,
        metavar="T",
        help="the point that path is written for: LinuxCNC tool orientation 1-8 (the "
        "imaginary tip), 0 or 9 (the nose centre)",
    )
    p.add_argument(
        "--ball-radius",
        type=T.positive_mm,
        default=None,
        help="the probe's calibrated ball radius (mm; default: a marked placeholder)",
    )
    p.add_argument(
        "--dialect",
        choices=("linuxcnc", "fanuc", "haas", "okuma"),
        default=None,
        help="the program's dialect (default: detected from what it contains, and said)",
    )
    p.add_argument("--force", action="store_true", help="write over an existing STUDY")
    p.add_argument("--quiet", "-q", action="store_true", help="print only errors")
    p.set_defaults(func=cmd_init)


def cmd_init(args, console) -> int:
    from ..jobs import ToolNose, init_study

    result = init_study(
        args.program,
        args.out,
        force=args.force,
        kind=args.kind,
        x_mode=args.x_mode,
        tolerance_class=args.tolerance_class,
        run=args.run,
        nose=ToolNose(args.tool_table, args.tool_units, args.nose_radius, args.tip),
        ball_radius_mm=args.ball_radius,
        dialect=args.dialect,
    )
    c = result.contour
    dialect = next((s for s in result.content.program if s.key == "dialect"), None)
    if dialect is not None:
        console.say(f"{args.program}: read as {dialect.value} ({dialect.comment})")
    source = (
        f"the part contour under the tool path of lines {c.lead_in}-{c.exit}"
        if args.nose_radius is not None
        else f"the finish contour of {c.comp.code} (line {c.comp.line})"
    )
    console.say(
        f"{args.program}: {source}, {c.kind}: {len(c.segments)} features (lead-in line "
        f"{c.lead_in} and exit line {c.exit} are not features)"
    )
    for f, s in zip(result.content.features, c.segments, strict=True):
        console.say(f"  {f.id:<14} {f.type:<4} line {s.line:<4} {s.source}")
    console.say(
        f"wrote {result.path}: replace the ISO 2768-{args.tolerance_class} general tolerances "
        "and the placeholders ([probe], [program]) with yours"
    )
    return 0
