"""Shared check for the benchmark CSV outputs."""
import csv

import numpy as np


def assert_positive_table(path, columns, n_rows: int, names) -> None:
    """The CSV at `path` has the header `columns`, `n_rows` rows, and finite positive `names` columns."""
    with open(path) as f:
        table = list(csv.reader(f))
    assert tuple(table[0]) == tuple(columns) and len(table) == 1 + n_rows
    for line in table[1:]:
        record = dict(zip(table[0], line))
        for name in names:
            assert np.isfinite(float(record[name])) and float(record[name]) > 0, (name, record)
