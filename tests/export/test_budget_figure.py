"""The uncertainty budget figure: each source's share of a feature parameter's
variance, and a parameter without variance (a feature the plan could not measure, as
on LinuxCNC's shipped pawn) drawn with no share, not a division by zero."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest

from piecs_bayes.export.figures import budget_figure
from piecs_bayes.io import load_study
from piecs_bayes.jobs import fit_study, linearised_uncertainty

DEMO = Path(__file__).resolve().parents[2] / "data" / "demo" / "study.toml"


@pytest.fixture(scope="module")
def demo_lin():
    study = load_study(DEMO)
    return study, linearised_uncertainty(study, fit_study(study))


def _shares(fig) -> np.ndarray:
    """The bars' widths per source (rows: sources, columns: parameters)."""
    ax = fig.axes[0]
    return np.array([[bar.get_width() for bar in c] for c in ax.containers])


def test_shares_sum_to_the_whole_and_a_parameter_without_variance_has_none(demo_lin):
    study, lin = demo_lin
    shares = _shares(budget_figure(lin, study.profile))
    np.testing.assert_allclose(shares.sum(axis=0), 100.0, rtol=1e-12)
    # the first parameter without variance: every source 0 of 0 (a feature not measured)
    budget = {k: np.array(v, dtype=float) for k, v in lin.deviation_budget.items()}
    for v in budget.values():
        v[0] = 0.0
    unmeasured = dataclasses.replace(lin, deviation_budget=budget)
    shares = _shares(budget_figure(unmeasured, study.profile))  # no RuntimeWarning (errors)
    assert np.all(shares[:, 0] == 0.0)
    np.testing.assert_allclose(shares[:, 1:].sum(axis=0), 100.0, rtol=1e-12)
