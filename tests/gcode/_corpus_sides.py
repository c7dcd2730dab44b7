"""The corpus programs (tests/data/gcode/*.ngc) whose moves in air do not confirm the
side of their G41/G42 (issue 42): `nose_compensate(kind="auto")` refuses them, naming
``--kind``; with the kind each one is, they are resolved as before. Every other corpus
program's moves agree with its G41/G42 (tests/gcode/test_material_side.py checks both).
"""

from __future__ import annotations

from pathlib import Path

#: program -> (its kind, why its moves do not tell it)
SAID_BY_KIND: dict[str, tuple[str, str]] = {
    "03_od_toward_tailstock_t1_g41.ngc": (
        "external",
        "entered from behind the contour and left in front of it: no move in air passes beside it",
    ),
    "08_bore_toward_face_t8_g42.ngc": (
        "internal",
        "entered from behind the contour and left in front of it: no move in air passes beside it",
    ),
    "09_od_arcs_reversed_t9_g41.ngc": (
        "external",
        "entered from behind the contour and left in front of it: no move in air passes beside it",
    ),
    "19_full_finish_t10.ngc": (
        "external",
        "its third roughing pass (line 14, X31 to Z-34.5) cuts below the finish taper "
        "(line 27), so the rapid after it (line 15) passes below the finish contour and "
        "the exit (line 31) above it: air on both sides",
    ),
    "28_comp_on_at_program_end.ngc": (
        "external",
        "compensation is still on at the program's end: no exit, no move beside it",
    ),
    "29_bore_ring_in_front_and_behind_t2.ngc": (
        "internal",
        "a ring's bore left behind the ring and back over it (lines 10-11): where a "
        "bore's wall would be, as far as the program says",
    ),
}


def corpus_kind(path: str | Path) -> str:
    """The `kind` that resolves corpus program `path`: ``"auto"`` unless listed."""
    listed = SAID_BY_KIND.get(Path(path).name)
    return "auto" if listed is None else listed[0]
