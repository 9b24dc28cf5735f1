"""Barrier values per row name, read like a dict without building one every tick.

:class:`RowValues` holds what a filter step needs to give its margins and active rows,
and computes them only when they are read.
"""

from __future__ import annotations

from collections.abc import Callable, ItemsView, Iterator, Mapping, ValuesView

import numpy as np


class Margins(Mapping[str, float]):
    """Barrier value h per row name: a read-only mapping over a names tuple and a values array.

    Reads like the ``dict`` it stands for (``margins[name]``, iteration in row order,
    ``items()``, ``values()``, ``dict(margins)``, equality with a dict) without building
    one entry per row every tick. :attr:`names` and :attr:`array` give the rows in order.
    """

    __slots__ = ('_array', '_index', '_names')

    def __init__(
        self, names: tuple[str, ...], array: np.ndarray, index: Mapping[str, int] | None = None
    ) -> None:
        """Wrap ``array`` (shape (len(names),), made read-only) under ``names``.

        Args:
            names: Row names, distinct, in row order.
            array: The values, one per name.
            index: Position of each name (shared between views of the same rows); built
                from ``names`` when None.

        Raises:
            ValueError: ``array`` does not have one value per name.
        """
        if array.shape != (len(names),):
            raise ValueError(
                f'margins: expected {len(names)} values, got an array of shape {array.shape}'
            )
        array.setflags(write=False)
        self._names = names
        self._array = array
        self._index = index if index is not None else {n: i for i, n in enumerate(names)}

    @property
    def names(self) -> tuple[str, ...]:
        """Row names, in row order."""
        return self._names

    @property
    def array(self) -> np.ndarray:
        """The values in row order, shape (len(names),) (read-only)."""
        return self._array

    def __getitem__(self, name: str) -> float:
        return float(self._array[self._index[name]])

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def __iter__(self) -> Iterator[str]:
        return iter(self._names)

    def __len__(self) -> int:
        return len(self._names)

    def items(self) -> ItemsView[str, float]:
        """Return the ``(name, h)`` pairs in row order."""
        return _MarginItems(self)

    def values(self) -> ValuesView[float]:
        """Return the values h in row order."""
        return _MarginValues(self)

    def __repr__(self) -> str:
        return f'{type(self).__name__}({dict(self.items())!r})'


class _MarginItems(ItemsView[str, float]):
    """``Margins.items()``, iterated without one lookup per row."""

    _mapping: Margins

    def __iter__(self) -> Iterator[tuple[str, float]]:
        return zip(self._mapping.names, self._mapping.array.tolist(), strict=True)


class _MarginValues(ValuesView[float]):
    """``Margins.values()``, iterated without one lookup per row."""

    _mapping: Margins

    def __iter__(self) -> Iterator[float]:
        return iter(self._mapping.array.tolist())


class RowValues:
    """One tick's margins and active rows at u*, computed on first read, then kept.

    Holds the row residuals ``A u* - lower`` (already computed by the step) and two
    writers: one of every barrier value h (families then actuator box), one of the box
    margins alone. Nothing is evaluated until :attr:`margins` or :attr:`active` is read.
    """

    __slots__ = (
        '_active',
        '_index',
        '_margins',
        '_n_rows',
        '_names',
        '_slack',
        '_tolerance',
        '_write_box',
        '_write_margins',
    )

    def __init__(
        self,
        names: tuple[str, ...],
        index: Mapping[str, int],
        n_rows: int,
        slack: np.ndarray,
        write_margins: Callable[[np.ndarray], None],
        write_box: Callable[[np.ndarray], None],
        tolerance: float,
    ) -> None:
        """Keep the step's residuals and the writers.

        Args:
            names: Row names: the barrier rows, then the actuator box's.
            index: Position of each name.
            n_rows: The number of barrier rows (before the box's).
            slack: Shape (len(names),): the barrier rows' residuals ``A u* - lower`` first;
                the box entries are written here when :attr:`active` is first read.
            write_margins: Writes every row's h at u* into an array of shape (len(names),).
            write_box: Writes the box margins at u* into an array of their shape.
            tolerance: A row is active when its residual (box: margin) is at most this.
        """
        self._names = names
        self._index = index
        self._n_rows = n_rows
        self._slack = slack
        self._write_margins = write_margins
        self._write_box = write_box
        self._tolerance = tolerance
        self._margins: Margins | None = None
        self._active: tuple[str, ...] | None = None

    @property
    def margins(self) -> Margins:
        """Barrier value h per row name at u* (computed on the first read)."""
        if self._margins is None:
            values = np.empty(len(self._names))
            self._write_margins(values)
            self._margins = Margins(self._names, values, self._index)
        return self._margins

    @property
    def active(self) -> tuple[str, ...]:
        """Names of the rows whose residual or box margin is at most the tolerance."""
        if self._active is None:
            slack = self._slack
            self._write_box(slack[self._n_rows :])
            picked = np.flatnonzero(slack <= self._tolerance).tolist()
            self._active = tuple([self._names[i] for i in picked])
        return self._active
