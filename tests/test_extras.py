"""The optional extras (`dask`, `notebooks`) are optional: the package and its CLI
work without them, and `--scheduler` without Dask says which extra to install."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

BATCH = Path(__file__).resolve().parents[1] / "data" / "batch" / "study.toml"

#: modules of the optional extras, made unimportable (None in sys.modules)
EXTRAS = ("dask", "distributed", "jupyterlab", "jupyter_server", "notebook")

_WITHOUT_EXTRAS = f"""
import sys
for name in {EXTRAS!r}:
    sys.modules[name] = None
from piecs_bayes.cli import main
"""


def _run(code: str, *args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "JAX_PLATFORMS": "cpu", "MPLBACKEND": "Agg"}
    return subprocess.run(
        [sys.executable, "-c", _WITHOUT_EXTRAS + code, *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=300,
    )


_IMPORT_ALL_AND_HELP = f"""
import importlib, pkgutil
import piecs_bayes
for info in pkgutil.walk_packages(piecs_bayes.__path__, "piecs_bayes."):
    importlib.import_module(info.name)
try:
    main(["--help"])
except SystemExit as exc:
    assert not exc.code, exc.code
loaded = [m for m in sys.modules if m.split(".")[0] in {EXTRAS!r} and sys.modules[m]]
assert not loaded, loaded
"""


def test_every_module_and_the_cli_load_without_the_extras():
    done = _run(_IMPORT_ALL_AND_HELP)
    assert done.returncode == 0, done.stderr
    assert "capability" in done.stdout


def test_scheduler_without_dask_names_the_extra(tmp_path):
    done = _run(
        "sys.exit(main(sys.argv[1:]))",
        "capability",
        str(BATCH),
        "--glob",
        "part0[1-3].csv",
        "--scheduler",
        "tcp://127.0.0.1:1",
        "--out",
        str(tmp_path / "cap"),
    )
    assert done.returncode == 2, done.stderr
    assert 'pip install "piecs_bayes[dask]"' in done.stderr
    assert "Traceback" not in done.stderr
