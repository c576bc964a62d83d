"""CSV tables (contact.csv, path.csv): every float reads back to itself, integers stay integers."""

import csv
import io

import numpy as np

from contactfem.io.table import csv_table


def read(text: str) -> tuple[list[str], list[list[str]]]:
    rows = list(csv.reader(io.StringIO(text)))
    return rows[0], rows[1:]


def test_every_float_reads_back_exactly_and_integers_stay_integers():
    rng = np.random.default_rng(7)
    edge = np.array([0.0, -0.0, 5e-324, -2.2250738585072014e-308, 1.7976931348623157e308, 0.1, 1.0 / 3.0,
                     2.0**53 + 2.0, 1e16, 1e-5, np.inf, -np.inf])
    values = np.concatenate([edge, rng.standard_normal(5000) * 10.0 ** rng.integers(-30, 30, 5000)])
    active = (rng.random(len(values)) > 0.5).astype(int)
    header, rows = read(csv_table({"value": values, "active": active}))
    assert header == ["value", "active"]
    assert len(rows) == len(values)
    back = np.array([float(row[0]) for row in rows])
    assert np.array_equal(back, values)
    assert np.array_equal(np.signbit(back), np.signbit(values))  # -0.0 stays negative
    assert [row[1] for row in rows] == [str(a) for a in active]
    # The shortest decimal that reads back: what repr writes, not 17 digits.
    assert rows[5][0] == "0.1" and rows[6][0] == repr(1.0 / 3.0)


def test_lists_may_mix_integers_and_floats_per_value():
    text = csv_table({"factor": [0.25, 1.0], "iterations": [3, np.int64(2)], "mixed": [1, np.float64(2.5)]})
    assert text == "factor,iterations,mixed\n0.25,3,1\n1.0,2,2.5\n"


def test_a_table_without_rows_is_its_header():
    assert csv_table({"a": np.zeros(0), "b": []}) == "a,b\n"
