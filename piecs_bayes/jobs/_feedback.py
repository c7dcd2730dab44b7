r"""Feedback over a production run: track every feature from part to part, replay the
feedback policies, and recommend the next part's correction.

[`feedback_study`][] (a study and its probe files; [`feedback_from_values`][] for values
from elsewhere) works per part, in production order, and per feature on the
characteristic $\delta$ (mm, + outside the material; the capability study's values) and
returns a [`FeedbackResult`][]: per feature the tracking model's predictives, level, odd
parts and steps (declared in `[feedback] tool_changes`, or found); every policy replayed
on the counterfactual that a correction adds to the following parts, the anchors both
with the shop's one setting (a) and tuned on the run (b); the coverage of the 95 %
predictive intervals; the `bayes` correction for the next part. With finished parts
the transfer coefficient $\beta$ is fitted and the replay runs on the finish deviations.
The drawn coordinate only states the numbers (`*_drawn_mm`).

The job and its outputs: docs/formats.md, "Finished-part measurements"; docs/feedback.md.
"""

from __future__ import annotations

import math
import time
import warnings
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, replace
from types import MappingProxyType

import numpy as np

from ..errors import InputError
from ..feedback import (
    POLICIES,
    SHOP_SETTINGS,
    at_measured,
    expand_sampled,
    fit_transfer,
    next_part,
    predictive_coverage,
    replay,
    track,
    tune,
)
from ..geometry import drawn_scale
from ._batch import capability_values
from ._feedback_result import COVERAGE_LEVEL, FeatureFeedback, FeedbackResult
from ._fit import load_probe_data
from ._options import source_sds

_Z95 = 1.959963984540054


def _progress_fn(progress) -> Callable[[str], None]:
    if callable(progress):
        return progress
    if not progress:
        return lambda msg: None
    t0 = time.perf_counter()
    return lambda msg: print(f"[{time.perf_counter() - t0:6.1f} s] {msg}", flush=True)


def _finish_check(y, u, tr, transfer, meas, resid_sd) -> dict:
    """The finished-part check of one feature: `meas` is `{index: (value, u)}`."""
    beta, u_beta = transfer
    inside1, n1, inside2 = [], 0, []
    for i, (fv, fu) in meas.items():
        lo, hi = tr.pred_lo[i], tr.pred_hi[i]
        if np.isfinite(lo) and np.isfinite(hi):
            c = 0.5 * beta * (lo + hi)
            extra = _Z95 * math.hypot(fu, u_beta * tr.pred_mean[i])
            h = math.hypot(0.5 * abs(beta) * (hi - lo), extra)
            inside1.append(abs(fv - c) <= h)
            n1 += 1
        s = math.sqrt((beta * u[i]) ** 2 + (u_beta * y[i]) ** 2 + fu**2 + resid_sd**2)
        inside2.append(abs(fv - beta * y[i]) <= _Z95 * s)
    return {
        "n": len(meas),
        "coverage_one_step": float(np.mean(inside1)) if inside1 else math.nan,
        "n_one_step": n1,
        "coverage_semifinish": float(np.mean(inside2)) if inside2 else math.nan,
        "residual_sd": resid_sd,
    }


def _transfer_fit(fid, parts, y, u, finish, notes):
    """`(beta, u_beta), {index: (value, u)}, residual sd` of one feature, or Nones."""
    if finish is None:
        return None, {}, 0.0
    by_part = finish.for_feature(fid)
    idx = {p: i for i, p in enumerate(parts)}
    meas = {idx[p]: (v, uu) for p, (v, uu, _) in by_part.items() if p in idx}
    if len(meas) < 2:
        if by_part:
            notes.append(f"{fid}: {len(meas)} finished part(s) with a semifinish value; "
                         "a transfer coefficient needs 2: replayed as measured")  # fmt: skip
        return None, {}, 0.0
    ii = np.array(sorted(meas))
    fv = np.array([meas[i][0] for i in ii])
    fu = np.array([meas[i][1] for i in ii])
    beta, u_beta = fit_transfer(y[ii], fv, u[ii], fu)
    extra = (fv - beta * y[ii]) ** 2 - fu**2 - (beta * u[ii]) ** 2
    resid_sd = math.sqrt(max(0.0, float(np.mean(extra))))
    return (float(beta), float(u_beta)), meas, resid_sd


