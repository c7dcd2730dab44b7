"""The main job and the capability study give the recorded outputs (tests/golden.py).

These guard refactors: moving code must not change a number. Both jobs run exactly as
their commands do (`make demo`; `piecs-bayes capability data/batch/study.toml`),
with their default seeds, once per session.
"""

import warnings

import golden
import pytest


@pytest.fixture(scope="module")
def outputs(tmp_path_factory):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the CLI prints warnings; not the point here
        root = tmp_path_factory.mktemp("golden")
        return {
            "demo": golden.run_demo(root / "demo"),
            "capability": golden.run_capability(root / "capability"),
        }


@pytest.mark.parametrize("job", ["demo", "capability"])
def test_outputs_equal_the_recorded_ones(outputs, job):
    why = golden.version_mismatch(job)
    if why:
        pytest.skip(f"golden outputs recorded with other package versions: {why}")
    problems = golden.compare(job, outputs[job])
    assert not problems, "\n".join(problems)


def test_masks_leave_numbers_of_results_alone():
    text = (
        "made 2026-12-01T18:30:25+00:00; converged (8000 steps, 18 s, 1121 effective "
        "samples/s); dia_24 -0.0123 mm; 18.0 s sampling"
    )
    assert golden.masked(text) == (
        "made <time>; converged (8000 steps, <s>, <n> effective samples/s); "
        "dia_24 -0.0123 mm; <s> sampling"
    )
