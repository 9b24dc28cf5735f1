"""Pinocchio's raw hand terms as the model needs them, compiled.

After ``computeAllTerms`` and ``updateFramePlacements``, Pinocchio's data holds every joint's
placement, velocity and acceleration (ddq = 0), the joint Jacobian in the world frame, M
(upper triangle only), ``C dq + g`` and g, in its own joint order; the model orders joints
as its ``joint_names``. :func:`hand_in_model_order` forms the fingertip frames' terms from
them (the formulas of Pinocchio's ``getFrameJacobian`` and ``getFrameClassicalAcceleration``
in LOCAL_WORLD_ALIGNED, the same operations in the same order: the frame Jacobians are those
calls' bits; the accelerations agree to rounding, as Pinocchio's compiled code may fuse a
multiply-add) and gathers everything into the model's joint order. One implementation
serves the hand's terms (:meth:`~grasp_safety_filter.model.hand.HandModel.terms`) and the
one-pass grasp terms (:mod:`~grasp_safety_filter.model.packed_terms`).

Placements are rows of 12: the rotation's 9 entries column by column, then the translation
(Pinocchio's ``SE3`` in memory); motions are rows of 6, ``(linear, angular)``.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def _rotate(placement: np.ndarray, x0: float, x1: float, x2: float, out: np.ndarray) -> None:
    """``out = R x`` with R the rotation of a placement row (Eigen's 3x3 product order)."""
    for r in range(3):
        out[r] = placement[r] * x0 + placement[r + 3] * x1 + placement[r + 6] * x2


@kernel
def _frame_classical_acceleration(
    joint_placement: np.ndarray,
    v_joint: np.ndarray,
    a_joint: np.ndarray,
    offset: np.ndarray,
    out: np.ndarray,
) -> None:
    """Write a frame's classical acceleration at ddq = 0, LOCAL_WORLD_ALIGNED, into ``out``.

    Pinocchio's ``getFrameClassicalAcceleration``: with the parent joint's velocity v and
    acceleration a in its own frame, its rotation R_i and the frame's offset t in it,
    ``v_f = (R_i (v_lin + v_ang × t), R_i v_ang)``, ``a_f = (R_i (a_lin + a_ang × t),
    R_i a_ang)`` and the classical acceleration is ``(a_f_lin + v_f_ang × v_f_lin, a_f_ang)``.
    """
    t0, t1, t2 = offset[0], offset[1], offset[2]
    v_lin = np.empty(3)
    v_ang = np.empty(3)
    a_lin = np.empty(3)
    _rotate(
        joint_placement,
        v_joint[0] + (v_joint[4] * t2 - v_joint[5] * t1),
        v_joint[1] + (v_joint[5] * t0 - v_joint[3] * t2),
        v_joint[2] + (v_joint[3] * t1 - v_joint[4] * t0),
        v_lin,
    )
    _rotate(joint_placement, v_joint[3], v_joint[4], v_joint[5], v_ang)
    _rotate(
        joint_placement,
        a_joint[0] + (a_joint[4] * t2 - a_joint[5] * t1),
        a_joint[1] + (a_joint[5] * t0 - a_joint[3] * t2),
        a_joint[2] + (a_joint[3] * t1 - a_joint[4] * t0),
        a_lin,
    )
    _rotate(joint_placement, a_joint[3], a_joint[4], a_joint[5], out[3:])
    out[0] = a_lin[0] + (v_ang[1] * v_lin[2] - v_ang[2] * v_lin[1])
    out[1] = a_lin[1] + (v_ang[2] * v_lin[0] - v_ang[0] * v_lin[2])
    out[2] = a_lin[2] + (v_ang[0] * v_lin[1] - v_ang[1] * v_lin[0])


@kernel
def hand_in_model_order(
    raw: tuple[np.ndarray, ...],
    frames: tuple[np.ndarray, ...],
    joint_index: np.ndarray,
    dq: np.ndarray,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
    np.ndarray, np.ndarray, np.ndarray, np.ndarray,
]:
    """Return the hand's terms in the model's joint order.

    Args:
        raw: Pinocchio's terms at ``(q, dq)`` in its joint order
            (:class:`~grasp_safety_filter.model.hand.RawHandTerms`).
        frames: Where the fingertip frames hang in Pinocchio's model
            (:class:`~grasp_safety_filter.model.hand.FingertipFrames`).
        joint_index: Pinocchio's index of each of the model's joints, (m,).
        dq: Joint velocities (the model's order), (m,), rad/s.

    Returns:
        ``p_fingertip_in_palm`` (n, 3), ``R_fingertip_to_palm`` (n, 3, 3), ``J_fingertip``
        (n, 6, m): ``J_lin = J_world_lin - p_f × J_world_ang`` on the supporting columns
        (``getFrameJacobian``), zero elsewhere; ``twist_fingertip = J_fingertip dq`` (n, 6)
        (BLAS, as numpy's product), ``J_fingertip_dot_dq`` (n, 6), ``M_h`` (m, m, both
        triangles), ``M_h_inverse`` (m, m), ``h_bias`` (m,) and ``gravity_torque`` (m,).
    """
    (
        frame_placements, joint_placements, joint_velocities, joint_accelerations, J_joints,
        M_upper, nle, g, M_inverse_pin,
    ) = raw
    frame_index, parent_joint, offset_in_parent, support = frames
    n = frame_index.shape[0]
    m = joint_index.shape[0]
    p_f = np.empty((n, 3))
    R_f = np.empty((n, 3, 3))
    J_s = np.zeros((n, 6, m))
    twist_f = np.empty((n, 6))
    J_dot_dq = np.empty((n, 6))
    for i in range(n):
        placement = frame_placements[frame_index[i]]
        for r in range(3):
            p_f[i, r] = placement[9 + r]
            for c in range(3):
                R_f[i, r, c] = placement[r + 3 * c]
        t0, t1, t2 = p_f[i, 0], p_f[i, 1], p_f[i, 2]
        for j in range(m):
            k = joint_index[j]
            if support[i, k]:
                w0, w1, w2 = J_joints[3, k], J_joints[4, k], J_joints[5, k]
                J_s[i, 0, j] = J_joints[0, k] - (t1 * w2 - t2 * w1)
                J_s[i, 1, j] = J_joints[1, k] - (t2 * w0 - t0 * w2)
                J_s[i, 2, j] = J_joints[2, k] - (t0 * w1 - t1 * w0)
                J_s[i, 3, j] = w0
                J_s[i, 4, j] = w1
                J_s[i, 5, j] = w2
        twist_f[i] = np.dot(J_s[i], dq)
        parent = parent_joint[i]
        _frame_classical_acceleration(
            joint_placements[parent],
            joint_velocities[parent],
            joint_accelerations[parent],
            offset_in_parent[i],
            J_dot_dq[i],
        )
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
    return p_f, R_f, J_s, twist_f, J_dot_dq, M_h, M_h_inverse, h_bias, gravity
