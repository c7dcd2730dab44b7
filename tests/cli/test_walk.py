"""A reader's walk (issue 37): `piecs-bayes fit` and `plan` pass from the command line
into the numerics through at most 5 packages, never coming back to one they left
(benchmarks/walk.py, which docs/architecture.md tells a reader to run)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
DEMO = ROOT / "data" / "demo" / "study.toml"


def _walk_module():
    spec = importlib.util.spec_from_file_location("walk", ROOT / "benchmarks" / "walk.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


@pytest.mark.parametrize("command", ["fit", "plan"])
def test_the_walk_is_short_and_one_way(command, tmp_path, capsys):
    walk = _walk_module()
    chains, code = walk.walk([command, str(DEMO), "--out", str(tmp_path), "--quiet"])
    assert code == 0
    longest = max(chains, key=len)
    assert len(longest) <= 5, longest
    assert [c for c in chains if len(set(c)) < len(c)] == []
    # it reaches the numerics: the fit's path goes down to geometry
    assert any(c[:2] == ("cli", "jobs") and c[-1] == "geometry" for c in chains)
    assert walk.report(chains, 5) == 0
    capsys.readouterr()


def test_the_walk_sees_a_return():
    walk = _walk_module()
    from collections import Counter

    chains = Counter({("cli", "export", "io", "export"): 1, ("cli", "jobs"): 3})
    assert walk.report(chains, 5) == 1
