"""The plant's stabilised rate from the model's torque-affine terms, compiled.

With the model's terms at one instant (:mod:`grasp_safety_filter.model.dynamics_kernel`:
``f_c(u) = F u + f_0``, ``ddq(u) = D u + d_0``, ``x_o_ddot(u) = X u + x_0``, ``J_h``, ``G``,
``B_ho``) and the contact velocity residual ``e = J_h dq - G^T x_o_dot`` (per contact,
contact frame, m/s), the Baumgarte-stabilised plant (:mod:`hand_sim_node.simulator`) is

    s = K_v e + K_p [0, 0, δ_i]_i,        c = B_ho^-1 s
    f_c = f_c(u) + c
    ddq = ddq(u) - M_h^-1 J_h^T c = ddq(u) - F^T s
    x_o_ddot = x_o_ddot(u) + M_o^-1 G c

(``F = B_ho^-1 J_h M_h^-1`` with ``B_ho`` and ``M_h`` symmetric, so ``M_h^-1 J_h^T c =
F^T B_ho c = F^T s``). Two compiled passes around LAPACK's solve of ``B_ho c = s``, as in
the model's kernel; the quaternion's rate is :func:`~grasp_safety_filter.model.quaternion.
quaternion_derivative`'s. Units: SI.

:func:`stabilised_rate` reads the model's terms from a GraspState (or the stage's
equivalent); :func:`sphere_on_plane_stage_rate` computes them at a Runge–Kutta stage of
spherical fingertips on flat faces by calling the model's kernels from compiled code
(numba's dispatch and boxing cost more than a kernel's arithmetic at these sizes).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.dynamics_kernel import acceleration_terms, velocity_terms
from grasp_safety_filter.model.hand_kernel import hand_in_model_order
from grasp_safety_filter.model.quaternion import quaternion_derivative
from grasp_safety_filter.model.rolling_kernels import sphere_on_plane_contacts
from grasp_safety_filter.model.wrench_solve import contact_wrench


@kernel
def baumgarte_correction(
    J_h: np.ndarray,
    G: np.ndarray,
    dq: np.ndarray,
    twist_object: np.ndarray,
    penetration: np.ndarray,
    position_gain: float,
    velocity_gain: float,
) -> np.ndarray:
    """``s = K_v e + K_p [0, 0, δ_i]_i`` with ``e = J_h dq - G^T x_o_dot``, shape (k,), m/s².

    With soft fingers (k = 4n) the last n rows, the spin rows (rad/s²), are 0: their residual
    is left as it is. A compliant spin row's residual is its creep (the model's, as MuJoCo's soft
    contacts creep), not drift; and near a grasp where an internal torsion is barely
    reachable, ``B_ho^-1`` turns a tiny spin residual into a huge torsion.

    Args:
        J_h: Hand Jacobian (k, m), k = 3n or 4n.
        G: Grasp map (6, k).
        dq: Joint velocities (m,), rad/s.
        twist_object: Object twist (6,), palm coordinates.
        penetration: Normal interpenetration per contact (n,), m.
        position_gain: ``K_p``, 1/s².
        velocity_gain: ``K_v``, 1/s.
    """
    k, m = J_h.shape
    correction = np.zeros(k)
    for r in range(3 * penetration.shape[0]):
        residual = 0.0
        for j in range(m):
            residual += J_h[r, j] * dq[j]
        for j in range(6):
            residual -= G[j, r] * twist_object[j]
        correction[r] = velocity_gain * residual
    for i in range(penetration.shape[0]):
        correction[3 * i + 2] += position_gain * penetration[i]
    return correction


@kernel
def _stabilised_rates(
    F: np.ndarray,
    f_0: np.ndarray,
    D: np.ndarray,
    d_0: np.ndarray,
    X: np.ndarray,
    x_0: np.ndarray,
    effort: np.ndarray,
    stabilisation: np.ndarray,
    correction: np.ndarray,
    M_o_inverse: np.ndarray,
    G: np.ndarray,
    dq: np.ndarray,
    twist_object: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``x_dot`` without its quaternion rate (left 0), and ``f_c``; the module's formulas."""
    k, m = F.shape
    x_dot = np.zeros(2 * m + 13)
    f_c = np.empty(k)
    for r in range(k):
        total = f_0[r]
        for j in range(m):
            total += F[r, j] * effort[j]
        f_c[r] = total + correction[r]
    for r in range(m):
        x_dot[r] = dq[r]
        total = d_0[r]
        for j in range(m):
            total += D[r, j] * effort[j]
        for j in range(k):
            total -= F[j, r] * stabilisation[j]
        x_dot[m + r] = total
    G_correction = np.empty(6)
    for r in range(6):
        total = 0.0
        for j in range(k):
            total += G[r, j] * correction[j]
        G_correction[r] = total
    for r in range(6):
        total = x_0[r]
        for j in range(m):
            total += X[r, j] * effort[j]
        for j in range(6):
            total += M_o_inverse[r, j] * G_correction[j]
        x_dot[2 * m + 7 + r] = total
    for r in range(3):
        x_dot[2 * m + r] = twist_object[r]
    return x_dot, f_c


