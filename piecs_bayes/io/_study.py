"""Study files (TOML): the part's nominal profile, the probe, the machine, the
uncertainty sources, the probe files and the part program of one job.

All lengths are converted to millimetres and X to radius here, at the
boundary; every error names the file, the key path (``profile.feature[2].end``)
and, where there is one, the feature id and the offending value. See
``docs/formats.md`` for the format with an example.

[`load_study`][] reads the file and composes the section readers of
`_sections` (core sections) and `_job_sections` (job sections) into the
[`Study`][] of `_settings`.
"""

from __future__ import annotations

import re
import tomllib
from pathlib import Path
from types import MappingProxyType

from ..errors import InputError
from ._feedback_section import FEEDBACK_KEYS, read_feedback
from ._job_sections import JOB_KEYS, read_job_section, read_plausibility, read_program_settings
from ._reader import Reader
from ._schema import check_keys
from ._sections import (
    read_compensation,
    read_files,
    read_fit,
    read_machine,
    read_probe,
    read_probe_format,
    read_profile,
    read_sources,
)
from ._settings import Study
from ._text import check_encoding, decode, read_bytes

_MM_PER = {"mm": 1.0, "in": 25.4}
_CORE_SECTIONS = {"study", "profile", "probe", "machine", "uncertainty", "fit", "compensation"}


def _parse(path: Path) -> dict:
    """The TOML tree of a study file: UTF-8 (a BOM accepted); a file in another
    encoding is read in the one its own ``encoding = "..."`` line names."""
    name = str(path)
    data = read_bytes(path, what="study file")
    try:
        text = decode(data, file=name)
    except InputError:
        m = re.search(rb'^\s*encoding\s*=\s*"([A-Za-z0-9_.-]+)"', data, flags=re.MULTILINE)
        if m is None:
            raise
        text = decode(
            data, file=name, encoding=check_encoding(m.group(1).decode("ascii"), file=name)
        )
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise InputError(f"not valid TOML: {exc}", file=name) from None


def load_study(path) -> Study:
    """Read and validate a study file.

    **Arguments:**

    - `path`: the TOML file; probe files and the part program are resolved
      relative to its folder.

    **Returns:** a :class:`Study` (mm, radius X).

    **Raises:** :class:`InputError` naming the file, key path, feature and value.
    """
    path = Path(path)
    name = str(path)
    tree = _parse(path)
    check_keys(tree, name, {**JOB_KEYS, "feedback": FEEDBACK_KEYS})
    r = Reader(name)
    study = r.table(tree, "study", "", required=True)
    encoding = check_encoding(study.get("encoding", "utf-8"), file=name)
    units = r.choice(study, "units", "study.", ("mm", "in"), "mm")
    scale = _MM_PER[units]

    profile = read_profile(r, tree, scale)
    probe = read_probe(r, tree, scale, profile, path.parent)
    transform = read_machine(r, tree, scale)
    sources = read_sources(r, r.table(tree, "uncertainty", ""), scale)
    if probe.calibration is not None and "ball_radius" in sources:
        raise r.error(
            "uncertainty.ball_radius",
            "a source beside [probe] calibration: the calibration's covariance is the "
            "radius's uncertainty (the budget's 'probe calibration'); remove it",
        )
    fit = read_fit(r, tree, scale, profile)
    comp = read_compensation(r, tree, scale)
    probe_files, program = read_files(r, study, path.parent)
    probe_format, probe_plan = read_probe_format(r, study, path.parent, transform)
    program_settings = read_program_settings(
        r, r.table(tree, "program", ""), scale, profile, path.parent
    )
    job = {
        name: MappingProxyType(read_job_section(r, tree, name, scale, profile)) for name in JOB_KEYS
    }
    known = _CORE_SECTIONS | {"program", *job}
    extra = {k: v for k, v in tree.items() if k not in known}
    if "feedback" in extra:  # [feedback]: read by jobs.feedback_study from `sections`
        extra["feedback"] = read_feedback(r, r.table(tree, "feedback", ""), path.parent)
    plausibility = read_plausibility(r, r.table(tree, "plausibility", ""), scale)
    return Study(
        path=path,
        name=str(study.get("name", path.stem)),
        units=units,
        profile=profile,
        probe=probe,
        transform=transform,
        sources=MappingProxyType(sources),
        probe_files=probe_files,
        program=program,
        fit=fit,
        compensation=comp,
        sections=MappingProxyType(extra),
        program_settings=program_settings,
        encoding=encoding,
        plausibility=MappingProxyType(plausibility),
        probe_format=probe_format,
        probe_plan=probe_plan,
        **job,
    )
