"""Writers: results tables, adjusted programs, error-spec files, reports. Never re-fit."""

from ._atomic import write_bytes_atomic as write_bytes_atomic
from ._atomic import write_text_atomic as write_text_atomic
from ._tables import fit_csv as fit_csv
from ._tables import fit_json as fit_json
from ._tables import path_csv as path_csv
from ._tables import residuals_csv as residuals_csv
from ._tables import to_csv as to_csv
