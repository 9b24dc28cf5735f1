"""A campaign sample's random draws: the distributions of ``random`` and the random reference.

Each draw reads the sample's own generator (``numpy.random.default_rng([seed, sample])``), in
the campaign file's order, so that a sample's values depend on nothing else.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import math
from typing import Any

import numpy as np

#: The reference's axes, in the order of ``reference.amplitude``.
AXES = ('x', 'y', 'z', 'roll', 'pitch', 'yaw')
#: The distributions of a campaign's ``random`` section.
DISTRIBUTIONS = ('uniform', 'log_uniform', 'choice', 'scale')


def draw_value(rng: np.random.Generator, kind: str, arguments: Sequence[Any]) -> Any:
    """Draw a value; for ``scale`` the factor that multiplies the scenario's own value."""
    if kind == 'choice':
        return arguments[int(rng.integers(len(arguments)))]
    lo, hi = arguments
    if kind == 'log_uniform':
        return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))
    return float(rng.uniform(lo, hi))


def draw_reference(
    rng: np.random.Generator, reference: Mapping[str, Any]
) -> tuple[list[float], float]:
    """Draw an amplitude A (per axis: a magnitude in its range and a sign) and a frequency w."""
    amplitude = [0.0] * len(AXES)
    for axis in reference['axes']:
        index = AXES.index(axis)
        lo, hi = reference['position' if index < 3 else 'orientation']
        amplitude[index] = float(rng.choice((-1.0, 1.0)) * rng.uniform(lo, hi))
    return amplitude, float(rng.uniform(*reference['frequency']))
