"""The grasp's contact dynamics at one instant: the compiled passes around LAPACK's solve.

The formulas, and what each term means, are those of
:mod:`~grasp_safety_filter.model.dynamics_kernel`; this is the call for Python callers (the
staged grasp state, the simulator's general stage).
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.dynamics_kernel import acceleration_terms, velocity_terms
from grasp_safety_filter.model.wrench_solve import contact_wrench


def contact_dynamics(
    J_fingertip: np.ndarray,
    twist_fingertip: np.ndarray,
    J_fingertip_dot_dq: np.ndarray,
    p_fingertip_in_palm: np.ndarray,
    M_h_inverse: np.ndarray,
    h_bias: np.ndarray,
    p_object_in_palm: np.ndarray,
    twist_object: np.ndarray,
    M_o_inverse: np.ndarray,
    C_o_twist: np.ndarray,
    w_e: np.ndarray,
    p_contact_in_palm: np.ndarray,
    R_contact_to_palm: np.ndarray,
    H_cf: np.ndarray,
    H_cf_dot_w: np.ndarray,
    sliding_velocity: np.ndarray,
    frame_angular_velocity: np.ndarray,
    joint_span: np.ndarray,
    fingertip_span: np.ndarray,
    torsion: bool = False,
    compliance: float = 0.0,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
    np.ndarray, np.ndarray,
]:
    """Contact Jacobians, grasp map, their rates and the torque-affine terms of one instant.

    Args:
        J_fingertip: ``J_s`` per fingertip (LOCAL_WORLD_ALIGNED), (n, 6, m).
        twist_fingertip: ``(v_f, w_f)``, (n, 6).
        J_fingertip_dot_dq: ``(a_f0, alpha_f0) = J_s_dot dq``, (n, 6).
        p_fingertip_in_palm: Fingertip sphere centres, (n, 3), m.
        M_h_inverse: ``M_h^-1``, (m, m).
        h_bias: ``C_h dq + g``, (m,), N·m.
        p_object_in_palm: Object centre of mass, (3,), m.
        twist_object: ``(v_o, w_o)``, (6,).
        M_o_inverse: ``M_o^-1``, (6, 6).
        C_o_twist: ``C_o x_o_dot``, (6,).
        w_e: External wrench on the object, (6,).
        p_contact_in_palm: Contact points, (n, 3), m.
        R_contact_to_palm: Contact frames ``R_pc``, (n, 3, 3).
        H_cf: Relative rotation (contact frame) ↦ xi_cf_dot, (n, 2, 3).
        H_cf_dot_w: ``H_cf_dot w``, (n, 2).
        sliding_velocity: ``M_cf xi_cf_dot`` along (rho1, rho2), (n, 2), m/s.
        frame_angular_velocity: ``Omega`` (contact-frame components), (n, 3), rad/s.
        joint_span: Each joint's span, ``[start, stop)`` (:class:`~grasp_safety_filter.model.
            hand.Branches`), (m, 2).
        fingertip_span: Each fingertip's span, (n, 2).
        torsion: Soft-finger contacts: each contact also transmits a torque about its
            normal and the fingertip cannot spin on the object (k = 4n rows, the n torsion
            rows after the 3n force rows); False: point contacts with friction (k = 3n).
        compliance: Soft fingers' relative torsional compliance
            (:func:`~grasp_safety_filter.model.wrench_solve.wrench_solve`).

    Returns:
        ``J_h`` (k, m), ``G`` (6, k), ``J_h_dot dq`` (k,), ``G_dot^T x_o_dot`` (k,),
        ``B_ho`` (k, k), and ``[matrix | offset]`` of ``f_c`` (k, m + 1), ``ddq``
        (m, m + 1), ``x_o_ddot`` (6, m + 1) and ``xi_cf_ddot`` (2n, m + 1, contact-major).

    Raises:
        numpy.linalg.LinAlgError: B_ho is singular (the contact forces are not determined).
    """
    (
        J_h, G, Jh_dot_dq, G_dot_T_twist, B_ho, force_rhs, ddq, M_h_inv_J_hT, M_o_inv_G,
        x_ddot_free, w_c, w_relative,
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
        p_contact_in_palm,
        R_contact_to_palm,
        H_cf,
        H_cf_dot_w,
        sliding_velocity,
        frame_angular_velocity,
        joint_span,
        fingertip_span,
        torsion,
    )
    # B_ho is at most 16 × 16: LAPACK (scipy) in between the two compiled passes.
    force = contact_wrench(B_ho, force_rhs, torsion, compliance)
    ddq, x_ddot, xi_ddot = acceleration_terms(
        force, ddq, M_h_inv_J_hT, M_o_inv_G, x_ddot_free, w_c, w_relative,
        J_fingertip, J_fingertip_dot_dq, R_contact_to_palm, H_cf, H_cf_dot_w, joint_span,
        fingertip_span,
    )
    return J_h, G, Jh_dot_dq, G_dot_T_twist, B_ho, force, ddq, x_ddot, xi_ddot
