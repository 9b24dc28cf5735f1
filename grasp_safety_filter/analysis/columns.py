"""Growing numeric columns: a run's per-tick numbers kept as packed arrays while a bag streams.

A Python object per message (or a list of small arrays) costs kilobytes per tick; a packed
float64 row costs 8 bytes per number. :class:`Column` grows by doubling, so appending is
amortised O(1) and the memory held is at most twice the rows'.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: Rows allocated at first.
INITIAL_ROWS = 1024


class Column:
    """Rows of one shape and dtype, appended one at a time.

    Args:
        shape: Shape of one row, e.g. ``()`` for a scalar per tick, ``(9,)``, ``(3, 2)``.
        dtype: NumPy dtype of the values.

    """

    def __init__(self, shape: tuple[int, ...] = (), dtype: Any = np.float64) -> None:
        self.shape = tuple(shape)
        self._data = np.empty((INITIAL_ROWS, *self.shape), dtype=dtype)
        self._size = 0

    @classmethod
    def of(cls, rows: np.ndarray) -> Column:
        """Return a column holding ``rows`` (shape ``(rows, *shape)``; not copied)."""
        column = cls.__new__(cls)
        column.shape = tuple(rows.shape[1:])
        column._data, column._size = rows, len(rows)
        return column

    def __len__(self) -> int:
        """Return the number of rows appended."""
        return self._size

    def append(self, row: Any) -> None:
        """Append one row (anything NumPy converts to the row shape).

        Raises:
            ValueError: ``row`` has another shape.

        """
        if self._size == len(self._data):
            rows = max(2 * len(self._data), INITIAL_ROWS)
            grown = np.empty((rows, *self.shape), dtype=self._data.dtype)
            grown[: self._size] = self._data
            self._data = grown
        self._data[self._size] = row
        self._size += 1

    def array(self) -> np.ndarray:
        """Return the rows, shape ``(rows, *shape)``: a view, not a copy (no second buffer)."""
        return self._data[: self._size]

    def __repr__(self) -> str:
        """Describe the column by its size and row shape."""
        return f'Column({self._size} rows of shape {self.shape}, {self._data.dtype})'
