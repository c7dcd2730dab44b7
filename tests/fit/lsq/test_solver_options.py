"""The least-squares engine's `SolverOptions`: the defaults `least_squares` and
`solve_arrays` had as keywords, and their refusals."""

from __future__ import annotations

import inspect

import numpy as np
import pytest

from piecs_bayes.errors import InputError
from piecs_bayes.fit.lsq import SolverOptions, least_squares, solve_arrays


def test_defaults_are_the_keywords_they_replace():
    s = SolverOptions()
    assert (s.method, s.rtol, s.atol, s.max_steps) == ("lm", 1e-10, 1e-12, 1000)
    for fn in (least_squares, solve_arrays):
        assert inspect.signature(fn).parameters["solver"].default == s
    assert SolverOptions("dogleg", max_steps=np.int64(5)).max_steps == 5


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"method": "bfgs"}, r"^unknown solver 'bfgs'; expected one of \('lm', 'gauss_newton', "),
        ({"max_steps": 0}, r"^max_steps must be a positive integer, got 0$"),
        ({"max_steps": 2.5}, r"^max_steps must be a positive integer, got 2.5$"),
    ],
)
def test_bad_values_are_refused_as_before(kwargs, match):
    with pytest.raises(InputError, match=match):  # a ValueError, as solve_arrays' was
        SolverOptions(**kwargs)
