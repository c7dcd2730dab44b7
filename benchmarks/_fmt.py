"""Markdown tables and times for the benchmarks' printouts (no JAX import: the CLI
benchmark times start-up)."""

from __future__ import annotations

import os


def table(rows, head) -> str:
    """A Markdown table of `rows` under `head` (columns padded to their widest cell)."""
    widths = [max(len(str(r[i])) for r in [head, *rows]) for i in range(len(head))]
    line = "| " + " | ".join(str(h).ljust(w) for h, w in zip(head, widths, strict=True)) + " |"
    out = [line, "|" + "|".join("-" * (w + 2) for w in widths) + "|"]
    for r in rows:
        out.append(
            "| " + " | ".join(str(c).ljust(w) for c, w in zip(r, widths, strict=True)) + " |"
        )
    return "\n".join(out)


def ms(t: float) -> str:
    """Seconds as `12.34 ms` below a second, else `1.23 s`."""
    return f"{t * 1e3:.2f} ms" if t < 1 else f"{t:.2f} s"


def load() -> str:
    one, five, fifteen = os.getloadavg()
    return f"load average {one:.2f} / {five:.2f} / {fifteen:.2f} (1/5/15 min)"
