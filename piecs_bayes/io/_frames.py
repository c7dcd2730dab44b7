"""Result rows as a pandas DataFrame, the same table as their CSV read back.

The results' `rows()` are the one source of both: `export` writes them as CSV,
`to_dataframe()` hands them to pandas here. pandas is imported only when a frame is
asked for (the command line starts without it).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

import numpy as np


def rows_to_dataframe(rows: Iterable[Mapping], columns: list[str] | None = None):
    """The rows (dicts, one per table row) as a `pandas.DataFrame`.

    Missing values are what `pandas.read_csv` makes of the CSV's empty cells: an
    empty string or `None` is NaN, and a column without any value is float; so
    `to_dataframe()` equals `pd.read_csv` of the matching CSV (to its 10 digits).

    **Arguments:**

    - `rows`: dicts with the same keys in the same order (missing keys: NaN).
    - `columns`: the column order (default: the keys of the rows).

    **Returns:** a `pandas.DataFrame`, one row per dict.
    """
    import pandas as pd

    frame = pd.DataFrame.from_records(list(rows), columns=columns)
    for name in frame.columns:
        col = frame[name]
        if not (pd.api.types.is_object_dtype(col) or pd.api.types.is_string_dtype(col)):
            continue
        missing = col.isna() | col.eq("")
        if missing.all():
            frame[name] = np.nan
        elif missing.any():
            frame[name] = col.where(~missing, np.nan)
    return frame.infer_objects()
