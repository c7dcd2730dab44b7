"""The report as one self-contained HTML document (figures as base64 PNG)."""

from __future__ import annotations

import base64
import html

from ..figures import RC
from ..raster import png_bytes
from ._sections import report_sections
from ._summary import summary_table
from .model import CLASS_COLOURS, Bullets, Fig, PageBreak, Para, Pre, Table, Tables, is_num

CSS = """
body{font-family:system-ui,-apple-system,"Segoe UI",Roboto,Helvetica,Arial,sans-serif;
max-width:1180px;margin:0 auto;padding:1em 1.5em;color:#222;line-height:1.4}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:2px solid #ddd;padding-bottom:.2em;
margin-top:2em}nav ol{columns:3;font-size:.95em}
table{border-collapse:collapse;margin:.6em 0 1em;font-size:.86em}
th,td{border:1px solid #ccc;padding:.25em .5em;text-align:left;vertical-align:top}
th{background:#f2f2f2}td.num{text-align:right;font-variant-numeric:tabular-nums}
caption{caption-side:bottom;text-align:left;font-size:.92em;color:#555;padding-top:.3em}
ul.reasons{margin:.2em 0 .8em;font-size:.92em}h3.verdict{font-size:1em;margin:.8em 0 .2em}
figure{margin:1em 0}figure img{max-width:100%;height:auto;border:1px solid #eee}
figcaption{font-size:.92em;color:#555}
pre{background:#f7f7f7;border:1px solid #e3e3e3;padding:.6em;overflow-x:auto;font-size:.82em}
pre .add{color:#0a6b0a;background:#eaffea}pre .del{color:#a00;background:#ffecec}
pre .hunk{color:#555}
p.warn{background:#fff0f0;border-left:4px solid #c33;padding:.4em .6em}
p.note{background:#f4f4f4;border-left:4px solid #999;padding:.4em .6em}
p.fail{background:#f8d0d0;font-weight:bold;padding:.4em .6em}
p.pass{background:#d9f2d9;font-weight:bold;padding:.4em .6em}
p.sign{margin-top:2.5em}div.tables{display:flex;flex-wrap:wrap;gap:2em;align-items:flex-start}
""" + "".join(f"tr.{c} td,td.{c},h3.{c} span{{background:{v}}}" for c, v in CLASS_COLOURS.items())


def render_html_block(b, png: dict | None = None) -> str:
    e = html.escape
    if isinstance(b, Para):
        cls = "" if b.kind == "p" else f' class="{b.kind}"'
        return f"<p{cls}>{e(b.text)}</p>"
    if isinstance(b, Table):
        return _table_html(b)
    if isinstance(b, Bullets):
        items = "".join(f"<li>{e(r)}</li>" for r in b.items)
        cls = f' class="verdict {b.kind}"' if b.kind else ""
        return f'<h3{cls}><span>{e(b.title)}</span></h3><ul class="reasons">{items}</ul>'
    if isinstance(b, PageBreak):
        return ""
    if isinstance(b, Tables):
        return '<div class="tables">' + "".join(_table_html(t) for t in b.tables) + "</div>"
    if isinstance(b, Pre):
        out = []
        for line in b.lines:
            t = e(line)
            if b.diff and line.startswith("+") and not line.startswith("+++"):
                t = f'<span class="add">{t}</span>'
            elif b.diff and line.startswith("-") and not line.startswith("---"):
                t = f'<span class="del">{t}</span>'
            elif b.diff and line.startswith("@@"):
                t = f'<span class="hunk">{t}</span>'
            out.append(t)
        cap = f"<p><strong>{e(b.caption)}</strong></p>" if b.caption else ""
        return f"{cap}<pre>{chr(10).join(out)}</pre>"
    if isinstance(b, Fig):
        data = (png or {}).get(b.name)
        if data is None:
            data = png_bytes(b.make())
        src = "data:image/png;base64," + base64.b64encode(data).decode("ascii")
        return (
            f'<figure id="fig-{b.name}"><img alt="{e(b.caption)}" src="{src}">'
            f"<figcaption>{e(b.caption)}</figcaption></figure>"
        )
    raise TypeError(f"unknown report block {b!r}")


def _table_html(b: Table) -> str:
    e = html.escape
    head = "".join(f"<th>{e(h)}</th>" for h in b.headers)
    body = []
    for k, row in enumerate(b.rows):
        cls = b.classes[k] if k < len(b.classes) and b.classes[k] else ""
        marks = b.cells[k] if b.cells is not None and k < len(b.cells) else [""] * len(row)
        cells = []
        for c, m in zip(row, marks, strict=False):
            names = " ".join(x for x in ("num" if is_num(c) else "", m) if x)
            cells.append(f'<td class="{names}">{e(c)}</td>' if names else f"<td>{e(c)}</td>")
        body.append(
            f'<tr class="{cls}">{"".join(cells)}</tr>' if cls else f"<tr>{''.join(cells)}</tr>"
        )
    cap = f"<caption>{e(b.caption)}</caption>" if b.caption else ""
    title = f"<p><strong>{e(b.title)}</strong></p>" if b.title else ""
    return (
        f"{title}<table>{cap}<thead><tr>{head}</tr></thead><tbody>{''.join(body)}</tbody></table>"
    )


def html_report_text(res, sections, png) -> str:
    e = html.escape
    title = f"piecs_bayes report: {res.study.name}"
    nav = "".join(f'<li><a href="#{sid}">{e(t)}</a></li>' for sid, t, _ in sections)
    parts = [
        "<!DOCTYPE html>",
        '<html lang="en"><head><meta charset="utf-8">',
        '<meta name="viewport" content="width=device-width, initial-scale=1">',
        f"<title>{e(title)}</title><style>{CSS}</style></head><body>",
        f"<header><h1>{e(title)}</h1>",
        f"<p>Part {e(str(res.part or '–'))} · {e(res.created)} · piecs_bayes "
        f"{e(res.versions.get('piecs_bayes', '?'))} · lengths in mm, deviations in µm, X of "
        "the part frame as radius unless marked Ø</p>",
        f"<nav><ol>{nav}</ol></nav></header>",
    ]
    for k, (sid, t, blocks) in enumerate(sections, start=1):
        parts.append(f'<section id="{sid}"><h2>{k}. {e(t)}</h2>')
        parts += [render_html_block(b, png) for b in blocks]
        parts.append("</section>")
    parts.append("</body></html>")
    return "\n".join(parts) + "\n"


def report_html(res) -> str:
    """The report as one self-contained HTML document (figures as base64 PNG)."""
    from matplotlib import rc_context

    with rc_context(RC):
        return html_report_text(res, report_sections(res), {})


def summary_html(res) -> str:
    """The summary table alone, as an HTML fragment (notebooks)."""
    return render_html_block(summary_table(res))
