"""Affine maps ``u ↦ matrix @ u + offset``: how every grasp quantity depends on the torque."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class AffineMap:
    """An affine function of the joint torque, ``y(u) = matrix @ u + offset``.

    Attributes:
        matrix: Shape (k, m): sensitivity of y to the joint torque u (m joints).
        offset: Shape (k,): value of y at u = 0.
    """

    matrix: np.ndarray
    offset: np.ndarray

    def __post_init__(self) -> None:
        if self.matrix.ndim != 2 or self.offset.shape != (self.matrix.shape[0],):
            raise ValueError(
                f'AffineMap: expected matrix (k, m) and offset (k,), got {self.matrix.shape} '
                f'and {self.offset.shape}'
            )

    def __call__(self, u: np.ndarray) -> np.ndarray:
        """Evaluate at the joint torque ``u`` (shape (m,))."""
        return self.matrix @ u + self.offset

    def rows(self, index: np.ndarray | slice | list[int]) -> AffineMap:
        """Return the affine map of a subset of the outputs."""
        return AffineMap(self.matrix[index], self.offset[index])
