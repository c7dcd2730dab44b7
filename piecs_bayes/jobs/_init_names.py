"""The names and general tolerances `init` gives the features of a finish contour.

Ids: ``dia_<Ø>`` / ``bore_<Ø>`` (a line of constant x, external / internal),
``face_z<depth>`` (constant z, depth = -z; ``face_zp<z>`` for z > 0), ``taper_<n>``,
``arc_<n>``; numbers in the study's units (4 decimals in mm, 5 in inches, trailing
zeros stripped, ``p`` for the point, ``m`` for a minus); a repeat gets ``_2``, ``_3``.
Tolerances: ISO 2768-1 by nominal size (`geometry.iso2768_tolerance`): a
diameter's diameter, a face's distance from Z0 (at least 0.5 mm), a taper's length
(Table 1), an arc's radius (Table 2), written as drawn on `tolerance_on`.
"""

from __future__ import annotations

import math

from ..gcode import FinishContour
from ..geometry import feature_form, iso2768_tolerance

MM_PER = {"mm": 1.0, "in": 25.4}


def _num(value: float, units: str) -> str:
    text = f"{value:.{5 if units == 'in' else 4}f}".rstrip("0").rstrip(".")
    text = "0" if text in ("-0", "") else text
    return text.replace("-", "m").replace(".", "p")


def feature_ids(contour: FinishContour, units: str) -> list[tuple[str, str]]:
    """`(id, form)` of every segment of `contour`, ids unique (see the module doc)."""
    scale = MM_PER[units]
    count = {"taper": 0, "arc": 0}
    seen: dict[str, int] = {}
    out = []
    for s in contour.segments:
        form = feature_form(s.start, s.end, s.center)
        if form == "cylinder":
            head = "dia" if contour.kind == "external" else "bore"
            fid = f"{head}_{_num(2 * s.start[0] / scale, units)}"
        elif form == "face":
            z = s.start[1] / scale
            fid = f"face_zp{_num(z, units)}" if z > 0 else f"face_z{_num(-z, units)}"
        else:
            count[form] += 1
            fid = f"{form}_{count[form]}"
        seen[fid] = seen.get(fid, 0) + 1
        out.append((fid if seen[fid] == 1 else f"{fid}_{seen[fid]}", form))
    return out


def general_tolerance(seg, form: str, tol_class: str, units: str):
    """`(tolerance_on, ±t in the study's units, comment)` of a contour segment of
    `form` (`geometry.feature_form`) in ISO 2768 class `tol_class`."""
    if form == "cylinder":
        on, size, what = "diameter", 2 * abs(seg.start[0]), "Ø{} mm"
    elif form == "face":
        depth = abs(seg.start[1])
        on, size = "length", max(depth, 0.5)
        what = f"the face {depth:.6g} mm from Z0" + (" (as 0.5 mm)" if depth < 0.5 else "")
    elif form == "taper":
        on, size, what = "normal", math.dist(seg.start, seg.end), "a taper {} mm long"
    else:
        on, size, what = "normal", seg.radius, "R{} mm"
    gt = iso2768_tolerance(size, tol_class, table="radius" if form == "arc" else "linear")
    comment = f"{gt.label} general tolerance for {what.replace('{}', f'{size:.6g}')}"
    if gt.note:
        comment += f" ({gt.note})"
    return on, gt.value / MM_PER[units], f"{comment}: replace with the drawing's"
