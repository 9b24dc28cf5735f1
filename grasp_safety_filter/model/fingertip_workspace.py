"""The fingertip workspace: the box of admissible fingertip contact coordinates (a, b).

Per contact, ``a_min <= a <= a_max`` and ``b_min <= b <= b_max`` (rad) in the fingertip
sphere's chart ``c(a, b) = R (-cos a cos b, sin a, -cos a sin b)``; the chart is singular at
``a = ±pi/2``, so ``a`` is bounded inside ``[-pi/2, pi/2]``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grasp_safety_filter.errors import ConfigError


class GraspConfigError(ConfigError):
    """The configuration does not describe a valid grasp (names the parameter and the values)."""


@dataclass(frozen=True)
class FingertipWorkspace:
    """Admissible fingertip coordinates ``a_min ≤ a ≤ a_max, b_min ≤ b ≤ b_max``, rad."""

    a_min: float
    a_max: float
    b_min: float
    b_max: float

    def __post_init__(self) -> None:
        if not -np.pi / 2 <= self.a_min < self.a_max <= np.pi / 2:
            raise GraspConfigError(
                'model.fingertip_workspace: expected -pi/2 <= a_min < a_max <= pi/2, got '
                f'a_min={self.a_min}, a_max={self.a_max}'
            )
        if not self.b_min < self.b_max:
            raise GraspConfigError(
                'model.fingertip_workspace: expected b_min < b_max, got '
                f'b_min={self.b_min}, b_max={self.b_max}'
            )

    def __iter__(self):  # noqa: ANN204 - tuple-like unpacking: a_min, a_max, b_min, b_max
        return iter((self.a_min, self.a_max, self.b_min, self.b_max))

    def margins(self, xi_cf: np.ndarray) -> np.ndarray:
        """Barrier values ``(a - a_min, a_max - a, b - b_min, b_max - b)`` per contact, (n, 4)."""
        xi = np.atleast_2d(xi_cf)
        a, b = xi[:, 0], xi[:, 1]
        return np.column_stack([a - self.a_min, self.a_max - a, b - self.b_min, self.b_max - b])
