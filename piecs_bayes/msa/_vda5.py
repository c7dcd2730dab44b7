"""The uncertainty budget of VDA 5 / ISO 22514-7: measuring system and measuring process.

[`uncertainty_budget`][] lists every standard uncertainty as a [`BudgetComponent`][]:
of the measuring system (MS) the calibration of the reference U_cal / k (u_CAL), the
resolution RE / sqrt 12 (u_RE), the repeatability on the reference (u_EVR, the type-1
s), the bias |Bi| / sqrt 3 unless it is corrected (u_BI) and further sources given
(linearity u_LIN, ...); of the measuring process (MP) also the repeatability on the
parts (u_EVO), the reproducibility of the setups (u_AV) and their interaction with the
parts (u_IA) from the gauge R&R, and the process's own sources (temperature u_T, the
part's own form u_OBJ, ...). Resolution and repeatability are one effect: the larger
counts (`resolution_rule="max"`). U = k u (k = 2), Q = 2 U / T against 15 % (MS) and
30 % (MP): [`UncertaintyBudget`][]. Formulas: docs/msa.md.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from numbers import Real

from ..errors import InputError
from ._grr import GrrResult
from ._settings import MsaSettings
from ._type1 import Type1Result

#: the VDA 5 symbols of sources named in a study's file
SYMBOLS = {
    "linearity": "u_LIN",
    "temperature": "u_T",
    "stability": "u_STAB",
    "object": "u_OBJ",
    "gauges": "u_GV",
}


@dataclass(frozen=True)
class BudgetComponent:
    """One standard uncertainty `u` (mm): its VDA 5 `symbol`, what it is (`name`),
    where its value came from (`origin`), and whether it is counted in the measuring
    system's (`in_ms`) and the measuring process's (`in_mp`) sums (a resolution or
    repeatability below the larger of them is not: VDA 5's max rule)."""

    symbol: str
    name: str
    u: float
    origin: str
    in_ms: bool
    in_mp: bool

    def as_dict(self) -> dict:
        return {k: getattr(self, k) for k in ("symbol", "name", "u", "origin", "in_ms", "in_mp")}


@dataclass(frozen=True)
class UncertaintyBudget:
    """The budget: `components`, the combined standard uncertainties `u_ms` and `u_mp`
    (None without a gauge R&R), the expanded `U_ms`, `U_mp` (k = `coverage_factor`),
    the capability ratios `q_ms = 2 U_MS / T`, `q_mp = 2 U_MP / T` and the smallest
    tolerances the gauge is capable of (`t_min_ms = 2 U_MS / q_ms_limit`, ...)."""

    components: tuple[BudgetComponent, ...]
    tolerance: float
    u_ms: float
    u_mp: float | None
    settings: MsaSettings = field(repr=False)

    @property
    def U_ms(self) -> float:  # noqa: N802 - the symbol of the standard
        return self.settings.coverage_factor * self.u_ms

    @property
    def U_mp(self) -> float | None:  # noqa: N802
        return None if self.u_mp is None else self.settings.coverage_factor * self.u_mp

    @property
    def q_ms(self) -> float:
        return 2.0 * self.U_ms / self.tolerance

    @property
    def q_mp(self) -> float | None:
        return None if self.u_mp is None else 2.0 * self.U_mp / self.tolerance

    @property
    def q_ms_ok(self) -> bool:
        return self.q_ms <= self.settings.q_ms_limit

    @property
    def q_mp_ok(self) -> bool | None:
        return None if self.q_mp is None else self.q_mp <= self.settings.q_mp_limit

    @property
    def t_min_ms(self) -> float:
        return 2.0 * self.U_ms / self.settings.q_ms_limit

    @property
    def t_min_mp(self) -> float | None:
        return None if self.u_mp is None else 2.0 * self.U_mp / self.settings.q_mp_limit

    @property
    def verdict(self) -> str:
        """`"capable"` when Q_MS (and Q_MP, when known) are within their limits."""
        ok = self.q_ms_ok and self.q_mp_ok is not False
        return "capable" if ok else "not capable"

    def table(self) -> list[dict]:
        return [c.as_dict() for c in self.components]

    def __repr__(self) -> str:
        mp = "" if self.u_mp is None else f", U_MP={self.U_mp:.4g}, Q_MP={self.q_mp:.1%}"
        return (
            f"UncertaintyBudget({len(self.components)} components, U_MS={self.U_ms:.4g}, "
            f"Q_MS={self.q_ms:.1%}{mp}: {self.verdict})"
        )


def uncertainty_budget(
    type1: Type1Result,
    grr: GrrResult | None = None,
    *,
    system: dict | None = None,
    process: dict | None = None,
    bias_corrected: bool = False,
    settings: MsaSettings = MsaSettings(),
) -> UncertaintyBudget:
    """The VDA 5 budget of a gauge from its type-1 study (and gauge R&R).

    **Arguments:** `type1` (reference, resolution, s, bias, tolerance); `grr` (the
    measuring process: u_EVO, u_AV, u_IA); `system`, `process`: further standard
    uncertainties by name (mm; `linearity`, `temperature`, `object`, `stability` get
    their VDA 5 symbols); `bias_corrected`: the bias is corrected, u_BI not counted.

    **Returns:** an [`UncertaintyBudget`][]; its MP part only with `grr`.
    """
    comps = _system_components(type1, bias_corrected) + _given(system, False)
    if grr is not None:
        comps += _process_components(grr) + _given(process, True)
    elif process:
        raise InputError("measuring-process sources need a gauge R&R (the [grr] study)")
    names = [c.name for c in comps]
    if len(set(names)) < len(names):
        raise InputError(f"an uncertainty source is named twice: {sorted(names)}")
    comps = _resolution_rule(comps, settings.resolution_rule)
    u_ms = math.sqrt(sum(c.u**2 for c in comps if c.in_ms))
    u_mp = None if grr is None else math.sqrt(sum(c.u**2 for c in comps if c.in_mp))
    return UncertaintyBudget(tuple(comps), type1.tolerance, u_ms, u_mp, settings)


def _system_components(t1: Type1Result, bias_corrected: bool) -> list[BudgetComponent]:
    ref = t1.reference
    bias = 0.0 if bias_corrected else abs(t1.bias) / math.sqrt(3.0)
    how = "corrected: not counted" if bias_corrected else f"|Bi| / sqrt 3, Bi = {t1.bias:.4g} mm"
    return [
        BudgetComponent(
            "u_CAL",
            "calibration of the reference",
            ref.u,
            f"U / k = {ref.expanded_uncertainty:g} mm / {ref.coverage_factor:g}",
            True,
            True,
        ),
        BudgetComponent(
            "u_RE",
            "resolution",
            t1.resolution / math.sqrt(12.0),
            f"RE / sqrt 12, RE = {t1.resolution:g} mm",
            True,
            True,
        ),
        BudgetComponent(
            "u_EVR", "repeatability on the reference", t1.s, f"type-1 s, n = {t1.n}", True, True
        ),
        BudgetComponent("u_BI", "bias on the reference", bias, how, True, True),
    ]


def _process_components(grr: GrrResult) -> list[BudgetComponent]:
    c = grr.components
    inter = c.get("part x appraiser")
    who = grr.appraiser_is
    return [
        BudgetComponent(
            "u_EVO",
            "repeatability on the parts",
            c["repeatability"].sd,
            "gauge R&R repeatability",
            False,
            True,
        ),
        BudgetComponent(
            "u_AV",
            f"reproducibility ({who}s)",
            c["appraiser"].sd,
            f"gauge R&R {who} component",
            False,
            True,
        ),
        BudgetComponent(
            "u_IA",
            f"part x {who} interaction",
            0.0 if inter is None else inter.sd,
            "pooled into repeatability" if inter is None else "gauge R&R",
            False,
            True,
        ),
    ]


#: the components the studies give: a source given by one of these names is refused
RESERVED = ("cal", "re", "evr", "bi", "evo", "av", "ia")


def _given(sources: dict | None, process: bool) -> list[BudgetComponent]:
    out = []
    for name, u in (sources or {}).items():
        if str(name).lower() in RESERVED:
            raise InputError(
                f"uncertainty source {name!r}: u_{str(name).upper()} comes from "
                "the studies; give another name",
                value=name,
            )
        if isinstance(u, bool) or not isinstance(u, Real) or not 0 <= u < math.inf:
            raise InputError(
                f"uncertainty source {name!r}: expected a standard uncertainty >= 0, got {u!r}",
                value=u,
            )
        symbol = SYMBOLS.get(name, f"u_{name}")
        out.append(BudgetComponent(symbol, str(name), float(u), "given", not process, True))
    return out


def _resolution_rule(comps: list[BudgetComponent], rule: str) -> list[BudgetComponent]:
    """VDA 5's max rule: of u_RE and the repeatabilities (u_EVR; u_EVO in the process)
    only the largest counts; `"both"`: u_RE and the larger repeatability."""
    by = {c.symbol: c for c in comps}
    ms_group, mp_group = ["u_RE", "u_EVR"], ["u_RE", "u_EVR", "u_EVO"]
    if rule == "both":
        ms_group, mp_group = ["u_EVR"], ["u_EVR", "u_EVO"]
    ms_keep = max((by[s] for s in ms_group), key=lambda c: c.u).symbol
    mp_keep = max((by[s] for s in mp_group if s in by), key=lambda c: c.u).symbol
    return [
        replace(
            c,
            in_ms=c.in_ms and (c.symbol not in ms_group or c.symbol == ms_keep),
            in_mp=c.symbol not in mp_group or c.symbol == mp_keep,
        )
        for c in comps
    ]
