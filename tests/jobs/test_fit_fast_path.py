"""One fast path (issue 16): `fit_study` (the CLI's and the main job's fit) runs the
batch kernel, every feature of the part in one compiled call (`fit_profile(solver=
"auto")`), with the per-feature loop's results, errors and messages; its trace is
kept across processes (`_config.persisted`), and a missing or broken file is traced
again."""

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes import _config
from piecs_bayes.errors import AnalysisError, InputError
from piecs_bayes.fit import FitOptions, fit_profile, to_part_frame
from piecs_bayes.io import load_study
from piecs_bayes.jobs import fit_options, fit_study, load_probe_data

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo" / "study.toml"
BATCH = ROOT / "data" / "batch" / "study.toml"


def _loop(study, probe, method, part=None):
    """The per-feature loop (`fit_profile(solver="lm")`) on the same points."""
    return fit_profile(
        study.profile, probe.feature, to_part_frame(study.transform, probe.points),
        ball_radius=study.probe.ball_radius, options=replace(fit_options(study, method), solver="lm"),
        lines=probe.lines, file=probe.file,
        part=part if part is not None else probe.parts[0],
    )  # fmt: skip


def _assert_same_fit(loop, fast):
    """The tolerances of tests/fit/test_batch.py (the batch path against the loop)."""
    assert type(fast) is type(loop)
    assert fast.part == loop.part and fast.unmeasured == loop.unmeasured
    assert fast.method == loop.method and list(fast.fits) == list(loop.fits)
    assert fast.sigma.source == loop.sigma.source and fast.sigma.dof == loop.sigma.dof
    np.testing.assert_allclose(fast.sigma.value, loop.sigma.value, rtol=1e-6)
    for fid, a in loop.fits.items():
        b = fast[fid]
        assert a.method == b.method and a.fixed == b.fixed
        assert a.result.status == b.result.status and b.converged
        np.testing.assert_array_equal(a.lines, b.lines)
        np.testing.assert_allclose(b.points, a.points, rtol=0, atol=1e-12)
        np.testing.assert_array_equal(a.outliers, b.outliers)
        np.testing.assert_allclose(b.values, a.values, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.std_errors, a.std_errors, rtol=1e-6)
        np.testing.assert_allclose(b.covariance, a.covariance, rtol=1e-6, atol=1e-30)
        np.testing.assert_allclose(b.residuals, a.residuals, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.weights, a.weights, rtol=1e-6, atol=1e-9)
        np.testing.assert_allclose(b.error_vectors, a.error_vectors, rtol=0, atol=1e-9)
        np.testing.assert_allclose(b.nominal_points, a.nominal_points, rtol=0, atol=1e-9)
        assert b.result.n == a.result.n and b.result.dof == a.result.dof
        np.testing.assert_allclose(b.residual_sd, a.residual_sd, rtol=1e-6)
    assert [r["parameter"] for r in fast.rows()] == [r["parameter"] for r in loop.rows()]


@pytest.mark.parametrize("method", ["robust", "lsq"])
def test_fit_study_equals_the_per_feature_loop_on_the_demo_part(method):
    study = load_study(DEMO)
    probe = load_probe_data(study)
    fast = fit_study(study, probe, method=method)
    _assert_same_fit(_loop(study, probe, method), fast)
    if method == "robust":  # the chip under the stylus on dia_30
        assert fast["dia_30"].outliers.tolist() == [5]


def test_fixed_parameters_known_sigma_and_a_missing_feature_equal_the_loop():
    study = load_study(BATCH)
    files = sorted(study.path.parent.glob("part*.csv"))[:3]
    probe = load_probe_data(study, files)
    keep = ~((probe.part == "part02") & (probe.feature == "shoulder"))
    probe = probe.select(keep)
    fixed = replace(study, fit=replace(study.fit, fix=("fillet.radius",)))
    known = replace(study, fit=replace(study.fit, known_sigma=True))
    for s, method in ((fixed, "robust"), (known, "lsq"), (study, "robust")):
        for part in probe.parts:
            one = probe.for_part(part)
            fast = fit_study(s, probe, method=method, part=part)
            _assert_same_fit(_loop(s, one, method, part), fast)
    assert fit_study(study, probe, part="part02").unmeasured == ("shoulder",)
    assert np.all(fit_study(fixed, probe, part="part01")["fillet"].values[2] == 0.0)


