"""The data outputs: strict JSON (every command's --json, the nodes' summary) and CSV (output columns, rows of
mixed values).

Light to import (the standard library only at module level): numpy, the model and the scene load inside the
functions that need them.
"""

from __future__ import annotations

import json
import math
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from collections.abc import Iterable

    import numpy as np


def to_json(data) -> str:
    """Strict JSON (no NaN or Infinity, which jq and JavaScript reject): non-finite numbers become null."""
    import numpy as np

    def finite(value):
        if isinstance(value, dict):
            return {key: finite(item) for key, item in value.items()}
        if isinstance(value, (list, tuple)):
            return [finite(item) for item in value]
        if isinstance(value, (np.floating, np.integer)):
            value = value.item()
        if isinstance(value, float) and not math.isfinite(value):
            return None
        return value

    return json.dumps(finite(data), indent=2, allow_nan=False)


def write_csv(path, columns: dict[str, np.ndarray] | Iterable[dict[str, np.ndarray]], digits: int = 12) -> None:
    """Write output columns as CSV with a header line (digits significant digits; 17 round-trips a double
    exactly). columns: a dict of equal-length columns, or an iterable of such dicts whose rows follow one another
    (the header from the first; memory then holds one at a time)."""
    with open(path, "w") as file:
        for index, chunk in enumerate([columns] if isinstance(columns, dict) else columns):
            write_csv_rows(file, chunk, digits, header=index == 0)


def write_csv_rows(file, columns: dict[str, np.ndarray], digits: int = 12, header: bool = True) -> None:
    """Write output columns to the open text file `file` as CSV rows (digits significant digits), the header line
    first when `header`: each row is formatted on its own, so that rows written in pieces make the same file."""
    import numpy as np

    np.savetxt(
        file,
        np.column_stack(list(columns.values())),
        delimiter=",",
        header=",".join(columns) if header else "",
        comments="",
        fmt=f"%.{digits}g",
    )


def write_rows_csv(path, rows: list[dict], digits: int = 17) -> None:
    """Write rows of mixed values (numbers, text, booleans) as CSV with a header line, the first row's keys in
    order: numbers with `digits` significant digits (17 round-trips a double), None as an empty field, text
    quoted where it needs to be (the csv module)."""
    import csv

    def field(value):
        if isinstance(value, float):
            return f"{value:.{digits}g}"
        return "" if value is None else value

    with open(path, "w", newline="", encoding="utf-8") as file:
        writer = csv.writer(file)
        writer.writerow(list(rows[0]) if rows else [])
        writer.writerows([field(value) for value in row.values()] for row in rows)
