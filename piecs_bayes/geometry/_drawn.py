r"""Tolerances as drawn: the coordinate a feature's tolerance is given on.

A drawing tolerances a diameter on the diameter, a face on its axial position Z, a taper
or an arc along the surface normal; the fits and decisions work on the *normal
deviation* $\delta$ (along the outward normal $n$, + outward). [`drawn_scale`][]:

| `tolerance_on` | form                 | drawn deviation            |
|----------------|----------------------|----------------------------|
| `"diameter"`   | cylinder             | $2\,\mathrm{sign}(n_x)\,\delta$ |
| `"radius"`     | cylinder             | $\mathrm{sign}(n_x)\,\delta$   |
| `"length"`     | face, shoulder       | $\mathrm{sign}(n_z)\,\delta$   |
| `"normal"`     | taper, arc           | $\delta$                  |

`Feature.tolerance` holds the limits of $\delta$ (converted once, [`normal_limits`][]);
[`drawn_limits`][] gives them back as drawn. Why: docs/formats.md, "Tolerances as drawn".
"""

from __future__ import annotations

import math

#: the coordinates a tolerance can be given on
TOLERANCE_ON = ("diameter", "radius", "length", "normal")

#: which coordinates fit which form of feature (the first: as on a drawing)
_CHOICES = {
    "cylinder": ("diameter", "radius"),
    "face": ("length",),
    "taper": ("normal",),
    "arc": ("normal",),
}

#: the form, in words, for messages
FORM_WORDS = {
    "cylinder": "a diameter (cylinder)",
    "face": "a face or shoulder",
    "taper": "a taper (cone)",
    "arc": "an arc",
}


def feature_form(p0, p1, center=None) -> str:
    """`"cylinder"`, `"face"`, `"taper"` or `"arc"`: the form of a nominal feature
    from its end points (radius X, Z) and, for an arc, its centre."""
    if center is not None:
        return "arc"
    dx, dz = p1[0] - p0[0], p1[1] - p0[1]
    size = max(math.hypot(dx, dz), 1e-12)
    if abs(dx) <= 1e-9 * size:
        return "cylinder"
    if abs(dz) <= 1e-9 * size:
        return "face"
    return "taper"


def _form(feature) -> str:
    return feature_form(feature.p0, feature.p1, getattr(feature, "center", None))


def tolerance_choices(form: str) -> tuple[str, ...]:
    """The values of `tolerance_on` a feature of `form` accepts (first: as drawn)."""
    return _CHOICES[form]


def _outward(feature) -> tuple[float, float]:
    """Nominal outward normal `(n_x, n_z)` of a line (plain floats)."""
    dx, dz = feature.p1[0] - feature.p0[0], feature.p1[1] - feature.p0[1]
    s = math.hypot(dx, dz)
    return feature.side * dz / s, -feature.side * dx / s


def drawn_scale(feature, on: str | None = None) -> float:
    """Drawn deviation per unit of normal deviation for `feature` with its tolerance
    on `on` (default: the feature's own `tolerance_on`); see the module docstring."""
    on = feature.tolerance_on if on is None else on
    if on == "normal":
        return 1.0
    form = _form(feature)
    if on not in _CHOICES[form]:
        raise ValueError(
            f"feature {feature.id!r} is {FORM_WORDS[form]}: its tolerance cannot be on the "
            f"{on!r}; expected {' or '.join(repr(c) for c in _CHOICES[form])}"
        )
    nx, nz = _outward(feature)
    if on == "length":
        return math.copysign(1.0, nz)
    return math.copysign(2.0 if on == "diameter" else 1.0, nx)


def normal_limits(feature, drawn: tuple[float, float], on: str | None = None):
    """The limits of the normal deviation for limits `drawn` on `on` (ordered)."""
    k = drawn_scale(feature, on)
    lo, hi = sorted((float(drawn[0]) / k, float(drawn[1]) / k))
    return lo, hi


def drawn_limits(feature) -> tuple[float, float]:
    """The feature's tolerance (`feature.tolerance`, on the normal deviation) as drawn."""
    k = drawn_scale(feature)
    lo, hi = sorted((k * feature.tolerance[0], k * feature.tolerance[1]))
    return lo, hi
