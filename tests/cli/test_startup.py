"""The command line starts at once (issue 16): parsing the arguments (`--help`) imports
no JAX, and every subpackage that computes switches JAX to float64 when imported. The
report's drawing helper (`export.raster`) imports no JAX either (issue 39)."""

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

ROOT = Path(__file__).resolve().parents[2]
SUBPACKAGES = ("geometry", "io", "gcode", "fit", "compensate", "uncertainty", "jobs",
               "export.report", "export.figures", "export.machine", "export.tables")  # fmt: skip


def _python(code: str, **env_more) -> subprocess.CompletedProcess:
    env = {**os.environ, "JAX_PLATFORMS": "cpu", **env_more}
    return subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True
    )


def test_building_the_parser_and_help_import_no_jax():
    code = (
        "import sys, contextlib, io\n"
        "import piecs_bayes, piecs_bayes.cli\n"
        "parser = piecs_bayes.cli.build_parser()\n"
        "for argv in (['--help'], ['fit', '--help'], ['compensate', '--help']):\n"
        "    with contextlib.redirect_stdout(io.StringIO()), contextlib.suppress(SystemExit):\n"
        "        piecs_bayes.cli.main(argv)\n"
        "heavy = [m for m in ('jax', 'numpy', 'scipy', 'matplotlib', 'pandas') if m in sys.modules]\n"
        "print(','.join(heavy))\n"
    )
    out = _python(code)
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ""


@pytest.mark.parametrize("sub", SUBPACKAGES)
def test_float64_is_on_after_importing_any_subpackage(sub):
    out = _python(
        f"import piecs_bayes.{sub}\n"
        "import jax, jax.numpy as jnp\n"
        "assert jax.config.jax_enable_x64\n"
        "assert jnp.zeros(1).dtype == jnp.float64, jnp.zeros(1).dtype\n"
    )
    assert out.returncode == 0, out.stderr


def test_programs_run_in_the_calling_thread_unless_the_user_says_otherwise():
    """`_config` turns JAX's asynchronous CPU dispatch off (a small call's handoff to
    JAX's thread cost 4x the call); a user's JAX_CPU_ENABLE_ASYNC_DISPATCH is kept. The
    same log posterior gives the same numbers both ways (the same program)."""
    code = (
        "import numpy as np\n"
        "import piecs_bayes._config, jax, jax.numpy as jnp\n"
        "from piecs_bayes.fit.mcmc import gaussian_loglik\n"
        "f = jax.jit(jax.vmap(lambda t, y: gaussian_loglik(y - t[0] - t[1] * jnp.arange(5.0),"
        " jnp.exp(t[2])), in_axes=(0, None)))\n"
        "t = np.array([[0.1, 2.0, -1.0], [0.0, 1.9, -0.5]]); y = 2.0 * np.arange(5.0) + 0.05\n"
        "print(jax.config.read('jax_cpu_enable_async_dispatch'), *np.asarray(f(t, y)).tolist())\n"
    )
    runs = {}
    for env in ({}, {"JAX_CPU_ENABLE_ASYNC_DISPATCH": "1"}):
        out = _python(code, **env)
        assert out.returncode == 0, out.stderr
        flag, *values = out.stdout.split()
        runs[flag] = np.array([float(v) for v in values])
    assert set(runs) == {"False", "True"}
    sigma = np.exp([-1.0, -0.5])
    resid = 2.0 * np.arange(5.0) + 0.05 - np.array([[0.1 + 2.0 * i for i in range(5)],
                                                    [1.9 * i for i in range(5)]])  # fmt: skip
    want = np.sum(-0.5 * (resid / sigma[:, None]) ** 2 - np.log(sigma[:, None])
                  - 0.5 * np.log(2 * np.pi), axis=1)  # fmt: skip
    np.testing.assert_allclose(runs["False"], want, rtol=1e-13)
    np.testing.assert_allclose(runs["True"], runs["False"], rtol=1e-15)