def test_a_fit_that_fails_raises_the_loops_error():
    study = load_study(DEMO)
    probe = load_probe_data(study)
    pts = probe.points.copy()
    pts[np.flatnonzero(probe.feature == "dia_24")[2]] = np.nan
    bad = replace(probe, points=pts)
    with pytest.raises(AnalysisError) as loop:
        _loop(study, bad, "robust")
    with pytest.raises(AnalysisError) as fast:
        fit_study(study, bad)
    assert str(fast.value) == str(loop.value) and "non-finite" in str(fast.value)
    assert fast.value.result is not None
    assert fast.value.result.status == loop.value.result.status


def test_a_three_point_line_with_one_point_down_weighted_is_refused_with_the_reason():
    """`[fit] min_points_line = 3` (the default) and a chip of 25 um under the middle
    point of face_end's first three: the robust fit keeps about 2.1 effective points
    for the line's 2 parameters, no residual to judge the points by. Both paths refuse
    with one message naming the feature, the part, the file and the point's line,
    residual and weight, and the ways out; with every point kept (method lsq) the
    same data fit, the chip's residual the largest."""
    study = load_study(DEMO)
    probe = load_probe_data(study)
    rows = np.flatnonzero(probe.feature == "face_end")
    keep = ~np.isin(np.arange(len(probe)), rows[3:])
    pts = probe.points.copy()
    pts[rows[1], 1] += 0.025  # Z, along the face's outward normal
    three = replace(probe, points=pts).select(keep)
    with pytest.raises(AnalysisError) as fast:
        fit_study(study, three)
    with pytest.raises(AnalysisError) as loop:
        _loop(study, three, "robust")
    msg = str(fast.value)
    assert msg == str(loop.value)
    line = int(probe.lines[rows[1]])
    assert msg.startswith("feature 'face_end', part 'probe_part01', probe file ")
    assert "effective points of 3 for 2 parameters" in msg
    assert f"down-weighted: line {line} (residual +2" in msg, msg
    assert "[fit] min_points_line" in msg and 'method = "lsq"' in msg
    eff = float(msg.split("keeps ")[1].split(" ")[0])
    assert 2.0 < eff < 3.0
    plain = fit_study(study, three, method="lsq")["face_end"]
    assert plain.result.converged and plain.outliers.size == 0
    assert np.argmax(np.abs(plain.residuals)) == 1 and abs(plain.residuals[1]) > 0.005


def test_input_errors_are_the_loops():
    study = load_study(DEMO)
    probe = load_probe_data(study)
    rows = np.flatnonzero(probe.feature == "taper")
    short = probe.select(~np.isin(np.arange(len(probe)), rows[2:]))
    with pytest.raises(InputError) as loop:
        _loop(study, short, "robust")
    with pytest.raises(InputError) as fast:
        fit_study(study, short)
    assert str(fast.value) == str(loop.value)
    assert "2 point(s) are too few for a line" in str(fast.value)


def test_a_layout_is_planned_once_and_only_for_itself():
    """Parts of one layout share a plan (`fit._part_fit`): a part fitted after another
    is what it is fitted alone; another layout (points in another order, one point
    fewer, a parameter fixed) gets its own plan and the loop's results; an input error
    is raised again on every call (nothing of a refused part is kept)."""
    from piecs_bayes.fit import _part_fit

    study = load_study(BATCH)
    files = sorted(study.path.parent.glob("part*.csv"))[:3]
    probe = load_probe_data(study, files)
    parts = [probe.for_part(p) for p in probe.parts]
    _part_fit._PLANS.clear()
    after = [fit_study(study, one) for one in parts]
    assert len(_part_fit._PLANS) == 1  # the batch parts share their layout
    for one, fit in zip(parts, after, strict=True):
        _part_fit._PLANS.clear()
        alone = fit_study(study, one)
        for fid, a in alone.fits.items():
            for name in ("values", "covariance", "residuals", "weights", "error_vectors",
                         "nominal_points", "points", "lines", "outliers"):  # fmt: skip
                np.testing.assert_array_equal(getattr(fit[fid], name), getattr(a, name))
        assert fit.sigma == alone.sigma
    rng = np.random.default_rng(16)
    one = parts[1]
    shuffled = one.select(rng.permutation(len(one)))
    fewer = one.select(np.arange(len(one)) != np.flatnonzero(one.feature == "fillet")[0])
    fixed = replace(study, fit=replace(study.fit, fix=("fillet.radius",)))
    for s, data in ((study, shuffled), (study, fewer), (fixed, one)):
        _assert_same_fit(_loop(s, data, "robust"), fit_study(s, data))
    assert len(_part_fit._PLANS) == 4
    short = one.select(~np.isin(np.arange(len(one)), np.flatnonzero(one.feature == "face_end")[2:]))
    for _ in range(2):
        with pytest.raises(InputError, match="too few for a line"):
            fit_study(study, short)
    assert len(_part_fit._PLANS) == 4


