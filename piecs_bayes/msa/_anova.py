"""The two-way crossed ANOVA of a gauge R&R: parts x appraisers x trials, balanced.

[`anova_sums`][] gives the sums of squares and degrees of freedom of many studies at
once (arrays `(..., parts, appraisers, trials)`); [`AnovaTable`][] is one study's
table, with the part x appraiser interaction (`anova_table(..., pooled=False)`) or
with it pooled into repeatability (`pooled=True`, AIAG MSA 4th ed. when its p-value
is above 0.25). The F tests follow the expected mean squares of the random-effects
model: parts and appraisers against the interaction, the interaction against
repeatability; in the pooled table everything against the pooled repeatability.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import stats

#: the sources of the full table, in order (the last is the total)
SOURCES = ("part", "appraiser", "part x appraiser", "repeatability", "total")


def anova_sums(y) -> tuple[np.ndarray, tuple[int, ...]]:
    """`(ss, df)`: the sums of squares (..., 5) of `SOURCES` and their degrees of freedom
    of each study in `y` (..., p, o, r)."""
    y = np.asarray(y, float)
    p, o, r = y.shape[-3:]
    grand = y.mean((-3, -2, -1))[..., None, None]
    cell = y.mean(-1)
    part = cell.mean(-1)
    appr = cell.mean(-2)
    ss_p = o * r * ((part - grand[..., 0]) ** 2).sum(-1)
    ss_o = p * r * ((appr - grand[..., 0]) ** 2).sum(-1)
    ss_po = r * ((cell - part[..., :, None] - appr[..., None, :] + grand) ** 2).sum((-2, -1))
    ss_e = ((y - cell[..., None]) ** 2).sum((-3, -2, -1))
    ss_t = ((y - grand[..., None]) ** 2).sum((-3, -2, -1))
    df = (p - 1, o - 1, (p - 1) * (o - 1), p * o * (r - 1), p * o * r - 1)
    return np.stack([ss_p, ss_o, ss_po, ss_e, ss_t], -1), df


def interaction_p(ss, df) -> np.ndarray:
    """The p-value of the interaction's F test (MS_PO / MS_E) of each study."""
    with np.errstate(divide="ignore", invalid="ignore"):
        f = (ss[..., 2] / df[2]) / (ss[..., 3] / df[3])
    return stats.f.sf(f, df[2], df[3])


@dataclass(frozen=True)
class AnovaRow:
    """One source: sum of squares, degrees of freedom, mean square, F and its p-value
    (None for repeatability and the total)."""

    source: str
    df: int
    ss: float
    ms: float
    f: float | None
    p: float | None

    def as_dict(self) -> dict:
        return {
            "source": self.source,
            "df": self.df,
            "ss": self.ss,
            "ms": self.ms,
            "f": self.f,
            "p": self.p,
        }


@dataclass(frozen=True)
class AnovaTable:
    """One study's ANOVA table; `pooled`: the interaction pooled into repeatability."""

    rows: tuple[AnovaRow, ...]
    pooled: bool

    def __getitem__(self, source: str) -> AnovaRow:
        for row in self.rows:
            if row.source == source:
                return row
        raise KeyError(source)

    def table(self) -> list[dict]:
        return [row.as_dict() for row in self.rows]

    def __repr__(self) -> str:
        head = f"{'source':<18}{'df':>4}{'SS':>13}{'MS':>13}{'F':>10}{'p':>9}"
        lines = [f"AnovaTable({'interaction pooled' if self.pooled else 'with interaction'})", head]
        for r in self.rows:
            f = "" if r.f is None else f"{r.f:10.3f}"
            p = "" if r.p is None else f"{r.p:9.4f}"
            lines.append(f"{r.source:<18}{r.df:>4}{r.ss:13.6g}{r.ms:13.6g}{f:>10}{p:>9}")
        return "\n".join(lines)


def anova_table(ss, df, *, pooled: bool) -> AnovaTable:
    """One study's table from its `anova_sums` (`ss` of shape (5,))."""
    ss = [float(v) for v in ss]
    ms = [s / d for s, d in zip(ss, df, strict=True)]
    if pooled:
        ss_e, df_e = ss[2] + ss[3], df[2] + df[3]
        ms_e = ss_e / df_e
        return AnovaTable(
            (
                _row("part", df[0], ss[0], ms_e, df_e),
                _row("appraiser", df[1], ss[1], ms_e, df_e),
                AnovaRow("repeatability", df_e, ss_e, ms_e, None, None),
                AnovaRow("total", df[4], ss[4], ss[4] / df[4], None, None),
            ),
            pooled=True,
        )
    return AnovaTable(
        (
            _row("part", df[0], ss[0], ms[2], df[2]),
            _row("appraiser", df[1], ss[1], ms[2], df[2]),
            _row("part x appraiser", df[2], ss[2], ms[3], df[3]),
            AnovaRow("repeatability", df[3], ss[3], ms[3], None, None),
            AnovaRow("total", df[4], ss[4], ms[4], None, None),
        ),
        pooled=False,
    )


def _row(source: str, df: int, ss: float, ms_den: float, df_den: int) -> AnovaRow:
    ms = ss / df
    f = ms / ms_den if ms_den > 0 else float("inf")
    return AnovaRow(source, df, ss, ms, f, float(stats.f.sf(f, df, df_den)))
