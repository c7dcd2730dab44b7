"""Tables of results: CSV/JSON/text of fits, bounds, decisions, capability, feedback,
gauge studies."""

from ... import _config  # noqa: F401  (float64 before any JAX array)
from ._csv import band_csv as band_csv
from ._csv import bounds_csv as bounds_csv
from ._csv import bounds_json as bounds_json
from ._csv import budget_csv as budget_csv
from ._csv import fit_csv as fit_csv
from ._csv import fit_json as fit_json
from ._csv import path_csv as path_csv
from ._csv import posterior_csv as posterior_csv
from ._csv import residuals_csv as residuals_csv
from ._csv import to_csv as to_csv
from ._feedback import feedback_csvs as feedback_csvs
from ._feedback import feedback_json as feedback_json
from ._feedback import feedback_text as feedback_text
from ._gauge import gauge_json as gauge_json
from ._gauge import gauge_text as gauge_text
from ._jobs import capability_csvs as capability_csvs
from ._jobs import capability_json as capability_json
from ._jobs import capability_text as capability_text
from ._jobs import decisions_csv as decisions_csv
from ._jobs import decisions_json as decisions_json
from ._jobs import decisions_text as decisions_text
from ._jobs import percent as percent
from ._jobs import risk_text as risk_text
