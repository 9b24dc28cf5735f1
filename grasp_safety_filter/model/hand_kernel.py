"""Pinocchio's raw hand terms in the model's joint order, compiled.

Pinocchio gives the fingertip placements, frame Jacobians, M (upper triangle only),
``C dq + g``, g and M^-1 in its own joint order; the model orders joints as its
``joint_names``. This one gather (copies, no arithmetic) serves the staged hand terms
(:meth:`~grasp_safety_filter.model.hand.HandModel.terms`) and the one-pass grasp terms
(:func:`~grasp_safety_filter.model.packed_terms.sphere_on_plane_terms`).
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def hand_in_model_order(
    placements: np.ndarray,
    J_frames: np.ndarray,
    M_upper: np.ndarray,
    nle: np.ndarray,
    g: np.ndarray,
    M_inverse_pin: np.ndarray,
    joint_index: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Return the hand's terms in the model's joint order.

    Args:
        placements: Fingertip frame placements, homogeneous, (n, 4, 4), m.
        J_frames: Fingertip frame Jacobians (LOCAL_WORLD_ALIGNED, Pinocchio's order), (n, 6, nv).
        M_upper: M_h, upper triangle (Pinocchio's order), (nv, nv), kg·m².
        nle: ``C_h dq + g`` (Pinocchio's order), (nv,), N·m.
        g: ``g(q)`` (Pinocchio's order), (nv,), N·m.
        M_inverse_pin: ``M_h^-1`` (Pinocchio's order), (nv, nv).
        joint_index: Pinocchio's index of each of the model's joints, (m,).

    Returns:
        ``p_fingertip_in_palm`` (n, 3), ``R_fingertip_to_palm`` (n, 3, 3), ``J_fingertip``
        (n, 6, m), ``M_h`` (m, m, both triangles), ``M_h_inverse`` (m, m), ``h_bias`` (m,)
        and ``gravity_torque`` (m,).
    """
    n = J_frames.shape[0]
    m = joint_index.shape[0]
    p_f = np.empty((n, 3))
    R_f = np.empty((n, 3, 3))
    J_s = np.empty((n, 6, m))
    for i in range(n):
        for r in range(3):
            p_f[i, r] = placements[i, r, 3]
            for c in range(3):
                R_f[i, r, c] = placements[i, r, c]
        for r in range(6):
            for j in range(m):
                J_s[i, r, j] = J_frames[i, r, joint_index[j]]
    M_h = np.empty((m, m))
    M_h_inverse = np.empty((m, m))
    h_bias = np.empty(m)
    gravity = np.empty(m)
    for r in range(m):
        a = joint_index[r]
        h_bias[r] = nle[a]
        gravity[r] = g[a]
        for c in range(m):
            b = joint_index[c]
            # Pinocchio fills the upper triangle of M only.
            M_h[r, c] = M_upper[a, b] if a <= b else M_upper[b, a]
            M_h_inverse[r, c] = M_inverse_pin[a, b]
    return p_f, R_f, J_s, M_h, M_h_inverse, h_bias, gravity
