"""Process-wide JAX settings, applied once when the package is imported.

float64 is switched on before any array is made: micrometres on a 100 mm part
need it. A persistent compilation cache in the user's cache directory lets a
second CLI run reuse the compiled fits (set ``PIECS_BAYES_NO_CACHE=1`` to opt out).
Every compilation is cached, however short (threshold 0 s): a `fit` run compiles
~50 small programs of 0.03-0.1 s each (eager operations, per-feature helpers)
that the default 1 s (or 0.2 s) threshold left out, ~2 s of a warm run.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

jax.config.update("jax_enable_x64", True)


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "piecs_bayes" / "jax"


if not os.environ.get("PIECS_BAYES_NO_CACHE"):
    try:
        _dir = _cache_dir()
        _dir.mkdir(parents=True, exist_ok=True)
        jax.config.update("jax_compilation_cache_dir", str(_dir))
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    except OSError:  # read-only home: run without the cache
        pass
