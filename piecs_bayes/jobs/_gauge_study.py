"""The gauge-study jobs: is the measuring system (the machine's own probe) capable of
the tolerance? (`piecs-bayes gauge-study type1|grr FILE`).

[`gauge_type1_study`][] runs the file's type-1 study and the measuring system's VDA 5
budget (Q_MS); [`gauge_rr_study`][] runs its gauge R&R (ANOVA, with the
average-and-range cross-check) and, when the file also has a type-1 study, the budget
of the measuring system and of the measuring process (Q_MS, Q_MP). Both return a
[`GaugeStudy`][]; `piecs_bayes.export` renders it. An `InputError` of the numbers is
re-raised naming the file it came from.
"""

from __future__ import annotations

from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from ..errors import InputError
from ..msa import (
    GrrResult,
    MsaSettings,
    Type1Result,
    UncertaintyBudget,
    gauge_rr,
    type1_study,
    uncertainty_budget,
)
from ._gauge_file import GaugeStudyFile, read_gauge_study
from ._gauge_program import PLAN_NAME, type1_gauging


@dataclass(frozen=True, eq=False)
class GaugeStudy:
    """What a gauge-study job computed: the `study` file it read, which `kind` of study
    was asked for (`"type1"` or `"grr"`), the results (None when not run) and notes."""

    study: GaugeStudyFile
    kind: str
    type1: Type1Result | None
    grr: GrrResult | None
    budget: UncertaintyBudget | None
    notes: tuple[str, ...] = ()

    @property
    def capable(self) -> bool:
        """The asked study's verdict and the budget's, together."""
        if self.kind == "type1":
            ok = self.type1.capable
        else:
            ok = self.grr.verdict == "acceptable" and self.grr.ndc_ok
        return ok and (self.budget is None or self.budget.verdict == "capable")

    def __repr__(self) -> str:
        parts = [repr(r) for r in (self.type1, self.grr, self.budget) if r is not None]
        return f"GaugeStudy({self.study.name!r}, {self.kind}):\n  " + "\n  ".join(parts)


@contextmanager
def _named(file: str):
    """An `InputError` without a file gets `file`."""
    try:
        yield
    except InputError as exc:
        if exc.file is not None:
            raise
        raise InputError(exc.reason, file=file, value=exc.value) from None


def _load(study, settings: MsaSettings | None) -> tuple[GaugeStudyFile, MsaSettings]:
    s = study if isinstance(study, GaugeStudyFile) else read_gauge_study(Path(study))
    return s, settings or s.settings


def _type1(s: GaugeStudyFile, st: MsaSettings) -> Type1Result:
    t = s.type1
    with _named(t.file):
        return type1_study(
            t.readings,
            reference=t.reference,
            tolerance=s.tolerance,
            resolution=s.resolution,
            settings=st,
        )


def _grr(s: GaugeStudyFile, st: MsaSettings) -> GrrResult:
    g = s.grr
    with _named(g.file):
        return gauge_rr(
            g.readings,
            tolerance=s.tolerance,
            parts=g.parts,
            appraisers=g.appraisers,
            appraiser_is=g.appraiser_is,
            settings=st,
        )


def _budget(s: GaugeStudyFile, t1, grr, st: MsaSettings) -> UncertaintyBudget:
    with _named(str(s.path)):
        return uncertainty_budget(
            t1,
            grr,
            system=s.system,
            process=s.process if grr else None,
            bias_corrected=s.bias_corrected,
            settings=st,
        )


def gauge_type1_study(study, *, settings: MsaSettings | None = None) -> GaugeStudy:
    """The type-1 study of a gauge-study file (a path or a read `GaugeStudyFile`) and
    the measuring system's budget; `settings` replace the file's `[settings]`."""
    s, st = _load(study, settings)
    if s.type1 is None:
        raise InputError(
            "the file has no [type1] study (reference, its U and k, readings)", file=str(s.path)
        )
    t1 = _type1(s, st)
    notes = (
        ("[uncertainty] process sources need the gauge R&R: run `gauge-study grr`",)
        if s.process
        else ()
    )
    return GaugeStudy(s, "type1", t1, None, _budget(s, t1, None, st), notes)


def gauge_rr_study(study, *, settings: MsaSettings | None = None) -> GaugeStudy:
    """The gauge R&R of a gauge-study file and, with a `[type1]` study in it too, the
    budget of the measuring system and process; `settings` replace the file's."""
    s, st = _load(study, settings)
    if s.grr is None:
        raise InputError(
            "the file has no [grr] study (readings of parts x appraisers x trials)",
            file=str(s.path),
        )
    grr = _grr(s, st)
    if s.type1 is None:
        note = "no [type1] study in the file: no VDA 5 budget (it needs the reference's U)"
        return GaugeStudy(s, "grr", None, grr, None, (note,))
    t1 = _type1(s, st)
    return GaugeStudy(s, "grr", t1, grr, _budget(s, t1, grr, st))


def gauge_type1_program(study) -> tuple[GaugeStudyFile, dict[str, str]]:
    """The file (read without its type-1 readings) and the type-1 gauging program of
    its `[type1.program]` with the plan its probe file is read against:
    `{file name: text}` (`jobs._gauge_program`)."""
    s = study
    if not isinstance(s, GaugeStudyFile):
        s = read_gauge_study(Path(study), readings=False)
    name, program, plan = type1_gauging(s)
    return s, {name: program, PLAN_NAME: plan}
