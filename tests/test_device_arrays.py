"""Arrays reach the device without a compiled program per shape (issue 39).

jax 0.10's `jnp.asarray` of a NumPy array binds `lax.stage`, an identity XLA compiles
once per shape and dtype; `jax.random.PRNGKey` compiles two programs. The package
transfers instead (`_config.on_device`) and makes the sampler's key in NumPy
(`threefry_key`): the same values, nothing compiled.
"""

from __future__ import annotations

import jax
import numpy as np
import pytest
from jax import monitoring

from piecs_bayes import _config
from piecs_bayes.fit.mcmc._lockstep import threefry_key

_BUILT: list[str] = []


def _on_duration(event, duration_secs, fun_name="?", **_):
    if event == "/jax/core/compile/backend_compile_duration":
        _BUILT.append(fun_name)


monitoring.register_event_duration_secs_listener(_on_duration)


def test_on_device_transfers_without_compiling_and_keeps_dtypes():
    # shapes no other test uses: a compiled identity would show here
    tree = {
        "a": np.arange(7 * 13, dtype=float).reshape(7, 13),
        "i": np.arange(11, dtype=np.int32),
        "x": 2.5,
        "none": None,
        "j": jax.device_put(np.ones(3)),
    }
    _BUILT.clear()
    out = _config.on_device(tree)
    assert _BUILT == []
    assert isinstance(out["a"], jax.Array) and out["a"].dtype == np.float64
    assert out["i"].dtype == np.int32 and out["x"].dtype == np.float64
    assert out["none"] is None and out["j"] is tree["j"]
    np.testing.assert_array_equal(out["a"], tree["a"])


@pytest.mark.parametrize("seed", [0, 1, 3, 2**31 - 1, 123_456_789, 2**40 + 5])
def test_threefry_key_is_jaxs_key_without_compiling(seed):
    _BUILT.clear()
    key = threefry_key(seed)
    assert _BUILT == []
    np.testing.assert_array_equal(key, np.asarray(jax.random.PRNGKey(seed)))
    assert key.dtype == np.uint32
