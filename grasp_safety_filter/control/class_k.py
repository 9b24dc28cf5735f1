"""Extended class-K functions: the decay rates alpha_1, alpha_2 of the zeroing barriers.

An extended class-K function is continuous, strictly increasing and zero at zero (paper,
Definition 1). Two are offered, both with a gain k > 0::

    cubic:   alpha(h) = k h^3     alpha'(h) = 3 k h^2     (the paper's choice, with k = 1)
    linear:  alpha(h) = k h       alpha'(h) = k

The cubic one is gentle far from the boundary (small for |h| < 1) and lets the state
approach the boundary quickly; the linear one gives exponential approach at rate k.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

#: Names of the available extended class-K functions.
CLASS_K_KINDS: tuple[str, ...] = ('cubic', 'linear')


@dataclass(frozen=True)
class ClassKFunction:
    """An extended class-K function ``alpha(h)`` with its derivative, vectorised over h.

    Attributes:
        kind: ``"cubic"`` (``alpha(h) = k h^3``) or ``"linear"`` (``alpha(h) = k h``).
        gain: The gain k > 0 (units make ``alpha(h)`` have the units of ``h_dot``, or of
            ``B_dot`` for alpha_2).
    """

    kind: str = 'cubic'
    gain: float = 1.0

    def __post_init__(self) -> None:
        if self.kind not in CLASS_K_KINDS:
            raise ValueError(
                f"class-K function 'kind': expected one of {list(CLASS_K_KINDS)}, "
                f'got {self.kind!r}'
            )
        gain = self.gain
        if isinstance(gain, bool) or not isinstance(gain, int | float):
            raise ValueError(f"class-K function 'gain': expected a number, got {gain!r}")
        if not (math.isfinite(gain) and gain > 0.0):
            raise ValueError(
                f"class-K function 'gain': expected a finite number > 0, got {gain!r}"
            )
        object.__setattr__(self, 'gain', float(gain))
        # Bound once: the barrier rows call these every control tick.
        object.__setattr__(self, '_cubic', self.kind == 'cubic')

    def value(self, h: np.ndarray) -> np.ndarray:
        """``alpha(h)``: ``k h^3`` (cubic) or ``k h`` (linear), elementwise."""
        if self._cubic:
            return self.gain * h * h * h
        return self.gain * h

    def derivative(self, h: np.ndarray) -> np.ndarray:
        """``alpha'(h)``: ``3 k h^2`` (cubic) or ``k`` (linear, broadcast to h's shape)."""
        if self._cubic:
            return (3.0 * self.gain) * h * h
        return np.full(np.shape(h), self.gain)

    def __call__(self, h: np.ndarray) -> np.ndarray:
        """Evaluate ``alpha(h)`` (same as :meth:`value`)."""
        return self.value(h)
