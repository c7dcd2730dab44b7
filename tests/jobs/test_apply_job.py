"""The main job records the one route to the machine (`apply_route`) and its
progress ends with "main job finished", not "done" (the caller says that)."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.io import load_study
from piecs_bayes.jobs import APPLY_ROUTES, JobOptions, apply_route, run_job

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"


@pytest.fixture(scope="module")
def study():
    return load_study(DEMO)


def _with(study, apply=None, program=True):
    s = replace(study, compensation=replace(study.compensation, apply=apply))
    return s if program else replace(s, program=None)


def test_apply_route_default_study_and_option(study):
    assert APPLY_ROUTES == ("program", "errspec", "tool_offset", "none")
    assert apply_route(study) == ("program", "the default: the study names a part program")
    assert apply_route(_with(study, program=False))[0] == "errspec"
    assert apply_route(_with(study, "tool_offset")) == (
        "tool_offset",
        "the study's [compensation] apply",
    )
    assert apply_route(_with(study, "tool_offset"), "none") == ("none", "chosen with --apply")
    with pytest.raises(InputError, match=r"--apply: unknown route 'both'"):
        apply_route(study, "both")
    with pytest.raises(InputError, match=r"study\.toml: compensation\.apply: 'program', but"):
        apply_route(_with(study, "program", program=False))
    with pytest.raises(InputError, match=r"study\.toml: --apply: 'program', but"):
        apply_route(_with(study, program=False), "program")


def test_run_job_records_the_route_and_finishes_without_done(study):
    lines: list[str] = []
    res = run_job(
        _with(study, "errspec"), JobOptions(bayes=False, uncertainty=False, capability=False),
        progress=lines.append,
    )  # fmt: skip
    assert (res.apply, res.apply_why) == ("errspec", "the study's [compensation] apply")
    assert res.settings["apply"] == "errspec"
    assert "apply: errspec" in repr(res)
    assert lines[-1].startswith("main job finished in ") and lines[-1].endswith("route: errspec")
    assert not any(line == "done" for line in lines)
    # a long step says so when it starts
    assert lines.index("fitting 7 features") < next(
        i for i, line in enumerate(lines) if line.startswith("fitted")
    )
    res = run_job(study, JobOptions(bayes=False, uncertainty=False, capability=False, apply="none"))
    assert res.apply == "none"


def test_route_file_names_are_the_files_written(study, tmp_path):
    from piecs_bayes.export.machine import route_file_names, write_machine_files
    from piecs_bayes.jobs import machine_data

    res = run_job(study, JobOptions(bayes=False, uncertainty=False, capability=False))
    for route in APPLY_ROUTES:
        r = replace(res, apply=route)
        data = machine_data(study, res.fit, gain=dict(res.gains), routes=(route,))
        mf = write_machine_files(study, data, tmp_path / route, route=route, program=res.program)
        written = {p.name for p in mf.written}
        names = route_file_names(r)
        assert set(names) <= written and (bool(names) == (route != "none")), (route, names)
        assert mf.alternatives == ()
        assert set(mf.as_dict()["files"]) == written


def test_job_options_defaults_and_refusal():
    """`JobOptions` holds what `run_job` took as keywords, with the same defaults; a bad
    `capability` is refused with the message it had (now before the job runs)."""
    o = JobOptions()
    assert (o.method, o.bayes, o.nsteps, o.seed, o.decisions, o.uncertainty, o.program) == (
        None, True, None, 0, True, True, True
    )  # fmt: skip
    assert (o.nose_radius, o.tool_table, o.errspec, o.capability, o.apply) == (
        None, None, True, "auto", None
    )  # fmt: skip
    for bad in ("yes", 1, None):
        with pytest.raises(InputError, match="capability: got .*, expected 'auto', True or False"):
            JobOptions(capability=bad)
