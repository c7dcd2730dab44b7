"""The controllers' own feedback rules, as published, with the settings a shop types
into the control: `siemens` (SINUMERIK measuring cycles, mean value with weighting
$k$ and tolerance bands), `renishaw` (Inspection Plus: feedback fraction, null band,
upper tolerance limit) and `heidenhain` (TNC workpiece inspection with tool
monitoring: every deviation added to DR, breakage tolerance). Settings are in mm
(the control's unit), keys named as on the control.

[`check_controller_settings`][] refuses a bad setting by name and value; the `*_step`
functions apply one arriving measurement to every run at once (`(R,)` arrays) and
return the adjustment of the tool offset in the replay's convention (a correction
adds to the part, + = material left); [`controller_alarms`][] counts the measured
parts on which the control raises an alarm. The rules and their sources:
docs/feedback.md, "The controllers' own rules".
"""

from __future__ import annotations

import math
from numbers import Integral, Real

import numpy as np

from ..errors import InputError

CONTROLLERS = ("siemens", "renishaw", "heidenhain")

_KEYS = {
    "siemens": ("_K", "_TZL", "_TMV", "_TDIF", "_TSA"),
    "renishaw": ("F", "V", "U"),
    "heidenhain": ("RBREAK",),
}


def _real(policy, key, v, *, low=0.0, strict=False, inf=False) -> float:
    ok = isinstance(v, Real) and not isinstance(v, bool) and not math.isnan(v)
    ok = ok and (v > low if strict else v >= low) and (inf or math.isfinite(v))
    if not ok:
        rel = ">" if strict else ">="
        more = " or inf (not programmed)" if inf else ""
        raise InputError(f"policy {policy!r}: setting {key} must be a number {rel} {low:g} "
                         f"(mm){more}, got {v!r}", value=v)  # fmt: skip
    return float(v)


def check_controller_settings(policy: str, st: dict) -> None:
    """Refuse a controller's settings that the control would not take (`InputError`
    naming the setting and its value); the keys are checked by the caller."""
    if policy == "siemens":
        k = st["_K"]
        if isinstance(k, bool) or not isinstance(k, Integral) or k < 1:
            raise InputError(f"policy 'siemens': setting _K (weighting factor) must be an "
                             f"integer >= 1, got {k!r}", value=k)  # fmt: skip
        z = _real(policy, "_TZL", st["_TZL"])
        prev, name = z, "_TZL"
        for key in ("_TMV", "_TDIF", "_TSA"):
            v = _real(policy, key, st[key], strict=True, inf=True)
            if v < prev:
                raise InputError(f"policy 'siemens': the bands must increase from _TZL to "
                                 f"_TSA, got {key}={v!r} < {name}={prev!r}", value=v)  # fmt: skip
            prev, name = v, key
    elif policy == "renishaw":
        f = st["F"]
        if isinstance(f, bool) or not isinstance(f, Real) or not 0 < f <= 1:
            raise InputError(f"policy 'renishaw': setting F (feedback, the fraction of the "
                             f"error applied) must be in (0, 1], got {f!r}", value=f)  # fmt: skip
        v = _real(policy, "V", st["V"])
        u = _real(policy, "U", st["U"], strict=True, inf=True)
        if u <= v:
            raise InputError(f"policy 'renishaw': setting U (upper tolerance limit) must "
                             f"exceed V (null band), got U={u!r}, V={v!r}", value=u)  # fmt: skip
    elif policy == "heidenhain":
        _real(policy, "RBREAK", st["RBREAK"])


def siemens_step(mean, d, st, half):
    """One measured difference `d` (from the setpoint at the middle of the tolerance)
    in the SINUMERIK rule: `(mean, adjustment)`. Beyond `_TSA` or `_TDIF`: no
    correction (alarm); beyond the tolerance (oversize/undersize, alarm) or `_TMV`:
    correction by `d` and the mean cleared; else $M_i = M_{i-1} + (D_i - M_{i-1})/k$,
    a correction by $M_i$ when $|M_i| >$ `_TZL`, and the mean cleared."""
    ad = np.abs(d)
    stop = (ad > st["_TSA"]) | (ad > st["_TDIF"])
    direct = ~stop & ((ad > half) | (ad > st["_TMV"]))
    avg = ~stop & ~direct
    m_new = mean + (d - mean) / int(st["_K"])
    fire = avg & (np.abs(m_new) > st["_TZL"])
    adj = np.where(direct, -d, np.where(fire, -m_new, 0.0))
    mean = np.where(direct | fire, 0.0, np.where(avg, m_new, mean))
    return mean, adj


def renishaw_step(err, st):
    """One measured error in the Inspection Plus rule: the adjustment $-F e$ when
    `V` $< |e| \\le$ `U`, else 0 (inside the null band; above the upper limit, alarm)."""
    ae = np.abs(err)
    return np.where((ae > st["V"]) & ~(ae > st["U"]), -st["F"] * err, 0.0)


def heidenhain_step(locked, err, st):
    """One measured deviation in the TNC tool monitoring: `(locked, adjustment)`; the
    deviation is added to DR (adjustment $-e$) unless the tool is locked: a deviation
    beyond `RBREAK` (> 0; 0: not monitored) locks it (TL = L, alarm) for good."""
    brk = (st["RBREAK"] > 0) & (np.abs(err) > st["RBREAK"])
    locked = locked | brk
    return locked, np.where(locked, 0.0, -err)


def controller_alarms(policy, st, real, inspected, half, mid) -> np.ndarray:
    """`(R,)` the measured parts on which the control raises an alarm: `siemens`
    beyond the tolerance, `_TDIF` or `_TSA`; `renishaw` above `U`; `heidenhain`
    beyond `RBREAK` (when > 0)."""
    if policy == "siemens":
        over = np.abs(real - mid) > min(half, st["_TDIF"], st["_TSA"])
    elif policy == "renishaw":
        over = np.abs(real) > st["U"]
    else:
        over = (st["RBREAK"] > 0) & (np.abs(real) > st["RBREAK"])
    return np.sum(over & inspected, axis=1)
