"""Writers: results tables, adjusted programs, error-spec files, reports. Never re-fit."""

from ._atomic import write_bytes_atomic as write_bytes_atomic
from ._atomic import write_text_atomic as write_text_atomic
