"""A result table's CSV text without pandas: per-episode rows as ``crowdnav evaluate`` and the experiments write them."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np


def _cell(value: Any) -> str:
    """A CSV cell as pandas writes it (``nan`` for missing numbers; floats at full precision)."""
    if isinstance(value, (bool, np.bool_)):
        return str(bool(value))
    if isinstance(value, (int, np.integer)):
        return str(int(value))
    if isinstance(value, (float, np.floating)):
        return "nan" if value != value else repr(float(value))
    return "" if value is None else str(value)


def episode_csv(rows: Sequence[Mapping[str, Any]]) -> str:
    """Per-episode rows (dicts with the same keys, in order) as the result table's CSV text, without pandas."""
    import csv
    import io

    buffer = io.StringIO()
    writer = csv.writer(buffer, lineterminator="\n")
    columns = list(rows[0]) if rows else []
    writer.writerow(columns)
    writer.writerows([_cell(row[column]) for column in columns] for row in rows)
    return buffer.getvalue()
