"""Reading back what `piecs-bayes fit` / `decide` wrote into a folder: the extra
points its "measure more" verdicts ask for (``decisions.json``) and the points its
part was probed at (``residuals.csv``), for ``plan --more``. A file that cannot be
read or is not the tool's is an `InputError` naming it (and the line of a bad row).
"""

from __future__ import annotations

import csv
import json
from pathlib import Path

from ..errors import InputError


def read_more_points(folder) -> tuple[dict[str, int], dict[str, list]]:
    """`({feature: extra points}, {feature: probed nominal points})` from a fit folder's
    decisions.json (verdict "measure more" with a count) and residuals.csv (the
    nominal `(x radius, z)` of every point not flagged an outlier, mm)."""
    folder = Path(folder)
    return _more(folder / "decisions.json"), _probed(folder / "residuals.csv")


def _more(dec: Path) -> dict[str, int]:
    try:
        body = json.loads(dec.read_text(encoding="utf-8"))
        rows = body["features"]
        return {
            r["feature"]: int(r["more_points"])
            for r in rows
            if r.get("verdict") == "measure more" and r.get("more_points")
        }
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", file=str(dec)) from None
    except (ValueError, KeyError, TypeError) as exc:
        raise InputError(f"not a decisions file of piecs-bayes: {exc}", file=str(dec)) from None


def _probed(res: Path) -> dict[str, list]:
    try:
        with open(res, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as exc:
        raise InputError(f"cannot read: {exc.strerror}", file=str(res)) from None
    probed: dict[str, list] = {}
    for i, r in enumerate(rows, start=2):
        try:
            if r.get("outlier") in ("1", "True", "true"):
                continue
            probed.setdefault(r["feature"], []).append(
                (float(r["nominal_x_radius_mm"]), float(r["nominal_z_mm"]))
            )
        except (KeyError, TypeError, ValueError) as exc:
            raise InputError(f"bad row: {exc}", file=str(res), line=i) from None
    return probed