def test_the_drawing_helper_imports_no_jax():
    out = _python(
        "import sys\n"
        "import piecs_bayes.export.raster\n"
        "print(','.join(m for m in ('jax', 'scipy', 'pandas') if m in sys.modules))\n"
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == ""


def test_the_cli_route_names_are_ios():
    from piecs_bayes.cli._common import APPLY_ROUTES
    from piecs_bayes.io import APPLY_ROUTES as IO_ROUTES

    assert APPLY_ROUTES == IO_ROUTES


def test_the_late_imports_in_their_thread_say_nothing(tmp_path):
    """The job's late imports (arviz, matplotlib's backends) load in a thread while the
    sampler runs: arviz's import notice (a FutureWarning, once a day per user cache:
    every time on a new machine) is not shown to the user, as where the main thread
    imports it (`fit.mcmc.import_arviz`)."""
    code = (
        "import warnings\n"
        "warnings.simplefilter('default')\n"
        "from piecs_bayes.cli._common import prefetch_imports\n"
        "prefetch_imports().join()\n"
        "import sys\n"
        "print(','.join(m for m in ('arviz', 'matplotlib.backends.backend_pdf') if m in sys.modules))\n"
    )
    out = _python(code, XDG_CACHE_HOME=str(tmp_path))
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "arviz,matplotlib.backends.backend_pdf"
    assert "ArviZ" not in out.stderr and "Warning" not in out.stderr, out.stderr


def test_a_lazy_module_imports_once_and_keeps_what_was_read():
    """`LazyModule` imports on the first read and keeps each attribute it read, so a
    hot loop's later reads are plain attribute reads."""
    from piecs_bayes import _config

    lazy = _config.LazyModule("json")
    assert "dumps" not in vars(lazy)
    import json

    assert lazy.dumps is json.dumps and vars(lazy)["dumps"] is json.dumps
    with pytest.raises(AttributeError):
        _ = lazy.no_such_name


def test_jax_still_finds_a_rocm_plugin_and_other_callers_see_every_distribution(tmp_path):
    """The ROCm plugin scan at `import jax` is narrowed to the distributions that can be
    one (`_config._rocm_scan_narrowed`): a `jax-rocm7-plugin` on the path is still
    found and loaded as jax would; any other caller, then and after, lists them all."""
    site = tmp_path / "site"
    info = site / "jax_rocm7_plugin-0.1.dist-info"
    info.mkdir(parents=True)
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: jax-rocm7-plugin\nVersion: 0.1\n")
    (site / "jax_rocm7_plugin").mkdir()
    (site / "jax_rocm7_plugin" / "__init__.py").write_text("")
    (site / "jax_rocm7_plugin" / "rocm_plugin_extension.py").write_text("FOUND = True\n")
    code = (
        "import importlib.metadata as md\n"
        "before = md.distributions\n"
        "from piecs_bayes import _config\n"
        "from jax._src.numpy import array_constructors as ac\n"
        "assert md.distributions is before\n"
        "assert getattr(ac.rocm_plugin_extension, 'FOUND', False)\n"
        "with _config._rocm_scan_narrowed():\n"
        "    inside = sorted(d.metadata['Name'] for d in md.distributions())\n"
        "outside = sorted(d.metadata['Name'] for d in md.distributions())\n"
        "assert inside == outside and 'jax-rocm7-plugin' in outside and len(outside) > 10\n"
    )
    out = _python(code, PYTHONPATH=str(site))
    assert out.returncode == 0, out.stderr


def test_a_kept_trace_runs_lapack_without_importing_scipy_linalg(tmp_path):
    """A kept trace's call initialises jaxlib's LAPACK handlers from SciPy's two Cython
    tables loaded alone (`_config.load_lapack_tables`), not from the whole of
    scipy.linalg; the SVD it runs is LAPACK's, and scipy.linalg imported afterwards is
    whole (its Cython tables the same modules)."""
    code = (
        "import sys\n"
        "import numpy as np\n"
        "import jax, jax.numpy as jnp\n"
        "from piecs_bayes import _config\n"
        "svd = _config.KeptTrace('svd_check', 'v1', jax.jit(lambda a: jnp.linalg.svd(a, compute_uv=False)))\n"
        "a = np.random.default_rng(1).normal(size=(7, 3))\n"
        "got = np.asarray(svd(a))\n"
        "assert 'scipy.linalg' not in sys.modules, 'scipy.linalg imported'\n"
        "np.testing.assert_allclose(got, np.linalg.svd(a, compute_uv=False), rtol=1e-13)\n"
        "import scipy.linalg\n"
        "assert scipy.linalg.cython_lapack is sys.modules['scipy.linalg.cython_lapack']\n"
        "np.testing.assert_allclose(scipy.linalg.svd(a, compute_uv=False), got, rtol=1e-13)\n"
    )
    for run in ("traced and kept", "read back"):
        out = _python(code, XDG_CACHE_HOME=str(tmp_path))
        assert out.returncode == 0, f"{run}: {out.stderr}"