def _one_feature(fid, feat, parts, y, u, usys, declared, policies, finish, notes, say,
                 loop=(1, 0)):  # fmt: skip
    tol = tuple(float(t) for t in feat.tolerance)
    changes = tuple(sorted({i for i, p in enumerate(parts) if p in declared}))
    for p in sorted(declared - set(parts)):
        notes.append(f"{fid}: tool change {p} has no value (its fit was left out): not declared")
    every, delay = loop
    prod = np.arange(len(parts)) * every  # production index of each measured part
    kw = {"inspect_every": every, "delay": delay}

    def run(fn, dev_, ud_, **more):  # a replay in production order, at the measured parts
        res_ = fn(expand_sampled(dev_, every), expand_sampled(ud_, every), tolerance=tol,
                  tool_changes=tuple(int(prod[i]) for i in changes), **kw, **more)  # fmt: skip
        return at_measured(res_, prod) if every > 1 else res_

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # all-NaN predictive of part 1
        tr = track(expand_sampled(y, every), expand_sampled(u, every),
                   tool_changes=tuple(int(prod[i]) for i in changes))  # fmt: skip
        tr = at_measured(tr, prod) if every > 1 else tr
    cov = predictive_coverage(tr, y, COVERAGE_LEVEL)
    n_cov = int(np.sum(np.isfinite(tr.pit(y))))
    transfer, meas, resid_sd = _transfer_fit(fid, parts, y, u, finish, notes)
    beta, u_beta = transfer if transfer is not None else (1.0, 0.0)
    dev, ud = beta * y, abs(beta) * u
    res = {}
    for name in policies:
        if name == "bayes":
            st = {} if transfer is None else {"transfer": (1.0, u_beta / max(abs(beta), 1e-12))}
            res[name] = run(replay, dev, ud, policy="bayes", settings=st)
        else:
            res[name] = run(tune, dev, ud, policy=name)
    for name in policies:  # comparison (a): the machine's one setting
        if name in SHOP_SETTINGS:
            one = run(replay, dev, ud, policy=name, settings=SHOP_SETTINGS[name])
            res[f"{name} (a)"] = replace(one, name=f"{name} (a)")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        nxt = next_part(y, u, tolerance=tol, tool_changes=changes, transfer=(beta, u_beta),
                        **kw)  # fmt: skip
    d = nxt["decision"]
    finish_info = None
    if transfer is not None:
        finish_info = _finish_check(y, u, tr, transfer, meas, resid_sd)
        finish_info["by_part"] = MappingProxyType({parts[i]: v for i, v in meas.items()})
    say(f"{fid}: {len(parts)} parts tracked, {len(res)} policies replayed")
    return FeatureFeedback(
        feature=fid,
        coordinate=feat.tolerance_on,
        scale=float(drawn_scale(feat)),
        tolerance=tol,
        parts=tuple(parts),
        values=_ro(y),
        u=_ro(u),
        u_systematic=float(usys),
        tool_changes=changes,
        track=tr,
        coverage=float(cov),
        n_covered=n_cov,
        policies=MappingProxyType(res),
        next_part=MappingProxyType(
            {
                "correction": float(nxt["correction"]),
                "u": float(nxt["u"]),
                "adjustment": float(nxt["adjustment"]),
                "mean": float(nxt["mean"]),
                "sd": float(nxt["sd"]),
                "verdict": str(d.verdict),
                "reasons": tuple(d.reasons),
            }
        ),  # fmt: skip
        transfer=transfer,
        finish=None if finish_info is None else MappingProxyType(finish_info),
    )


