"""Shared test set-up: float64, CPU, no plotting windows; shared paths."""

import os
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
os.environ.setdefault("MPLBACKEND", "Agg")

import pytest  # noqa: E402

import piecs_bayes._config  # noqa: E402,F401  (switches float64 on)

ROOT = Path(__file__).resolve().parent.parent
SHARED_REFERENCE = ROOT.parent / "shared" / "reference"
DATA = ROOT / "data"


@pytest.fixture
def reference_dir() -> Path:
    if not SHARED_REFERENCE.is_dir():
        pytest.skip(f"shared reference data not found at {SHARED_REFERENCE}")
    return SHARED_REFERENCE


# ------------------------------------------------------------------ compilations
# What a run compiles (issue 39): every executable JAX builds (from XLA or from the
# persistent cache), the XLA compilations among them, and the seconds spent tracing,
# lowering and compiling; summed over the workers and printed at the end of the run.
# PIECS_BAYES_COMPILE_LOG=FILE also writes each test's share, one JSON line per test.

import json  # noqa: E402
import time  # noqa: E402
from collections import Counter  # noqa: E402

from jax import monitoring  # noqa: E402

_TRACE, _LOWER, _BUILD = (
    "/jax/core/compile/jaxpr_trace_duration",
    "/jax/core/compile/jaxpr_to_mlir_module_duration",
    "/jax/core/compile/backend_compile_duration",
)
_RUN: Counter = Counter()
_TEST: Counter = Counter()
_BY_FUNCTION: Counter = Counter()  # seconds building each function's executables
_BY_FUNCTION_N: Counter = Counter()


def _on_duration(event, duration_secs, fun_name="?", **_):
    key = {_TRACE: "trace_s", _LOWER: "lower_s", _BUILD: "build_s"}.get(event)
    if key is not None:
        _TEST[key] += duration_secs
        if event == _BUILD:
            _TEST["executables"] += 1
            _BY_FUNCTION[fun_name] += duration_secs
            _BY_FUNCTION_N[fun_name] += 1
            if duration_secs > 0.3:
                _TEST[f"fn:{fun_name}"] += 1


def _on_event(event, **_):
    if event == "/jax/compilation_cache/cache_misses":
        _TEST["xla_compiles"] += 1


monitoring.register_event_duration_secs_listener(_on_duration)
monitoring.register_event_listener(_on_event)


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _TEST.clear()
    start = time.perf_counter()
    yield
    _RUN.update({k: v for k, v in _TEST.items() if not k.startswith("fn:")})
    log = os.environ.get("PIECS_BAYES_COMPILE_LOG")
    if log:
        row = {"test": item.nodeid, "wall_s": round(time.perf_counter() - start, 3)}
        row.update({k: round(v, 3) for k, v in _TEST.items()})
        with open(log, "a") as f:
            f.write(json.dumps(row) + "\n")


def pytest_sessionfinish(session):
    log = os.environ.get("PIECS_BAYES_COMPILE_LOG")
    if log and _BY_FUNCTION:
        top = {k: [_BY_FUNCTION_N[k], round(v, 3)] for k, v in _BY_FUNCTION.most_common()}
        with open(log, "a") as f:
            f.write(json.dumps({"build_by_function": top}) + "\n")
    workeroutput = getattr(session.config, "workeroutput", None)
    if workeroutput is not None:  # an xdist worker: hand the sums to the controller
        workeroutput["compilations"] = dict(_RUN)


@pytest.hookimpl(optionalhook=True)
def pytest_testnodedown(node, error):
    _RUN.update(getattr(node, "workeroutput", {}).get("compilations", {}))


def pytest_terminal_summary(terminalreporter):
    if _RUN:
        terminalreporter.write_line(
            f"jax: {int(_RUN['executables'])} executables built, "
            f"{int(_RUN['xla_compiles'])} compiled by XLA (the rest from the persistent "
            f"cache); tracing {_RUN['trace_s']:.0f} s, lowering {_RUN['lower_s']:.0f} s, "
            f"building {_RUN['build_s']:.0f} s, summed over the workers"
        )
