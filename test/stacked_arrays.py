"""Stacked numpy helpers of the oracles (tests only): batched products, cross-product matrices."""

from __future__ import annotations

import numpy as np


def matvec(A: np.ndarray, x: np.ndarray) -> np.ndarray:
    """``A[k] @ x[k]`` for stacked matrices (k, r, c) and vectors (k, c) (a batched matmul)."""
    return (A @ x[..., None])[..., 0]


# skew(v)_ij = -eps_ijk v_k: the Levi-Civita tensor as a (9, 3) matrix builds stacked skew
# matrices in one matmul.
_LEVI_CIVITA = np.zeros((3, 3, 3))
_LEVI_CIVITA[0, 1, 2] = _LEVI_CIVITA[1, 2, 0] = _LEVI_CIVITA[2, 0, 1] = 1.0
_LEVI_CIVITA[0, 2, 1] = _LEVI_CIVITA[2, 1, 0] = _LEVI_CIVITA[1, 0, 2] = -1.0
_SKEW_FROM_VECTOR = -_LEVI_CIVITA.reshape(9, 3)


def skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``v× = [[0, -v_z, v_y], [v_z, 0, -v_x], [-v_y, v_x, 0]]``.

    A vector (3,) gives (3, 3); stacked vectors (k, 3) give (k, 3, 3).
    """
    return (v @ _SKEW_FROM_VECTOR.T).reshape(*v.shape[:-1], 3, 3)


def cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Row-wise cross products ``a × b`` of vectors (3,) or stacked (k, 3), broadcast.

    Written as ``(a×) b``: np.cross costs ~20 µs of axis handling per call here.
    """
    return matvec(skew(a), b)