def stabilised_rate(
    state: Any,
    effort: np.ndarray,
    quaternion_xyzw: np.ndarray,
    M_o_inverse: np.ndarray,
    position_gain: float,
    velocity_gain: float,
    torsion: bool = False,
    torsional_compliance: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """``x_dot`` and the stabilised contact forces from the model's terms at one instant.

    Args:
        state: The model's terms, read-only arrays: a
            :class:`~grasp_safety_filter.model.grasp_state.GraspState` or a
            :class:`~hand_sim_node.stage.StageTerms` (reads ``dq``, ``twist_object``,
            ``J_h``, ``G``, ``B_ho``, ``penetration`` and the affine maps ``contact_force``,
            ``joint_acceleration``, ``object_acceleration``).
        effort: Joint torque u, shape (m,), N·m.
        quaternion_xyzw: The state's orientation quaternion as integrated (possibly not
            unit inside a Runge–Kutta step).
        M_o_inverse: ``M_o^-1`` at the state, (6, 6), read-only.
        position_gain: ``K_p`` of the stabilisation, 1/s².
        velocity_gain: ``K_v`` of the stabilisation, 1/s.
        torsion: Soft-finger contacts (the model's ``soft_finger``).
        torsional_compliance: Their relative torsional compliance (the model's).

    Returns:
        ``x_dot`` (2m + 13,) with the layout of ``SimState.to_vector``, and ``f_c`` (3n, or
        4n with soft fingers), contact frames, N (torsions N·m).

    Raises:
        numpy.linalg.LinAlgError: B_ho is singular.
    """
    stabilisation = baumgarte_correction(
        state.J_h,
        state.G,
        state.dq,
        state.twist_object,
        state.penetration,
        position_gain,
        velocity_gain,
    )
    if position_gain != 0.0 or velocity_gain != 0.0:
        correction = contact_wrench(state.B_ho, stabilisation, torsion, torsional_compliance)
    else:
        correction = stabilisation  # zero
    force, joints, body = state.contact_force, state.joint_acceleration, state.object_acceleration
    x_dot, f_c = _stabilised_rates(
        force.matrix,
        force.offset,
        joints.matrix,
        joints.offset,
        body.matrix,
        body.offset,
        effort,
        stabilisation,
        correction,
        M_o_inverse,
        state.G,
        state.dq,
        state.twist_object,
    )
    m = effort.shape[0]
    x_dot[2 * m + 3 : 2 * m + 7] = quaternion_derivative(quaternion_xyzw, state.twist_object[3:])
    return x_dot, f_c


@kernel
def _sphere_on_plane_stage_system(
    frame_placements: np.ndarray,
    joint_placements: np.ndarray,
    joint_velocities: np.ndarray,
    joint_accelerations: np.ndarray,
    J_joints: np.ndarray,
    M_upper: np.ndarray,
    nle: np.ndarray,
    g: np.ndarray,
    M_inverse_pin: np.ndarray,
    frame_index: np.ndarray,
    parent_joint: np.ndarray,
    offset_in_parent: np.ndarray,
    support: np.ndarray,
    joint_index: np.ndarray,
    joint_span: np.ndarray,
    fingertip_span: np.ndarray,
    dq: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    M_o_inverse: np.ndarray,
    C_o_twist: np.ndarray,
    w_e: np.ndarray,
    plane_origin: np.ndarray,
    plane_frame: np.ndarray,
    radius: np.ndarray,
    position_gain: float,
    velocity_gain: float,
    torsion: bool,
) -> tuple[np.ndarray, ...]:
    """Run the model's hand terms, contact kinematics and first dynamics pass, then ``s``.

    Returns ``B_ho``, the right-hand sides of ``B_ho [F | f_0] = force_rhs`` and of
    ``B_ho c = s``, and what the second pass reads.
    """
    (
        p_fingertip_in_palm, R_fingertip_to_palm, J_fingertip, twist_fingertip,
        J_fingertip_dot_dq, _, M_h_inverse, h_bias, _,
    ) = hand_in_model_order(
        frame_placements, joint_placements, joint_velocities, joint_accelerations, J_joints,
        M_upper, nle, g, M_inverse_pin, frame_index, parent_joint, offset_in_parent, support,
        joint_index, dq,
    )
    contacts = sphere_on_plane_contacts(
        p_fingertip_in_palm,
        R_fingertip_to_palm,
        twist_fingertip,
        p_object_in_palm,
        R_object_to_palm,
        twist_object,
        plane_origin,
        plane_frame,
        radius,
    )
    penetration, p_contact, R_pc = contacts[3], contacts[4], contacts[5]
    H_cf, H_cf_dot_w, sliding, Omega = contacts[10], contacts[11], contacts[12], contacts[13]
    (
        J_h, G, _, _, B_ho, force_rhs, ddq, M_h_inv_J_hT, M_o_inv_G, x_ddot_free, w_c,
        w_relative,
    ) = velocity_terms(
        J_fingertip,
        twist_fingertip,
        J_fingertip_dot_dq,
        p_fingertip_in_palm,
        M_h_inverse,
        h_bias,
        p_object_in_palm,
        twist_object,
        M_o_inverse,
        C_o_twist,
        w_e,
        p_contact,
        R_pc,
        H_cf,
        H_cf_dot_w,
        sliding,
        Omega,
        joint_span,
        fingertip_span,
        torsion,
    )
    stabilisation = baumgarte_correction(
        J_h, G, dq, twist_object, penetration, position_gain, velocity_gain
    )
    return (
        B_ho, force_rhs, stabilisation, G, ddq, M_h_inv_J_hT, M_o_inv_G, x_ddot_free, w_c,
        w_relative, R_pc, H_cf, H_cf_dot_w, J_fingertip, J_fingertip_dot_dq,
    )


@kernel
def _sphere_on_plane_stage_rate(
    force: np.ndarray,
    stabilisation: np.ndarray,
    correction: np.ndarray,
    G: np.ndarray,
    ddq: np.ndarray,
    M_h_inv_J_hT: np.ndarray,
    M_o_inv_G: np.ndarray,
    x_ddot_free: np.ndarray,
    w_c: np.ndarray,
    w_relative: np.ndarray,
    J_fingertip: np.ndarray,
    J_fingertip_dot_dq: np.ndarray,
    R_contact_to_palm: np.ndarray,
    H_cf: np.ndarray,
    H_cf_dot_w: np.ndarray,
    M_o_inverse: np.ndarray,
    effort: np.ndarray,
    dq: np.ndarray,
    twist_object: np.ndarray,
    quaternion_xyzw: np.ndarray,
    joint_span: np.ndarray,
    fingertip_span: np.ndarray,
) -> np.ndarray:
    """From ``[F | f_0]`` and ``c``: the model's second pass, then the module's formulas."""
    m = ddq.shape[0]
    joints, body, _ = acceleration_terms(
        force, ddq, M_h_inv_J_hT, M_o_inv_G, x_ddot_free, w_c, w_relative,
        J_fingertip, J_fingertip_dot_dq, R_contact_to_palm, H_cf, H_cf_dot_w, joint_span,
        fingertip_span,
    )
    x_dot, _ = _stabilised_rates(
        force[:, :m], force[:, m], joints[:, :m], joints[:, m], body[:, :m], body[:, m],
        effort, stabilisation, correction, M_o_inverse, G, dq, twist_object,
    )
    x_dot[2 * m + 3 : 2 * m + 7] = quaternion_derivative(quaternion_xyzw, twist_object[3:])
    return x_dot


def sphere_on_plane_stage_rate(
    hand: Any,
    q: np.ndarray,
    surface_arrays: tuple[np.ndarray, np.ndarray, np.ndarray],
    dq: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    quaternion_xyzw: np.ndarray,
    M_o_inverse: np.ndarray,
    C_o_twist: np.ndarray,
    w_e: np.ndarray,
    effort: np.ndarray,
    position_gain: float,
    velocity_gain: float,
    torsion: bool = False,
    torsional_compliance: float = 0.0,
) -> np.ndarray:
    """``x_dot`` of spherical fingertips on flat faces, from the hand's terms at a stage.

    The kernels :meth:`GraspModel.state` runs (the contacts' closed forms, both passes of
    :func:`~grasp_safety_filter.model.contact_dynamics.contact_dynamics`) and
    :func:`stabilised_rate`'s formulas, in two compiled calls around one LAPACK solve of
    ``B_ho`` (for ``[F | f_0]``, as the model's, and for ``c``): the same arithmetic, bit
    for bit, without a Python round trip per kernel. The hand's terms are formed in the
    first call from Pinocchio's (:func:`~grasp_safety_filter.model.hand_kernel.
    hand_in_model_order`, as :meth:`HandModel.terms` forms them).

    Args:
        hand: The hand (a :class:`~grasp_safety_filter.model.hand.HandModel`).
        q: Joint angles (m,), rad.
        surface_arrays: The faces' origins, frames and the fingertip radii
            (``SphereOnPlaneStack.surface_arrays``).
        dq: Joint velocities (m,), rad/s.
        p_object_in_palm: Object centre of mass (3,), m.
        R_object_to_palm: Object orientation (3, 3).
        twist_object: Object twist (6,), palm coordinates.
        quaternion_xyzw: The orientation quaternion as integrated (4,).
        M_o_inverse: ``M_o^-1`` (6, 6), read-only.
        C_o_twist: ``C_o x_o_dot`` (6,), read-only.
        w_e: External wrench on the object (6,), read-only.
        effort: Joint torque u, shape (m,), N·m.
        position_gain: ``K_p`` of the stabilisation, 1/s².
        velocity_gain: ``K_v`` of the stabilisation, 1/s.
        torsion: Soft-finger contacts (the model's ``soft_finger``).
        torsional_compliance: Their relative torsional compliance (the model's).

    Raises:
        numpy.linalg.LinAlgError: B_ho is singular.
    """
    plane_origin, plane_frame, radius = surface_arrays
    (
        B_ho, force_rhs, stabilisation, G, ddq, M_h_inv_J_hT, M_o_inv_G, x_ddot_free, w_c,
        w_relative, R_pc, H_cf, H_cf_dot_w, J_fingertip, J_fingertip_dot_dq,
    ) = _sphere_on_plane_stage_system(
        *hand.raw_terms(q, dq),
        *hand.fingertip_frames,
        hand.pinocchio_index,
        *hand.branches,
        dq,
        p_object_in_palm,
        R_object_to_palm,
        twist_object,
        M_o_inverse,
        C_o_twist,
        w_e,
        plane_origin,
        plane_frame,
        radius,
        position_gain,
        velocity_gain,
        torsion,
    )
    # Two solves, not one of [force_rhs | s]: LAPACK's bits depend on the number of columns.
    force = contact_wrench(B_ho, force_rhs, torsion, torsional_compliance)
    correction = contact_wrench(B_ho, stabilisation, torsion, torsional_compliance)
    x_dot = _sphere_on_plane_stage_rate(
        force, stabilisation, correction, G, ddq, M_h_inv_J_hT, M_o_inv_G, x_ddot_free, w_c,
        w_relative, J_fingertip, J_fingertip_dot_dq, R_pc, H_cf, H_cf_dot_w, M_o_inverse,
        effort, dq, twist_object, quaternion_xyzw, *hand.branches,
    )
    return x_dot
