"""The compiler's code generators (issue 39, `_config.LONG_RUNNING`): a run compiles
with XLA's elemental emitter (two thirds of the compile time) unless the user chose in
XLA_FLAGS, a child process keeps the choice as its parent's, and the programs that
run long ask for the fusion emitters through their compiler options."""

from __future__ import annotations

import json
import os
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from piecs_bayes import _config

_SHOW = (
    "import json, os; from piecs_bayes import _config; "
    "print(json.dumps([os.environ.get('XLA_FLAGS', ''), _config.LONG_RUNNING]))"
)


def _child(env_xla: str | None, marker: str | None = None) -> tuple[str, dict]:
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", _config._MARK)}
    if env_xla is not None:
        env["XLA_FLAGS"] = env_xla
    if marker is not None:
        env[_config._MARK] = marker
    out = subprocess.run([sys.executable, "-c", _SHOW], env=env, capture_output=True,
                         text=True, check=True)  # fmt: skip
    flags, options = json.loads(out.stdout)
    return flags, options


def test_a_run_compiles_with_the_elemental_emitter_and_long_programs_ask_for_fusion():
    import jaxlib

    if not jaxlib.__version__.startswith("0.10."):
        pytest.skip(f"jaxlib {jaxlib.__version__}: the flag is set on 0.10 only")
    flags, options = _child(None)
    assert flags.split() == ["--xla_cpu_use_fusion_emitters=false"]
    assert options == {"xla_cpu_use_fusion_emitters": True}
    # another XLA flag of the user's is kept, ours appended
    flags, options = _child("--xla_cpu_max_isa=AVX2")
    assert flags.split() == ["--xla_cpu_max_isa=AVX2", "--xla_cpu_use_fusion_emitters=false"]
    assert options == {"xla_cpu_use_fusion_emitters": True}
    # a child process inherits XLA_FLAGS and the marker: the choice is still ours
    flags, options = _child("--xla_cpu_use_fusion_emitters=false",
                            "--xla_cpu_use_fusion_emitters=false")  # fmt: skip
    assert flags.split() == ["--xla_cpu_use_fusion_emitters=false"]
    assert options == {"xla_cpu_use_fusion_emitters": True}


@pytest.mark.parametrize("value", ["true", "false"])
def test_the_users_choice_in_xla_flags_holds_for_every_program(value):
    flags, options = _child(f"--xla_cpu_use_fusion_emitters={value}")
    assert flags == f"--xla_cpu_use_fusion_emitters={value}"
    assert options == {}


def test_a_kept_trace_compiles_with_its_compiler_options(tmp_path, monkeypatch):
    """The options reach XLA (an unknown one is refused by name) and the program
    computes the same as without them."""
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))

    def f(x):
        return jnp.tanh(x) * jnp.exp(-x * x) + jnp.log1p(x * x)

    x = np.linspace(-2.0, 2.0, 101)
    plain = _config.KeptTrace("codegen_test", ("plain",), jax.jit(f)).compiled(x)
    fused = _config.KeptTrace("codegen_test", ("fused",), jax.jit(f),
                              {"xla_cpu_use_fusion_emitters": True}).compiled(x)  # fmt: skip
    np.testing.assert_allclose(np.asarray(fused(x)), np.asarray(plain(x)), rtol=1e-14, atol=1e-15)
    wrong = _config.KeptTrace("codegen_test", ("wrong",), jax.jit(f), {"xla_no_such_flag": 1})
    with pytest.raises(Exception, match="xla_no_such_flag"):
        wrong.compiled(x)