def test_the_trace_is_persisted_and_a_broken_file_is_traced_again(tmp_path, monkeypatch):
    pytest.importorskip("flatbuffers")  # jax.export's serialisation needs it
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("PIECS_BAYES_NO_CACHE", raising=False)
    calls = []

    def build():
        import jax
        import jax.numpy as jnp

        calls.append(1)
        meta = {"n": 0}

        def f(x):
            meta["n"] = int(x.shape[0])
            return jnp.cumsum(x) * 2.0

        return jax.jit(f), (jax.ShapeDtypeStruct((3,), float),), meta

    key = ("test", 3)
    f1, m1 = _config.persisted("unit_test", key, build, packages=("fit",))
    files = list((tmp_path / "piecs_bayes" / "export").glob("unit_test-*.bin"))
    assert len(files) == 1 and m1 == {"n": 3} and len(calls) == 1
    np.testing.assert_array_equal(f1(np.arange(3.0)), [0.0, 2.0, 6.0])
    f2, m2 = _config.persisted("unit_test", key, build, packages=("fit",))  # read back
    assert len(calls) == 1 and m2 == {"n": 3}
    np.testing.assert_array_equal(f2(np.arange(3.0)), [0.0, 2.0, 6.0])
    files[0].write_bytes(b"\x05\x00\x00\x00\x00\x00\x00\x00{bad}garbage")  # broken: traced again
    f3, m3 = _config.persisted("unit_test", key, build, packages=("fit",))
    assert len(calls) == 2 and m3 == {"n": 3}
    np.testing.assert_array_equal(f3(np.arange(3.0)), [0.0, 2.0, 6.0])
    _config.persisted("unit_test", ("test", 4), build, packages=("fit",))  # another key
    assert len(calls) == 3
    monkeypatch.setenv("PIECS_BAYES_NO_CACHE", "1")  # nothing read or written
    _config.persisted("unit_test", ("test", 5), build, packages=("fit",))
    assert len(calls) == 4 and len(list(files[0].parent.glob("unit_test-*.bin"))) == 2


def test_traces_unused_for_long_are_pruned_when_one_is_written(tmp_path, monkeypatch):
    pytest.importorskip("flatbuffers")
    import os
    import time

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    monkeypatch.delenv("PIECS_BAYES_NO_CACHE", raising=False)
    folder = tmp_path / "piecs_bayes" / "export"
    folder.mkdir(parents=True)
    days = 86400.0 * _config.EXPORT_MAX_AGE_DAYS
    stale, recent = folder / "part_fit-stale.bin", folder / "part_fit-recent.bin"
    for f, age in ((stale, days + 3600), (recent, days - 3600)):
        f.write_bytes(b"x")
        os.utime(f, (time.time() - age, time.time() - age))

    def build():
        import jax
        import jax.numpy as jnp

        return jax.jit(lambda x: jnp.sum(x)), (jax.ShapeDtypeStruct((2,), float),), {}

    _config.persisted("unit_test", ("prune", 1), build, packages=("fit",))
    assert not stale.exists() and recent.exists()
    [new] = folder.glob("unit_test-*.bin")
    os.utime(new, (time.time() - days - 3600,) * 2)  # old, but read again: touched, kept
    _config.persisted("unit_test", ("prune", 1), build, packages=("fit",))
    _config.persisted("unit_test", ("prune", 2), build, packages=("fit",))  # a write
    assert new.exists() and len(list(folder.glob("unit_test-*.bin"))) == 2


def test_unknown_solver_is_refused():
    study = load_study(DEMO)
    probe = load_probe_data(study)
    with pytest.raises(InputError, match="unknown solver 'newton'"):
        fit_profile(study.profile, probe.feature, probe.points, ball_radius=1.0,
                    options=FitOptions(solver="newton"))  # fmt: skip
