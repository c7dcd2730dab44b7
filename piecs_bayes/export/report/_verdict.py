"""The report's first page: the verdict a quality manager can sign.

Part and study, one row per feature as drawn (nominal, tolerance, deviation ± U,
conformance in colour, verdict for the next part), the part's conformance in one
sentence, what to load on the machine (the job's route, when it chose one), and
lines to sign. The details follow in the other sections.
"""

from __future__ import annotations

from collections.abc import Mapping

from ..machine import route_file_names
from ._summary import summary_rows, tolerance_text
from .model import PageBreak, Para, Table, css_class, num


def _verdict_table(rows: list[dict]) -> Table:
    cells, table = [], []
    for r in rows:
        state = r["conformance"] or ("not measured" if r["verdict"] == "not measured" else "–")
        table.append(
            [
                r["feature"],
                r["nominal"],
                tolerance_text(r["tol_lower_um"], r["tol_upper_um"], r["coordinate"]),
                num(r["deviation_um"], "+.1f", 1) + " ± " + num(r["U_um"], ".1f", 1),
                state,
                r.get("risk") or "–",
                r["verdict"],
            ]
        )
        cells.append(["", "", "", "", css_class(state), "", css_class(r["verdict"])])
    return Table(
        [
            "feature",
            "nominal (mm)",
            "tolerance (µm)",
            "deviation ± U (µm)",
            "conformance as measured",
            "risk of that decision",
            "verdict for the next part",
        ],
        table,
        caption="Tolerance and deviation as drawn: Ø on the diameter, Z on the axial "
        "position of a face, 'normal' along the surface normal (tapers, arcs); + is more "
        "material. U: expanded uncertainty (95 %). Conforms: inside the tolerance by more "
        "than U; does not conform: outside by more than U; ambiguous: within U of a limit "
        "(ISO 14253-1). Risk (JCGM 106, specific): a part accepted inside the acceptance zone "
        "(the tolerance less U) is out of tolerance with the consumer's risk; one rejected "
        "is in tolerance with the producer's risk.",
        cells=cells,
        emphasis=True,
    )


def _names(rows, state: str) -> list[str]:
    return [r["feature"] for r in rows if r["conformance"] == state]


def _part_sentence(rows: list[dict]) -> Para:
    bad, amb = _names(rows, "does not conform"), _names(rows, "ambiguous")
    measured = [r for r in rows if r["conformance"]]
    if not measured:
        return Para("No conformance decision in this run (decisions switched off).", "note")
    if bad:
        text = f"The part does NOT conform: {', '.join(bad)} outside the tolerance by more than U."
        kind = "fail"
    elif amb:
        text = "Conformance of the part is not proven (ambiguous)."
        kind = "warn"
    else:
        text = "The part conforms: every measured feature is inside its tolerance by more than U."
        kind = "pass"
    if amb:
        text += f" Within U of a limit: {', '.join(amb)}."
    missing = [r["feature"] for r in rows if r["verdict"] == "not measured"]
    if missing:
        text += f" Not measured: {', '.join(missing)}."
    return Para(text, kind)


def _next_part(rows: list[dict]) -> str:
    comp = [r for r in rows if r["verdict"].startswith("compensate")]
    more = [r["feature"] for r in rows if r["verdict"].startswith("measure more")]
    if not any(r["conformance"] for r in rows):
        return ""
    text = f"For the next part: compensate {len(comp)} of {len(rows)} features"
    if comp:
        big = max(comp, key=lambda r: abs(r["correction_um"]))
        on = {"diameter": " on the diameter", "radius": " on the radius", "length": " on Z"}
        text += (
            f" (largest correction {big['correction_um']:+.1f} µm"
            f"{on.get(big['coordinate'], '')} of {big['feature']})"
        )
    keep = [r["feature"] for r in rows if r["verdict"] == "do not compensate"]
    if keep:
        text += f"; leave {', '.join(keep)} as it is"
    if more:
        text += f"; measure {', '.join(more)} again with more probe points"
    return text + "."


def _load_line(res) -> str:
    """'What to load:' from the job's route (`res.apply`: a mapping with `route` and
    `files`, or the route's name), when the job chose one."""
    apply = getattr(res, "apply", None)
    if apply is None:
        return "What to load: no route chosen in this run (see the machine sections)."
    if isinstance(apply, Mapping):
        route, files = apply.get("route"), list(apply.get("files") or [])
    else:
        route, files = str(apply), list(route_file_names(res))
    if route == "none":
        return "What to load: nothing; the machine stays as it is."
    names = ", ".join(str(getattr(f, "name", f)) for f in files)
    why = getattr(res, "apply_why", "")
    return (
        f"What to load: route '{route}'"
        + (f": {names}" if names else "")
        + (f" ({why})" if why else "")
        + ". Load only this route: every route carries the whole correction, two apply "
        "it twice."
    )


def verdict_section(res) -> list:
    """The blocks of the verdict page (then a page break)."""
    rows = summary_rows(res)
    study = res.study
    head = (
        f"Part {res.part or '–'} of {study.name!r} ({study.path.name}): "
        f"{sum(f.n for f in res.fit)} probe points on {len(res.fit.fits)} of "
        f"{len(study.profile)} features; report made {res.created} with piecs_bayes "
        f"{res.versions.get('piecs_bayes', '?')}."
    )
    blocks: list = [Para(head), _verdict_table(rows), _part_sentence(rows)]
    nxt = _next_part(rows)
    if nxt:
        blocks.append(Para(nxt))
    blocks.append(Para(_load_line(res)))
    blocks.append(
        Para(
            "Checked by: ______________________    Date: ______________    "
            "Signature: ______________________",
            "sign",
        )
    )
    blocks.append(PageBreak())
    return blocks