def _ro(a) -> np.ndarray:
    a = np.array(a, dtype=float)
    a.flags.writeable = False
    return a


@dataclass(frozen=True)
class FeedbackSettings:
    """What the feedback over a run replays (the study's `[feedback]` table).

    - `tool_changes`: part ids cut first with a new tool (declared steps).
    - `policies`: the policies to replay (default: all, `feedback.POLICIES`).
    - `characteristic`: the nominal point of the values (`"mid"`, `"start"`, `"end"`).
    - `inspect_every`, `delay`: the values are every `inspect_every`-th part of the
      run, and a result arrives `delay` parts late (see `feedback.replay`): the
      replay, the tracking and the next part follow.
    """

    tool_changes: tuple[str, ...] = ()
    policies: tuple[str, ...] = POLICIES
    characteristic: str = "mid"
    inspect_every: int = 1
    delay: int = 0

    def __post_init__(self):
        object.__setattr__(self, "tool_changes", tuple(self.tool_changes))
        object.__setattr__(self, "policies", tuple(self.policies))
        for p in self.policies:
            if p not in POLICIES:
                raise InputError(f"unknown policy {p!r}; expected some of {', '.join(POLICIES)}",
                                 value=p)  # fmt: skip


def feedback_from_values(
    values: Mapping[str, Sequence[float]],
    u: Mapping[str, Sequence[float]],
    *,
    profile,
    parts: Mapping[str, Sequence[str]],
    u_systematic: Mapping[str, float] | None = None,
    finish=None,
    settings: FeedbackSettings | None = None,
    study: str = "",
    method: str = "",
    progress=False,
) -> FeedbackResult:
    """Feedback over a run from per-part values (pure; see the module doc).

    **Arguments:**

    - `values`, `u`: by feature id, the normal deviations δ and their standard
      uncertainties (mm), one per part in production order.
    - `profile`: the study's profile (tolerances and drawn coordinates).
    - `parts`: by feature id, the part ids of the values.
    - `u_systematic`: by feature, the systematic uncertainty common to every part (mm).
    - `finish`: finished-part measurements (`io.FinishData`) or `None`.
    - `settings`: the declared tool changes, the policies, the nominal point, the
      inspection interval and delay (a [`FeedbackSettings`][]; default: its defaults).
    - `study`, `method`: labels kept in the result.
    - `progress`: `True` (print), a callable `progress(message)`, or `False`.

    **Returns:** a [`FeedbackResult`][].
    """
    st = settings if settings is not None else FeedbackSettings()
    policies, inspect_every, delay = st.policies, st.inspect_every, st.delay
    say = _progress_fn(progress)
    notes: list[str] = []
    declared = set(st.tool_changes)
    feats = {}
    for fid in profile.ids:
        if fid not in values:
            continue
        y = np.asarray(values[fid], dtype=float)
        uu = np.asarray(u[fid], dtype=float)
        if y.size < 2:
            notes.append(f"{fid}: only {y.size} value(s); no feedback")
            continue
        feats[fid] = _one_feature(
            fid, profile[fid], list(parts[fid]), y, uu, (u_systematic or {}).get(fid, 0.0),
            declared, tuple(policies), finish, notes, say, (int(inspect_every), int(delay)),
        )  # fmt: skip
    all_parts = tuple(dict.fromkeys(p for f in feats.values() for p in f.parts))
    replayed = "measured" if not any(f.transfer for f in feats.values()) else "finish"
    return FeedbackResult(
        study=study,
        parts=all_parts,
        method=method,
        characteristic=st.characteristic,
        features=MappingProxyType(feats),
        policies=tuple(policies) + tuple(f"{p} (a)" for p in policies if p in SHOP_SETTINGS),
        tool_changes=tuple(p for p in all_parts if p in declared),
        replayed_on=replayed,
        finish_files=() if finish is None else tuple(dict.fromkeys(finish.files.tolist())),
        notes=tuple(notes),
        inspect_every=int(inspect_every),
        delay=int(delay),
    )


