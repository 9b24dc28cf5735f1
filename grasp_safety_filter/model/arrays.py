"""Small numpy helpers shared by the model modules."""

from __future__ import annotations

import numpy as np


def read_only(array: np.ndarray) -> np.ndarray:
    """Make ``array`` read-only in place and return it (for arrays shared or handed out)."""
    array.setflags(write=False)
    return array
