"""The verdict of a compensation decision and its reasons, from one place.

[`conclude`][] picks the verdict from the evaluated actions (`_actions.CoreVerdict`) and
writes, in the same branch, why: the reasons can never contradict the verdict. The
reasons are plain sentences with lengths in µm on the coordinate the tolerance is
drawn on (`VerdictWords`): on the diameter for a diameter, on Z for a face, along the
normal for tapers and arcs. The rule (docs/models/decision.md):

1. `compensate` when adjusting lowers the expected cost, the deviation is
   significant (when required), the correction is allowed and the compensated
   feature is predicted to conform;
2. `do not compensate` when adjusting is not justified and the part conforms as
   measured, or when the correction is above `max_correction` (investigate first);
3. `measure more` otherwise, with the number of extra probe points that would decide;
   when no number decides, the lower expected cost decides.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

from ._actions import CoreVerdict
from ._conformance import Conformance
from ._settings import DecisionSettings

Verdict = Literal["compensate", "do not compensate", "measure more"]

#: the coordinate of a drawn tolerance, in words
_ON = {
    "diameter": "on the diameter",
    "radius": "on the radius",
    "length": "on Z",
    "normal": "along the surface normal",
}


@dataclass(frozen=True)
class VerdictWords:
    """Lengths (mm of normal deviation) as drawn, in µm: `scale` × value on `coordinate`."""

    coordinate: str = "normal"
    scale: float = 1.0

    @property
    def on(self) -> str:
        return _ON.get(self.coordinate, f"on the {self.coordinate}")

    def dev(self, x: float) -> str:
        """A signed deviation as drawn."""
        v = self.scale * x * 1e3
        return f"{0.0 if abs(v) < 0.05 else v:+.1f} µm"

    def dev_u(self, x: float, u: float) -> str:
        """A signed deviation ± a size, as drawn."""
        return f"{self.dev(x)[:-3]} ± {self.size(u)}"

    def size(self, x: float) -> str:
        """A size (uncertainty, band, limit) as drawn."""
        return f"{abs(self.scale) * x * 1e3:.1f} µm"

    def limits(self, lo: float, hi: float) -> str:
        a, b = sorted((self.scale * lo * 1e3, self.scale * hi * 1e3))
        return f"{a:+.1f} … {b:+.1f} µm"


_STATE = {
    "conforms": "conforms (inside the tolerance by more than U)",
    "does not conform": "does not conform (outside the tolerance by more than U)",
    "ambiguous": "conformance not proven (within U of a limit)",
}


@dataclass(frozen=True)
class Conclusion:
    """What `conclude` decided: verdict, gain and correction applied, and why."""

    verdict: Verdict
    gain: float
    correction: float
    blocked: bool
    reasons: tuple[str, ...]


def _measured(c: Conformance, w: VerdictWords, dof: float) -> str:
    ndof = f", {dof:.0f} effective degrees of freedom" if math.isfinite(dof) else ""
    text = (
        f"as measured {w.dev_u(c.value, c.expanded)} {w.on} (± U, 95 %{ndof}); tolerance "
        f"{w.limits(*c.tolerance)}: {_STATE[c.state]}"
    )
    if c.state == "ambiguous":
        text += f", probability of conforming {c.p_conform:.2f}"
    return text


def _significance(core: CoreVerdict, band: float, st: DecisionSettings, w: VerdictWords) -> str:
    text = (
        f"null band ±{w.size(band)}: smaller deviations are not worth correcting; the "
        f"deviation is beyond it with probability {core.p_exceed:.3f}, "
        + (
            f"at least the required {st.p_significant:g}: significant"
            if core.significant
            else f"below the required {st.p_significant:g}: not significant"
        )
    )
    if st.prior_sd is not None:
        text += (
            f"; with the prior (setup deviations of sd {st.prior_sd * 1e3:.1f} µm) the "
            f"estimate is {w.dev_u(core.post.m, core.post.s)} (± 1 sd)"
        )
    return text


def _cost(core: CoreVerdict, st: DecisionSettings) -> str:
    none, b = core.actions[0], core.bayes
    unit = f"cost units: an out-of-tolerance part costs {st.out_of_tolerance_cost:g}"
    if b.correction == 0.0:
        return f"adjusting does not lower the expected cost ({none.expected_loss:.3g}; {unit})"
    return (
        f"expected cost: {none.expected_loss:.3g} leaving the program as it is, "
        f"{b.expected_loss:.3g} adjusting with gain {b.gain:.2f} ({unit})"
    )


def _compensated(
    core: CoreVerdict, gain: float, corr: float, w: VerdictWords, why: str = ""
) -> str:
    a = core.after
    after = (
        f"on nominal ± {w.size(a.expanded)}"
        if abs(w.scale * a.value) < 5e-5
        else w.dev_u(a.value, a.expanded)
    )
    return (
        f"compensate with gain {gain:.2f}{why}: the finish cut moves by {w.dev(corr)} {w.on}; "
        f"the next part is expected {after}, which {a.state}"
    )


def _undecided(core: CoreVerdict, n_points, more, st, w: VerdictWords) -> tuple[Verdict, str]:
    """Verdict and reason when the evidence is not clear (`more`: extra points or None)."""
    target = core.after if core.justified else core.before
    lo_a, hi_a = target.acceptance
    which = "the compensated part" if core.justified else "the part as measured"
    if lo_a <= hi_a:
        too_large = (
            f"the uncertainty is too large to decide: {which}, {w.dev(target.value)}, lies "
            f"outside the acceptance zone {w.limits(lo_a, hi_a)} (the tolerance less "
            f"U = {w.size(target.expanded)})"
        )
    else:
        too_large = (
            f"the uncertainty is too large to decide: U = {w.size(target.expanded)} is more "
            "than half the tolerance, so no value can be shown to conform"
        )
    if n_points is None:
        return "measure more", f"measure more: {too_large}; give n_points to estimate how many"
    if more is not None:
        return "measure more", (
            f"measure more: {too_large}; about {more} more probe points "
            f"({n_points} -> {n_points + more}, the random part of u falls as 1/√n) would decide"
        )
    stuck = (
        f"even {st.max_points_factor:g}× the probe points would not decide (the estimate "
        "sits on a threshold, or the systematic part of u dominates)"
    )
    if core.justified and not core.bayes.blocked:
        b = core.bayes
        return "compensate", _compensated(core, b.gain, b.correction, w, f" ({stuck})")
    return "do not compensate", (
        f"do not compensate: {stuck}, and adjusting is not justified by the evidence"
    )


def clear_verdict(core: CoreVerdict) -> Verdict | None:
    """The verdict when the evidence is clear, else None ('measure more')."""
    if core.justified:
        if core.bayes.blocked:
            return "do not compensate"
        return "compensate" if core.after.state == "conforms" else None
    return "do not compensate" if core.before.state == "conforms" else None


def conclude(core: CoreVerdict, *, band, max_corr, st, n_points, more, w, dof) -> Conclusion:
    """The verdict with the gain and correction it applies, and every reason for it."""
    b = core.bayes
    reasons = [_measured(core.before, w, dof), _significance(core, band, st, w), _cost(core, st)]
    verdict = clear_verdict(core)
    if verdict is None:
        verdict, why = _undecided(core, n_points, more, st, w)
        reasons.append(why)
        if verdict == "compensate":
            return Conclusion(verdict, b.gain, b.correction, False, tuple(reasons))
        return Conclusion(verdict, 0.0, 0.0, False, tuple(reasons))
    if verdict == "compensate":
        reasons.append(_compensated(core, b.gain, b.correction, w))
        return Conclusion(verdict, b.gain, b.correction, False, tuple(reasons))
    if core.justified:  # justified but blocked
        limit = f"{w.size(max_corr)} {w.on}" if w.scale != 1.0 else f"{w.size(max_corr)}"
        reasons.append(
            f"do not compensate: the correction {w.dev(b.correction)} exceeds max_correction, "
            f"the largest allowed ({limit}); investigate (wrong tool, offset or setup) "
            "before adjusting"
        )
        return Conclusion(verdict, 0.0, 0.0, True, tuple(reasons))
    if b.correction == 0.0:
        why = "adjusting does not lower the expected cost"
    else:
        why = (
            "the deviation is not significant (without a prior, a correction must be "
            "significant, or it would chase noise)"
        )
    reasons.append(f"do not compensate: {why}")
    return Conclusion(verdict, 0.0, 0.0, False, tuple(reasons))
