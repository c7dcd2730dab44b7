"""``piecs-bayes``: one command per user job; a thin layer over the public API.

Exit codes: 0 ok, 1 the analysis failed (no convergence, a gouge, a correction
above the limit), 2 bad input (a file, a cell, a setting) or usage, 130 interrupted,
143 terminated, 141 (quietly) when the reader of standard output went away.
"""

from ._main import build_parser as build_parser
from ._main import main as main
