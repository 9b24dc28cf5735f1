"""An anisotropic object's per-tick dynamic terms in one compiled pass, numpy's to the bit.

:class:`~grasp_safety_filter.model.rigid_object.RigidObject`'s ``M_o``, ``M_o^-1`` and
``C_o x_o_dot`` of a body whose inertia is not isotropic (a box) are each a few 3 × 3
products, some 14 µs of numpy calls a tick together. :func:`object_dynamics` makes the same
BLAS calls as numpy's ``@`` (:mod:`~grasp_safety_filter.model.fortran_linalg`) in one call.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.fortran_linalg import dgemm, matrix_matrix, matrix_vector


@kernel
def _rotated(R: np.ndarray, inertia: np.ndarray, out: np.ndarray) -> None:
    """Write numpy's ``R @ inertia @ R.T`` (3, 3) into ``out[3:, 3:]``."""
    left = np.empty((3, 3))
    matrix_matrix(R, inertia, left)
    rotated = np.empty((3, 3))
    # numpy's left @ R.T: R.T is R's buffer transposed, so BLAS gets 'T' on it.
    dgemm(ord('T'), ord('N'), 3, 3, 3, 1.0, R, 0, 3, left, 0, 3, 0.0, rotated, 0, 3)
    out[3:, 3:] = rotated


@kernel
def object_dynamics(
    mass: float,
    inertia: tuple[np.ndarray, np.ndarray],
    R: np.ndarray,
    twist: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(M_o, M_o^-1, C_o x_o_dot)`` as :class:`RigidObject`'s methods compute them.

    Args:
        mass: kg.
        inertia: ``(I_body, I_body^-1)``, (3, 3) each, C order.
        R: ``R_object_to_palm``, (3, 3), C order.
        twist: ``(v_o, w_o)``, (6,).
    """
    inertia_in_body, inverse_in_body = inertia
    M_o = np.zeros((6, 6))
    M_o_inverse = np.zeros((6, 6))
    inverse_mass = 1.0 / mass
    for i in range(3):
        M_o[i, i] = mass * 1.0
        M_o_inverse[i, i] = inverse_mass * 1.0
    _rotated(R, inertia_in_body, M_o)
    _rotated(R, inverse_in_body, M_o_inverse)
    w = twist[3:].copy()
    in_body = np.empty(3)
    matrix_vector(3, 3, R.reshape(-1), 0, 1, 3, w, in_body)  # R.T @ w
    momentum_in_body = np.empty(3)
    matrix_vector(3, 3, inertia_in_body.reshape(-1), 0, 3, 1, in_body, momentum_in_body)
    Iw = np.empty(3)
    matrix_vector(3, 3, R.reshape(-1), 0, 3, 1, momentum_in_body, Iw)
    bias = np.zeros(6)
    bias[3] = w[1] * Iw[2] - w[2] * Iw[1]
    bias[4] = w[2] * Iw[0] - w[0] * Iw[2]
    bias[5] = w[0] * Iw[1] - w[1] * Iw[0]
    return M_o, M_o_inverse, bias
