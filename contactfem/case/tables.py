"""The numbers of a CSV data file (a profile, an outline): comments, a header, delimiters."""

from __future__ import annotations

import numpy as np

from contactfem.case import limits
from contactfem.case.messages import shortened
from contactfem.case.reader import Reader


class DataLines:
    """The data lines of a CSV file: ``#`` comments and blank lines skipped, the delimiter
    (comma, semicolon or tab, else spaces) taken from the first data line, and that line
    dropped as a header when its first ``numeric`` fields are not all numbers."""

    def __init__(self, r: Reader, fkey: str, text: str, lines: list[str], limit: int, numeric: int | None,
                 expected: str) -> None:
        self.lines = lines
        indices = [i for i, line in enumerate(lines) if (start := line.lstrip()) and start[0] != "#"]
        if not indices:
            raise r.fail(fkey, text, f"the file holds no numbers; expected {expected}")
        first = self.content(lines[indices[0]])
        self.delimiter = next((d for d in (",", ";", "\t") if d in first), None)
        if not all(is_number(f) for f in self.fields(lines[indices[0]])[:numeric]):
            indices = indices[1:]  # a header
        if len(indices) < 2:
            raise r.fail(fkey, text, f"{len(indices)} data lines; expected at least 2 points")
        if len(indices) > limit:
            raise r.fail(fkey, text, f"{len(indices)} data lines; expected at most {limit} points")
        self.indices = indices

    @staticmethod
    def content(line: str) -> str:
        return line.split("#", 1)[0].strip()

    def fields(self, line: str) -> list[str]:
        return [f.strip() for f in self.content(line).split(self.delimiter)]

    def line_of(self, row: int) -> int:
        """The 1-based line number of data row ``row``."""
        return self.indices[row] + 1


def is_number(field: str) -> bool:
    try:
        float(field)
    except ValueError:
        return False
    return True


def checked_numbers(r: Reader, fkey: str, text: str, table: np.ndarray, data: DataLines) -> np.ndarray:
    bad = np.flatnonzero(~np.all(np.isfinite(table) & (np.abs(table) <= limits.SCALE_LIMIT), axis=1))
    if bad.size:
        raise r.fail(fkey, text, f"line {data.line_of(int(bad[0]))}: {table[bad[0]].tolist()}: expected finite "
                     f"numbers within ±{limits.SCALE_LIMIT:g}")
    return table


def parse_columns(r: Reader, fkey: str, text: str, lines: list[str], limit: int):
    """The numbers of a one- or two-column CSV (comma, semicolon, tab or spaces between
    them; ``#`` comments, blank lines and one header line allowed) as an (n, c) array,
    and a function from a row to its line number in the file."""
    data = DataLines(r, fkey, text, lines, limit, None, "lines x, h (or h with spacing)")
    data_lines = data.indices
    columns = len(data.fields(lines[data_lines[0]]))
    if columns not in (1, 2):
        raise r.fail(fkey, text, f"line {data_lines[0] + 1} has {columns} columns; expected two (x, h) or one "
                     "(h, with spacing)")
    try:
        table = np.loadtxt([lines[i] for i in data_lines], delimiter=data.delimiter, comments="#", ndmin=2,
                           dtype=np.float64)
        if table.shape != (len(data_lines), columns):
            raise ValueError("shape")
    except ValueError:
        for i in data_lines:
            row = data.fields(lines[i])
            if len(row) != columns:
                raise r.fail(fkey, text, f"line {i + 1} has {len(row)} columns; expected {columns} like the "
                             "first line of numbers") from None
            bad = next((f for f in row if not is_number(f)), None)
            if bad is not None:
                raise r.fail(fkey, text, f"line {i + 1}: {shortened(bad, 40)!r} is not a number") from None
        raise r.fail(fkey, text, "cannot read the numbers; expected lines x, h (or h with spacing)") from None
    return checked_numbers(r, fkey, text, table, data), data.line_of
