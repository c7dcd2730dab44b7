"""The study file's `[feedback]` table: feedback over a production run
(`piecs-bayes feedback`, `jobs.feedback_study`; docs/formats.md).

```toml
[feedback]
tool_changes = ["part21"]          # parts cut first after a tool change (part ids)
policies = ["none", "ewma", "bayes"]   # default: every policy
finish_files = ["finish/*.csv"]    # finished-part measurements (post-process loop)
characteristic = "mid"             # default: capability.characteristic, else "mid"
inspect_every = 5                  # every 5th part measured (default 1: every part)
delay = 1                          # a result arrives 1 part late (default 0)
```

`inspect_every` says that the probe files hold every `inspect_every`-th part of the
production run (the parts between are cut and not measured); `delay` that a part's
result arrives after `delay` more parts are cut. Both shape the tracking (a part not
measured is a prediction step), the replay (a correction is decided when a result
arrives and held until the next) and the next-part recommendation.

Every key is optional and checked here (type, known names; `finish_files`
resolved against the study's folder, each pattern must match a file); the part
ids of `tool_changes` are checked against the run's parts by the job, which
knows them. Errors name the file, the key path and the value.
"""

from __future__ import annotations

from pathlib import Path
from types import MappingProxyType

from ._reader import Reader

#: the replayed policies (`compensate._feedback.POLICIES`; a test keeps the two equal)
FEEDBACK_POLICIES = ("none", "full", "fixed_gain", "mean_value", "ewma", "dewma", "bayes")

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