def _declared(study, parts: Sequence[str], cfg) -> tuple[str, ...]:
    changes = tuple(cfg.get("tool_changes", ()))
    for p in changes:
        if p not in parts:
            shown = f"{parts[0]}..{parts[-1]}" if len(parts) > 3 else ", ".join(parts)
            raise InputError(
                f"feedback.tool_changes: unknown part {p!r}; the run has {len(parts)} parts "
                f"({shown})",
                file=str(study.path), value=p,
            )  # fmt: skip
    return changes


def _finish(study, finish, parts):
    """The finished-part measurements: `finish` (`FinishData`, or paths), else the
    study's `[feedback] finish_files`, else `None`; every part must be in the run."""
    from ..io import read_finish_files

    if finish is None:
        files = study.sections.get("feedback", {}).get("finish_files", ())
        if not files:
            return None
        finish = files
    if not hasattr(finish, "for_feature"):
        finish = read_finish_files(list(finish), profile=study.profile, units=study.units,
                                   encoding=study.encoding)  # fmt: skip
    known = set(parts)
    for i, p in enumerate(finish.part.tolist()):
        if p not in known:
            raise InputError(
                f"part {p!r} is not a part of the run ({len(parts)} parts from the probe files)",
                file=str(finish.files[i]), line=int(finish.lines[i]), column="part", value=p,
            )  # fmt: skip
    return finish


def feedback_study(study, *, probe=None, finish=None, progress=True) -> FeedbackResult:
    """Feedback over the study's run of parts: tracking, policy replay, next part.

    **Arguments:**

    - `study`: the study; its probe files give the parts in production order; its
      `[feedback]` table the declared tool changes, the policies and the finished-part
      files; its `[capability]` (or `[feedback]`) `characteristic` the nominal point.
    - `probe`: the probe data (`ProbeData`), read from the study when not given.
    - `finish`: finished-part measurements (`io.FinishData` or file paths) instead of
      the study's `finish_files`.
    - `progress`: `True` (print a line per step), a callable `progress(message)`, or
      `False`.

    **Returns:** a [`FeedbackResult`][].

    **Raises:** `InputError` for a tool change or finished part not in the run (naming
    the file, key or line, and the value).
    """
    say = _progress_fn(progress)
    cfg = study.sections.get("feedback", {})
    probe = probe if probe is not None else load_probe_data(study)
    parts = probe.parts
    if len(parts) < 2:
        raise InputError(f"feedback needs a run of at least 2 parts, got {len(parts)} in "
                         f"{probe.file_text}")  # fmt: skip
    declared = _declared(study, parts, cfg)
    fin = _finish(study, finish, parts)
    if fin is not None:
        say(f"read {len(fin)} finished-part measurements of {len(fin.parts)} parts")
    at = cfg.get("characteristic", study.capability.get("characteristic", "mid"))
    notes = []
    used = study.fit.method
    if used == "bayes":
        used = "robust"
        notes.append("per-part values from the robust fits (the study asks for bayes)")
    if study.fit.free_transform:
        raise InputError("feedback: joint fits (fit.free_transform) are not batched; "
                         "remove fit.free_transform", file=str(study.path))  # fmt: skip

    say(f"fitting {len(parts)} parts in batches (the first call compiles)")

    def fitted(done, total, last):
        say(f"fitted {done}/{total} parts ({last})")

    values, us, pids, usys, more = capability_values(
        study, probe, method=used, at=at, sources=source_sds(study), progress=fitted
    )
    notes += more
    settings = FeedbackSettings(
        tool_changes=declared, characteristic=at,
        **{k: cfg[k] for k in ("policies", "inspect_every", "delay") if k in cfg},
    )  # fmt: skip
    res = feedback_from_values(
        values, us, profile=study.profile, parts=pids, u_systematic=usys, finish=fin,
        settings=settings, study=study.name, method=used, progress=say,
    )  # fmt: skip
    return replace(res, notes=(*notes, *res.notes))
