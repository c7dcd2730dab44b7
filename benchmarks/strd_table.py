"""Print the NIST StRD digits table for piecs_bayes.fit.least_squares.

For each data set and certified start: the status of a plain Levenberg-Marquardt
fit, the minimum number of matching significant digits (lmfit's count,
-log10(|a-b|/|b|)) of the parameters, of the standard errors and of the residual
sum of squares, and the steps used. A failed start is retried with the setting
the test suite documents (tests/fit/lsq/test_strd.py, EXPECTED_FAILURES).

Run: ``.venv/bin/python benchmarks/strd_table.py [--markdown]``
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

os.environ.setdefault("JAX_PLATFORMS", "cpu")
TESTS = Path(__file__).resolve().parents[1] / "tests"
sys.path.insert(0, str(TESTS))
sys.path.insert(0, str(TESTS / "fit" / "lsq"))  # test_strd

from helpers import STRD_DIR, STRD_MODELS, fit_strd, read_strd  # noqa: E402
from test_strd import EXPECTED_FAILURES, SOLVER, _digits  # noqa: E402

import piecs_bayes  # noqa: E402,F401  (float64)


def rows():
    for name in sorted(STRD_MODELS):
        prob = read_strd(STRD_DIR / f"{name}.dat")
        for k, start in ((1, prob.start1), (2, prob.start2)):
            t0 = time.perf_counter()
            res = fit_strd(prob, start, solver=SOLVER)
            yield name, k, "", res, _digits(res, prob), time.perf_counter() - t0
            if (name, k) in EXPECTED_FAILURES:
                kw = EXPECTED_FAILURES[(name, k)]
                res = fit_strd(prob, start, solver=SOLVER, **kw)
                note = ", ".join(f"{a}={v!r}" for a, v in kw.items())
                yield name, k, note, res, _digits(res, prob), 0.0


def main(markdown: bool = False) -> None:
    head = ("data set", "start", "status", "params", "std err", "RSS", "steps", "note")
    if markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "---|" * len(head))
    else:
        print(
            f"{head[0]:9s} {head[1]:>5s}  {head[2]:18s} {'params':>6s} {'stderr':>6s} "
            f"{'RSS':>5s} {'steps':>5s}  note"
        )
    for name, k, note, res, d, _ in rows():
        shown = {key: (f"{v:.1f}" if res.converged else "-") for key, v in d.items()}
        cells = (
            name,
            str(k),
            res.status.name,
            shown["params"],
            shown["stderr"],
            shown["rss"],
            str(res.steps),
            note,
        )
        if markdown:
            print("| " + " | ".join(cells) + " |")
        else:
            print(
                f"{cells[0]:9s} {cells[1]:>5s}  {cells[2]:18s} {cells[3]:>6s} {cells[4]:>6s} "
                f"{cells[5]:>5s} {cells[6]:>5s}  {cells[7]}"
            )


if __name__ == "__main__":
    main(markdown="--markdown" in sys.argv)
