"""The study file's `[feedback]` table: feedback over a production run
(`piecs-bayes feedback`, `jobs.feedback_study`; docs/formats.md).

`read_feedback` checks and returns the table as a read-only mapping: `tool_changes`
(part ids cut first after a tool change), `policies` (of `FEEDBACK_POLICIES`; default
every policy), `finish_files` (finished-part measurements: patterns resolved against
the study's folder, each must match a file), `characteristic` (`"mid"`, `"start"`,
`"end"`; default the capability's, else `"mid"`), `inspect_every` (every E-th part of
the run measured; default 1) and `delay` (a result arrives that many parts late;
default 0). Every key is optional (`FEEDBACK_KEYS`); errors name the file, the key path
and the value. The part ids of `tool_changes` are checked against the run's parts by the
job, which knows them.

The table and what each key does: docs/formats.md, "Finished-part measurements".
"""

from __future__ import annotations

from pathlib import Path
from types import MappingProxyType

from ._reader import Reader

#: the replayed policies (`feedback.POLICIES`; a test keeps the two equal)
FEEDBACK_POLICIES = (
    "none", "full", "fixed_gain", "mean_value", "ewma", "dewma", "siemens", "renishaw",
    "heidenhain", "bayes",
)  # fmt: skip

#: the keys of `[feedback]` (for the schema check of the whole study file)
FEEDBACK_KEYS = ("tool_changes", "policies", "finish_files", "characteristic", "inspect_every",
                 "delay")  # fmt: skip

_CHARACTERISTICS = ("mid", "start", "end")


def _strings(r: Reader, sec: dict, key: str, what: str) -> tuple[str, ...]:
    val = sec[key]
    if not isinstance(val, list) or not all(isinstance(v, str) and v.strip() for v in val):
        raise r.error(f"feedback.{key}", f"expected a list of {what}, got {val!r}", value=val)
    seen = set()
    for v in val:
        if v in seen:
            raise r.error(f"feedback.{key}", f"{v!r} is listed twice", value=v)
        seen.add(v)
    return tuple(val)


def read_feedback(r: Reader, sec: dict, base: Path) -> MappingProxyType:
    """Validate `[feedback]` (see the module doc): `{tool_changes: (part id, ...),
    policies: (name, ...), finish_files: (Path, ...), characteristic: str,
    inspect_every: int >= 1, delay: int >= 0}`, only the keys given; `finish_files` as
    the sorted, de-duplicated files their patterns match."""
    out: dict = {}
    for key, val in sec.items():
        if key not in FEEDBACK_KEYS:
            raise r.error(
                f"feedback.{key}",
                f"unknown key {key!r}; expected one of {', '.join(FEEDBACK_KEYS)}",
                value=val,
            )
    if "tool_changes" in sec:
        out["tool_changes"] = _strings(r, sec, "tool_changes", "part ids")
    if "policies" in sec:
        names = _strings(r, sec, "policies", "policy names")
        for v in names:
            if v not in FEEDBACK_POLICIES:
                raise r.error(
                    "feedback.policies",
                    f"unknown policy {v!r}; expected some of {', '.join(FEEDBACK_POLICIES)}",
                    value=v,
                )
        if not names:
            raise r.error("feedback.policies", "expected at least one policy", value=[])
        out["policies"] = names
    if "finish_files" in sec:
        patterns = _strings(r, sec, "finish_files", "file names or patterns")
        files: list[Path] = []
        for pat in patterns:
            found = sorted(base.glob(pat)) if any(c in pat for c in "*?[") else [base / pat]
            found = [p for p in found if p.is_file()]
            if not found:
                raise r.error(
                    "feedback.finish_files",
                    f"{pat!r} matches no file in {base}",
                    value=pat,
                )
            files += [p for p in found if p not in files]
        out["finish_files"] = tuple(files)
    if "inspect_every" in sec:
        out["inspect_every"] = r.integer(sec, "inspect_every", "feedback.", 1, minimum=1)
    if "delay" in sec:
        out["delay"] = r.integer(sec, "delay", "feedback.", 0, minimum=0)
    if "characteristic" in sec:
        out["characteristic"] = r.choice(
            sec, "characteristic", "feedback.", _CHARACTERISTICS, "mid"
        )
    return MappingProxyType(out)
