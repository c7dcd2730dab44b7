"""The report of a feedback run (`piecs-bayes feedback`): the policy table, the
next-part recommendation, the predictive coverage, the steps and odd parts, the
finished-part check and the figures, as one self-contained HTML document (the
blocks and styles of the job report)."""

from __future__ import annotations

import html
import math
from pathlib import Path

from ...io import write_bytes_atomic, write_text_atomic
from ..figures import RC, feedback_figures, feedback_policy_figure, feedback_track_figure
from ..tables import feedback_csvs, feedback_json
from ._html import CSS, render_html_block
from .model import Fig, Para, Pre, Table, num

#: the drawn coordinate in a table cell
_ON = {"diameter": "Ø", "radius": "R", "length": "Z", "normal": "normal"}


def _policy_table(res) -> Table:
    names = list(res.policies)
    rows, cells = [], []
    for f in res.features.values():
        k = abs(f.scale)
        vals = [f.policies[n].rmsd_mm * k if n in f.policies else math.nan for n in names]
        best = min(v for v in vals if math.isfinite(v))
        rows.append([f.feature, _ON.get(f.coordinate, f.coordinate)]
                    + [num(v, ".2f") for v in vals])  # fmt: skip
        cells.append(["", ""] + ["ok" if v == best else "" for v in vals])
    over = [res.overall(n) for n in names]
    rows.append(["all (δ)", "normal"] + [num(o["rmsd_mm"], ".2f") for o in over])
    cells.append([""] * (2 + len(names)))
    rows.append(["out of tolerance", ""] + [str(o["out_of_tolerance"]) for o in over])
    cells.append([""] * (2 + len(names)))
    rows.append(["adjustments", ""] + [str(o["adjustments"]) for o in over])
    cells.append([""] * (2 + len(names)))
    return Table(
        ["feature", "on"] + [f"{res.policy_label(n)} (µm)" for n in names],
        rows,
        cells=cells,
        caption="RMS realised deviation per policy, as drawn (µm on the feature's "
        "coordinate; 'all': the normal deviation over every feature and part), on the "
        "counterfactual that a correction adds to the following parts. Two comparisons "
        "for the anchors (fixed_gain, mean_value, ewma, dewma and the controllers' own "
        "rules siemens, renishaw, heidenhain): (a) the one setting a shop "
        "tunes for the machine (compensate.SHOP_SETTINGS, the same for every run); (b) "
        "tuned on this run over their documented grids (a hindsight advantage bayes does "
        "not get; full is not tuned). bayes has fixed settings; green: the lowest.",
    )


def _settings_cell(settings) -> str:
    """A policy's settings in one cell (`gain=0.5 null_band=0.1 ...`; the mm twins left out)."""
    out = []
    for k, v in settings.items():
        if k.endswith("_mm") or isinstance(v, dict):
            continue
        out.append(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}")
    return " ".join(out) or "–"


def _settings_table(res) -> Table:
    names = [n for n in res.policies if n not in ("none", "full", "bayes")]
    rows = [[f.feature] + [_settings_cell(f.policies[n].settings) if n in f.policies else "–"
                           for n in names] for f in res.features.values()]  # fmt: skip
    return Table(["feature"] + [res.policy_label(n) for n in names], rows,
                  caption="The anchors' settings per feature ((a): the machine's one "
                  "setting; (b): tuned on this run; fixed_gain: gain, null "
                  "band and upper limit as fractions of the tolerance half-width; "
                  "mean_value: window K; ewma: λ; dewma: λ1, λ2; siemens: _K, _TZL, "
                  "_TMV, _TDIF, _TSA (mm); renishaw: F (fraction), V, U (mm); "
                  "heidenhain: RBREAK (mm); inf: not programmed).")  # fmt: skip


def _next_table(res) -> Table:
    rows = []
    for r, f in zip(res.next_part_rows(), res.features.values(), strict=True):
        k = abs(f.scale)
        rows.append([
            r["feature"], _ON.get(r["coordinate"], r["coordinate"]),
            num(r["correction_drawn_mm"], "+.2f"), num(r["u_drawn_mm"], ".2f"),
            num(r["u_with_systematic_mm"] * k, ".2f"), num(r["level_mm"] * f.scale, "+.2f"),
            r["verdict"],
            "–" if f.transfer is None else f"{f.transfer[0]:.3f} ± {f.transfer[1]:.3f}",
        ])  # fmt: skip
    return Table(
        ["feature", "on", "correction (µm)", "u (µm)", "u with systematic (µm)",
         "predicted level (µm)", "verdict", "transfer β"],
        rows,
        caption="The bayes policy's correction for the next part, as drawn: the total "
        "correction to apply (the run was cut without one), its standard uncertainty (of "
        "the predicted level), and with the systematic uncertainty common to every part "
        "(probe, machine) added; the level the finish cut is predicted to show.",
    )  # fmt: skip


