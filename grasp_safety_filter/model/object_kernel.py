"""The object's per-tick dynamic terms, compiled: ``M_o``, ``M_o^-1`` and ``C_o x_o_dot``.

In palm coordinates, with ``R = R_object_to_palm`` and the body-frame inertia ``I_body``:

    M_o = blkdiag(m I3, R I_body R^T),     M_o^-1 = blkdiag(I3 / m, R I_body^-1 R^T)
    C_o x_o_dot = (0, w × (R I_body R^T w))

An isotropic inertia ``c I3`` (the cube's, the sphere's) is the same in every frame and has
no gyroscopic torque: the terms are then the body-frame constants. One implementation
serves :class:`~grasp_safety_filter.model.rigid_object.RigidObject` and the one-pass grasp
terms (:mod:`~grasp_safety_filter.model.packed_terms`). Units: kg,
kg·m², N·m.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def _rotate_into(R: np.ndarray, inertia: np.ndarray, out: np.ndarray) -> None:
    """Write ``R @ inertia @ R^T`` (3, 3) into ``out[3:, 3:]``."""
    for i in range(3):
        for j in range(3):
            total = 0.0
            for k in range(3):
                for m in range(3):
                    total += R[i, k] * inertia[k, m] * R[j, m]
            out[3 + i, 3 + j] = total


@kernel
def object_dynamics(
    M_o_in_body: np.ndarray, isotropic: bool, R: np.ndarray, twist: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(M_o, M_o^-1, C_o x_o_dot)`` in palm coordinates, (6, 6), (6, 6), (6,).

    Args:
        M_o_in_body: ``blkdiag(m I3, I_body)`` and ``blkdiag(I3 / m, I_body^-1)``, (2, 6, 6)
            (:attr:`~grasp_safety_filter.model.rigid_object.RigidObject.mass_matrices_in_body`).
        isotropic: Whether ``I_body`` is isotropic (then the body-frame matrices and a zero
            bias are returned, as copies).
        R: ``R_object_to_palm``, (3, 3).
        twist: ``(v_o, w_o)``, (6,), palm coordinates (m/s, rad/s).
    """
    M_o = M_o_in_body[0].copy()
    M_o_inverse = M_o_in_body[1].copy()
    bias = np.zeros(6)
    if isotropic:
        return M_o, M_o_inverse, bias
    _rotate_into(R, M_o_in_body[0, 3:, 3:], M_o)
    _rotate_into(R, M_o_in_body[1, 3:, 3:], M_o_inverse)
    w = twist[3:]
    Iw = np.zeros(3)
    for i in range(3):
        for j in range(3):
            Iw[i] += M_o[3 + i, 3 + j] * w[j]
    bias[3] = w[1] * Iw[2] - w[2] * Iw[1]
    bias[4] = w[2] * Iw[0] - w[0] * Iw[2]
    bias[5] = w[0] * Iw[1] - w[1] * Iw[0]
    return M_o, M_o_inverse, bias
