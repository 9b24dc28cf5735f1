"""Barrier values per row name, read like a dict without building one every tick."""

from __future__ import annotations

from collections.abc import ItemsView, Iterator, Mapping, ValuesView

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
