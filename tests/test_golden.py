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


def _perturbed(text: str, rel: float) -> str:
    """Every decimal number of ``text`` times (1 + rel), printed at full precision."""
    return golden._NUMBER.sub(
        lambda m: repr(float(m.group()) * (1 + rel)) if "." in m.group() else m.group(), text
    )


@pytest.mark.parametrize("fname", ["fit.json", "toolpath.csv", "decisions.csv", "fit.csv"])
def test_a_change_of_1e6_relative_is_caught(fname):
    text = (golden.GOLDEN / "demo" / fname).read_text()
    assert golden.compare_text_file(fname, text, text) == []
    problems = golden.compare_text_file(fname, text, _perturbed(text, 1e-6))
    assert problems and "deterministic" in problems[0] and "relative" in problems[0], problems


def test_a_last_bit_change_passes_and_a_word_change_fails():
    text = (golden.GOLDEN / "demo" / "residuals.csv").read_text()
    assert golden.compare_text_file("residuals.csv", text, _perturbed(text, 1e-9)) == []
    changed = text.replace("dia_24", "dia_25", 1)
    assert "expected 24, got 25" in golden.compare_text_file("residuals.csv", text, changed)[0]


def test_monte_carlo_numbers_are_held_to_their_sampling_error():
    text = (golden.GOLDEN / "demo" / "posterior.csv").read_text()
    ess = (20000.0, 20000.0)
    # a mean moved by 1 standard error (sd / sqrt(ESS)) passes, by 10 it fails
    rows = text.splitlines()
    head, row = rows[0].split(","), rows[1].split(",")
    mean, sd = float(row[head.index("mean")]), float(row[head.index("sd")])
    for k, ok in ((1.0, True), (10.0, False)):
        moved = list(row)
        moved[head.index("mean")] = repr(mean + k * sd / ess[0] ** 0.5)
        new = "\n".join([rows[0], ",".join(moved), *rows[2:]]) + "\n"
        assert (golden.compare_text_file("posterior.csv", text, new, ess) == []) is ok
