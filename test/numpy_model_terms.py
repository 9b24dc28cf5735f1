"""The model terms as numpy expressions: the oracle of the compiled kernels (tests only).

The same equations as :mod:`grasp_safety_filter.model.dynamics_kernel`, written as stacked
numpy operations on arrays with a leading contact axis (one expression per term).
"""

from __future__ import annotations

from model_oracles import ContactStack, object_terms
import numpy as np
from stacked_arrays import cross, matvec, skew

from grasp_safety_filter.model.grasp_model import GraspModel


def numpy_model_terms(
    model: GraspModel,
    q: np.ndarray,
    dq: np.ndarray,
    p_o: np.ndarray,
    R_o: np.ndarray,
    twist_o: np.ndarray,
) -> dict[str, np.ndarray]:
    """Return J_h, G, their rates, B_ho and the ``[matrix | offset]`` of the affine terms.

    Keys: ``J_h``, ``G``, ``Jh_dot_dq``, ``G_dot_T_twist``, ``B_ho``, ``contact_force``,
    ``joint_acceleration``, ``object_acceleration``, ``xi_cf_ddot`` (augmented (k, m + 1)).
    """
    n, m = model.n_contacts, model.n_joints
    model.bind_contacts(q, p_o, R_o)
    stack = ContactStack(model.contacts)
    v_o, w_o = twist_o[:3], twist_o[3:]
    hand = model.hand.terms(q, dq)
    p_f, R_pf, J_s = hand.p_fingertip_in_palm, hand.R_fingertip_to_palm, hand.J_fingertip
    v_f, w_f = hand.twist_fingertip[:, :3], hand.twist_fingertip[:, 3:]
    a_f0, alpha_f0 = hand.J_fingertip_dot_dq[:, :3], hand.J_fingertip_dot_dq[:, 3:]
    J_w = J_s[:, 3:]
    geometry = stack.geometry(p_f, R_pf, p_o, R_o)
    R_pc = geometry.R_contact_to_palm
    R_cp = R_pc.transpose(0, 2, 1)
    w_relative = w_f - w_o
    rates = stack.rolling_rates(geometry, matvec(R_cp, w_relative))
    p_c = geometry.p_contact_in_palm
    p_fc, p_oc = p_c - p_f, p_c - p_o
    skew_fc, skew_oc = skew(p_fc), skew(p_oc)
    J_h = (R_cp @ (J_s[:, :3] - skew_fc @ J_w)).reshape(3 * n, m)
    G = np.concatenate((R_pc, skew_oc @ R_pc), axis=1).transpose(1, 0, 2).reshape(6, 3 * n)
    skew_contact = skew(w_f + matvec(R_pc, rates.frame_angular_velocity))
    v_cf = v_f - matvec(skew_fc, w_f)
    v_co = v_o - skew_oc @ w_o
    p_c_dot = v_cf + matvec(R_pc[:, :, :2], rates.sliding_velocity)
    Jh_dot_dq = matvec(
        R_cp,
        a_f0 - matvec(skew_fc, alpha_f0) + cross(w_f, p_c_dot - v_f) - matvec(skew_contact, v_cf),
    ).reshape(3 * n)
    G_dot_T_twist = matvec(
        R_cp, cross(w_o, p_c_dot - v_o) - matvec(skew_contact, v_co)
    ).reshape(3 * n)
    _, M_o_inv, bias = object_terms(model.object, R_o, twist_o)
    x_ddot_free = M_o_inv @ (model.object.external_wrench() - bias)
    M_h_inv = np.linalg.inv(hand.M_h)
    torque = np.eye(m, m + 1)
    torque[:, m] = -hand.h_bias
    ddq_free = M_h_inv @ torque
    M_h_inv_J_hT = M_h_inv @ J_h.T
    M_o_inv_G = M_o_inv @ G
    B_ho = J_h @ M_h_inv_J_hT + G.T @ M_o_inv_G
    force_rhs = J_h @ ddq_free
    force_rhs[:, m] += Jh_dot_dq - G_dot_T_twist - G.T @ x_ddot_free
    force = np.linalg.solve(B_ho, force_rhs)
    ddq = ddq_free - M_h_inv_J_hT @ force
    x_ddot = M_o_inv_G @ force
    x_ddot[:, m] += x_ddot_free
    alpha_relative = J_w @ ddq - x_ddot[3:]
    alpha_relative[:, :, m] += alpha_f0 - matvec(skew_contact, w_relative)
    xi_ddot = (rates.H_cf @ R_cp) @ alpha_relative
    xi_ddot[:, :, m] += rates.H_cf_dot_w
    return {
        'J_h': J_h,
        'G': G,
        'Jh_dot_dq': Jh_dot_dq,
        'G_dot_T_twist': G_dot_T_twist,
        'B_ho': B_ho,
        'contact_force': force,
        'joint_acceleration': ddq,
        'object_acceleration': x_ddot,
        'xi_cf_ddot': xi_ddot.reshape(2 * n, m + 1),
    }