def _steps_lines(res) -> list[str]:
    out = []
    for f in res.features.values():
        for s in f.steps:
            how = "declared tool change" if s["declared"] else "step found"
            out.append(f"{f.feature}: {how} before {s['part']} (p_step {s['p_step']:.2f})")
        if f.odd_parts:
            out.append(f"{f.feature}: odd part(s) {', '.join(f.odd_parts)}")
    return out or ["no step and no odd part found"]


def feedback_blocks(res, png: dict | None = None) -> list:
    """The report's blocks, in order."""
    cov = res.coverage()
    blocks = [
        Para(
            f"{len(res.parts)} parts ({res.parts[0]} … {res.parts[-1]}) in production "
            f"order, fits {res.method}, characteristic at {res.characteristic}; policies "
            f"replayed on the {res.replayed_on} deviations. Declared tool changes: "
            f"{', '.join(res.tool_changes) or 'none'}."
        ),
        _policy_table(res),
        _settings_table(res),
        _next_table(res),
        Para(
            f"95 % one-step-ahead predictive coverage: {cov['overall']:.1%} of {cov['n']} "
            "parts (each part's interval from the parts before it only; "
            + ", ".join(f"{k} {v:.0%}" for k, v in cov["features"].items())
            + ")."
        ),
        Pre(_steps_lines(res), caption="Steps and odd parts"),
    ]
    fin = res.finish_rows()
    if fin:
        blocks.append(Table(
            ["feature", "finished parts", "β", "u(β)", "residual sd (µm)",
             "coverage, one step", "coverage, from semifinish"],
            [[r["feature"], str(r["n_finished"]), f"{r['transfer']:.3f}",
              f"{r['u_transfer']:.3f}", num(r["residual_sd_mm"], ".2f"),
              f"{r['coverage_one_step']:.0%}", f"{r['coverage_from_semifinish']:.0%}"]
             for r in fin],
            caption="Post-process loop: the transfer coefficient β (finish = β × semifinish) "
            "from the finished parts, and the share of finished parts inside the 95 % finish "
            "bounds predicted before the part was cut (one step) and from its own semifinish "
            "measurement.",
        ))  # fmt: skip
    if res.notes:
        blocks.append(Pre(list(res.notes), caption="Notes"))
    blocks += [
        Fig("feedback_tracks", lambda: feedback_track_figure(res),
             "Deviation per part as drawn, with the 95 % one-step-ahead predictive band, "
             "steps, odd parts, each policy's realised deviation and the tolerance."),
        Fig("feedback_policies", lambda: feedback_policy_figure(res),
             "RMS realised deviation per policy and feature, relative to the tolerance."),
    ]  # fmt: skip
    return blocks


def feedback_report_html(res, *, png: dict | None = None) -> str:
    """The feedback report as one self-contained HTML document (figures as base64 PNG;
    `png`: figures already rendered, by name)."""
    from matplotlib import rc_context

    e = html.escape
    title = f"piecs_bayes feedback: {res.study}"
    with rc_context(RC):
        body = [render_html_block(b, png or {}) for b in feedback_blocks(res)]
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{e(title)}</title><style>{CSS}</style></head><body>",
        f"<header><h1>{e(title)}</h1><p>lengths in mm, deviations in µm (as drawn where "
        "marked Ø or Z)</p></header>",
        '<section id="feedback"><h2>Feedback over the run</h2>',
        *body,
        "</section></body></html>",
    ]
    return "\n".join(parts) + "\n"


def write_feedback(res, out, *, protect=(), figures: bool = True, report: bool = True):
    """Write feedback.json, the CSVs, the figures (PNG) and report.html into `out`,
    each atomically and never over a file in `protect`. Returns the paths written."""
    out = Path(out)
    written = [write_text_atomic(out / "feedback.json", feedback_json(res), protect=protect)]
    for name, text in feedback_csvs(res).items():
        written.append(write_text_atomic(out / name, text, protect=protect))
    png = {}
    if figures or report:
        for name, data in feedback_figures(res).items():
            png[name] = data
            if figures:
                written.append(write_bytes_atomic(out / f"{name}.png", data, protect=protect))
    if report:
        html = feedback_report_html(res, png=png)
        written.append(write_text_atomic(out / "feedback_report.html", html, protect=protect))
    return written
