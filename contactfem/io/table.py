"""CSV tables of named columns (contact.csv, path.csv): one way to write a number.

A float is written as the shortest decimal that reads back to it (``repr``), an integer
as itself. The text is built a column at a time, each column's values formatted from a
Python list, which is faster than formatting each field through a generator over the
rows; what remains is the shortest-decimal conversion itself.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

import numpy as np


def csv_table(columns: Mapping[str, Sequence | np.ndarray]) -> str:
    """The CSV text of ``columns`` (name → values, all of one length): a header of the names,
    then one line per row, newline-terminated."""
    names = list(columns)
    fields = [column_text(columns[name]) for name in names]
    lines = [",".join(names), *map(",".join, zip(*fields))]
    return "\n".join(lines) + "\n"


def column_text(values: Sequence | np.ndarray) -> list[str]:
    """Each value as CSV writes it: an integer as itself, anything else as the shortest
    decimal of its float that reads back to it (a list may mix the two)."""
    if isinstance(values, np.ndarray):
        if values.dtype.kind in "iu":
            return list(map(str, values.tolist()))
        return list(map(repr, values.astype(float, copy=False).tolist()))
    return [str(value) if isinstance(value, (int, np.integer)) else repr(float(value)) for value in values]
