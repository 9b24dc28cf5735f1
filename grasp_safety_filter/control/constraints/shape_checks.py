"""Shape checks of a family's state fields and of the stacked rows its writer fills."""

from __future__ import annotations

from typing import Any

import numpy as np


def check_rows(state_value: np.ndarray, rows: int, field: str) -> None:
    """Raise ValueError if a state array does not have ``rows`` leading entries."""
    if state_value.shape[0] != rows:
        raise ValueError(
            f"state.{field}: expected {rows} rows for this filter's joints/contacts, "
            f'got shape {state_value.shape}'
        )


def check_block(
    A: np.ndarray, lower: np.ndarray, start: int, count: int, n_joints: int, family: str
) -> None:
    """Raise ValueError unless rows ``start:start + count`` fit in ``A`` (K, m) and ``lower``.

    The compiled writers index without bounds checks: a block that does not fit would be
    written past the arrays or, read from a packed buffer, with the wrong row width.
    """
    if (
        A.ndim != 2
        or A.shape[1] != n_joints
        or lower.shape != (A.shape[0],)
        or start < 0
        or start + count > A.shape[0]
    ):
        raise ValueError(
            f'{family}: expected rows {start}:{start + count} of A (K, {n_joints}) and lower '
            f'(K,), got A {A.shape} and lower {lower.shape}'
        )


class CheckedBlock:
    """:func:`check_block` for a packed state's rows, done once for the same buffers.

    A filter writes into the same stacked ``A`` and ``lower`` from the same ``start`` on
    every tick; they (by identity) and the packed layout are checked the first time only.
    """

    __slots__ = ('_last',)

    def __init__(self) -> None:
        """Nothing checked yet."""
        self._last: tuple[Any, Any, Any, int] = (None, None, None, -1)

    def check(
        self, A: np.ndarray, lower: np.ndarray, start: int, count: int, layout: Any, family: str
    ) -> None:
        """:func:`check_block` with the layout's number of joints, unless just passed."""
        last = self._last
        if last[0] is A and last[1] is lower and last[2] is layout and last[3] == start:
            return
        check_block(A, lower, start, count, layout.n_joints, family)
        self._last = (A, lower, layout, start)
