"""Every model term at one instant, computed stage by stage, for any contact surfaces.

Hand terms (Pinocchio), then the contacts' geometry and rolling rates (one stacked call),
the object's terms, and the hand–object coupling and the torque-affine terms in one compiled
pass (:func:`~grasp_safety_filter.model.contact_dynamics.contact_dynamics`); the equations are
:mod:`~grasp_safety_filter.model.grasp_model`'s. Spherical fingertips on flat faces or on a
sphere object take :func:`~grasp_safety_filter.model.packed_state.packed_state` instead where
it gives an answer.
"""

from __future__ import annotations

from functools import partial

import numpy as np

from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.contact_dynamics import contact_dynamics
from grasp_safety_filter.model.contact_stack import ContactStack
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.hand import HandModel
from grasp_safety_filter.model.rigid_object import RigidObject


def staged_state(
    hand_model: HandModel,
    rigid_object: RigidObject,
    contacts: ContactStack,
    t: float,
    q: np.ndarray,
    dq: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    *,
    torsion: bool = False,
    torsional_compliance: float = 0.0,
) -> GraspState:
    """Every model term at one instant (see :class:`GraspState`), stage by stage.

    Args:
        hand_model: Kinematics and dynamics of the hand (m joints).
        rigid_object: The grasped object.
        contacts: The n fingertip–object surface pairs, stacked.
        t: Time, s.
        q: Joint positions, (m,), rad.
        dq: Joint velocities, (m,), rad/s.
        p_object_in_palm: Object centre of mass in the palm frame, (3,), m.
        R_object_to_palm: Object orientation, (3, 3).
        twist_object: Object twist ``x_o_dot = (v_o, w_o)`` in palm coordinates, (6,),
            (m/s, rad/s).
        torsion: Soft-finger contacts (4n wrench entries; see
            :mod:`~grasp_safety_filter.model.dynamics_kernel`).
        torsional_compliance: Their relative torsional compliance rho.
    """
    m = hand_model.n_joints
    q = np.array(q, dtype=float)
    dq = np.array(dq, dtype=float)
    p_o = np.array(p_object_in_palm, dtype=float)
    R_o = np.array(R_object_to_palm, dtype=float)
    twist_o = np.array(twist_object, dtype=float)
    hand = hand_model.terms(q, dq)
    p_f, R_pf, J_s = hand.p_fingertip_in_palm, hand.R_fingertip_to_palm, hand.J_fingertip

    # ---- contact geometry and rolling rates, (n, ...) arrays.
    geometry, rates = contacts.kinematics(p_f, R_pf, hand.twist_fingertip, p_o, R_o, twist_o)
    R_pc = geometry.R_contact_to_palm

    # ---- object
    M_o = rigid_object.inertia_matrix(R_o)
    C_o_twist = rigid_object.bias_wrench(R_o, twist_o)
    w_e = rigid_object.external_wrench()

    # ---- J_h, G, their rates along the rolling motion and the torque-affine terms
    # (module docstring; the formulas in dynamics_kernel).
    J_h, G, Jh_dot_dq, G_dot_T_twist, B_ho, force, ddq, x_ddot, xi_ddot = contact_dynamics(
        J_s,
        hand.twist_fingertip,
        hand.J_fingertip_dot_dq,
        p_f,
        hand.M_h_inverse,
        hand.h_bias,
        p_o,
        twist_o,
        rigid_object.inverse_inertia_matrix(R_o),
        C_o_twist,
        w_e,
        geometry.p_contact_in_palm,
        R_pc,
        rates.H_cf,
        rates.H_cf_dot_w,
        rates.sliding_velocity,
        rates.frame_angular_velocity,
        *hand_model.branches,
        torsion,
        torsional_compliance,
    )

    arrays = {
        'q': q,
        'dq': dq,
        'p_object_in_palm': p_o,
        'R_object_to_palm': R_o,
        'twist_object': twist_o,
        'p_fingertip_in_palm': p_f,
        'R_fingertip_to_palm': R_pf,
        'twist_fingertip': hand.twist_fingertip,
        'xi_cf': geometry.xi_cf,
        'xi_co': geometry.xi_co,
        'psi': geometry.psi,
        'xi_cf_dot': rates.xi_cf_dot,
        'xi_co_dot': rates.xi_co_dot,
        'psi_dot': rates.psi_dot,
        'penetration': geometry.penetration,
        'p_contact_in_palm': geometry.p_contact_in_palm,
        'R_contact_to_palm': R_pc,
        'M_h': hand.M_h,
        'h_bias': hand.h_bias,
        'gravity_torque': hand.gravity_torque,
        'J_fingertip': J_s,
        'J_h': J_h,
        'G': G,
        'Jh_dot_dq': Jh_dot_dq,
        'G_dot_T_twist': G_dot_T_twist,
        'M_o': M_o,
        'C_o_twist': C_o_twist,
        'w_e': w_e,
        'B_ho': B_ho,
    }
    # Every array is handed out read-only; the augmented matrices are frozen before their
    # column views are taken, so that the views are read-only too.
    for array in (*arrays.values(), force, ddq, x_ddot, xi_ddot):
        array.setflags(write=False)
    return GraspState(
        t=float(t),
        **arrays,
        contact_force=AffineMap(force[:, :m], force[:, m]),
        joint_acceleration=AffineMap(ddq[:, :m], ddq[:, m]),
        object_acceleration=AffineMap(x_ddot[:, :m], x_ddot[:, m]),
        xi_cf_ddot=AffineMap(xi_ddot[:, :m], xi_ddot[:, m]),
        xi_co_rate_terms=partial(contacts.object_rate_terms, geometry, rates),
    )
