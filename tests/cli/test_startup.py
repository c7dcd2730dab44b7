"""The command line starts at once (issue 16): parsing the arguments (`--help`) imports
no JAX, and every subpackage that computes switches JAX to float64 when imported. The
report's drawing helper (`export.raster`) imports no JAX either (issue 39)."""

import os
import subprocess
import sys
from pathlib import Path

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
