"""The nominal controller in numpy and Pinocchio: the oracle of the compiled kernels.

The law of :mod:`grasp_safety_filter.control.nominal` written with numpy expressions and
Pinocchio's Euler-angle functions, operation for operation as the controller computed it
before its arithmetic was compiled; test_nominal_kernel.py requires the kernels to give the
same numbers to the last bit.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from pinocchio import rpy

_WORLD = pin.ReferenceFrame.WORLD
RANK_TOLERANCE = 1e-12


def wrap_angle(angle):
    wrapped = np.remainder(np.asarray(angle, dtype=float) + math.pi, 2.0 * math.pi) - math.pi
    return np.where(wrapped == -math.pi, math.pi, wrapped)


def euler_from_matrix(R):
    return np.asarray(rpy.matrixToRpy(np.asarray(R, dtype=float)), dtype=float)


def euler_rate_jacobian(phi):
    return np.asarray(rpy.computeRpyJacobian(np.asarray(phi, dtype=float), _WORLD))


def euler_rate_jacobian_dot(phi, phi_dot):
    return np.asarray(
        rpy.computeRpyJacobianTimeDerivative(
            np.asarray(phi, dtype=float), np.asarray(phi_dot, dtype=float), _WORLD
        )
    )


def euler_rates_from_angular_velocity(phi, w_palm):
    E_inv = rpy.computeRpyJacobianInverse(np.asarray(phi, dtype=float), _WORLD)
    return np.asarray(E_inv @ np.asarray(w_palm, dtype=float))


def twist_from_euler(phi, r_dot):
    r_dot = np.asarray(r_dot, dtype=float)
    return np.concatenate((r_dot[:3], euler_rate_jacobian(phi) @ r_dot[3:]))


def euler_rates_from_twist(phi, twist):
    twist = np.asarray(twist, dtype=float)
    return np.concatenate((twist[:3], euler_rates_from_angular_velocity(phi, twist[3:])))


def acceleration_from_euler(phi, r_dot, r_ddot):
    r_dot = np.asarray(r_dot, dtype=float)
    r_ddot = np.asarray(r_ddot, dtype=float)
    phi_dot, phi_ddot = r_dot[3:], r_ddot[3:]
    alpha = euler_rate_jacobian(phi) @ phi_ddot + euler_rate_jacobian_dot(phi, phi_dot) @ phi_dot
    return np.concatenate((r_ddot[:3], alpha))


def euler_accelerations_from_acceleration(phi, r_dot, acceleration):
    r_dot = np.asarray(r_dot, dtype=float)
    acceleration = np.asarray(acceleration, dtype=float)
    alpha_from_rates = euler_rate_jacobian_dot(phi, r_dot[3:]) @ r_dot[3:]
    phi_ddot = euler_rates_from_angular_velocity(phi, acceleration[3:] - alpha_from_rates)
    return np.concatenate((acceleration[:3], phi_ddot))


def euler_pose_error(r_reference, r_object):
    r_reference = np.asarray(r_reference, dtype=float)
    r_object = np.asarray(r_object, dtype=float)
    return np.concatenate(
        (r_reference[:3] - r_object[:3], wrap_angle(r_reference[3:] - r_object[3:]))
    )


def paper_sample(r0, amplitude, frequency, t0, t):
    """``(r, r_dot, r_ddot)`` of the paper's reference at t."""
    phase = frequency * (t - t0)
    w = frequency
    return (
        r0 + amplitude * (math.cos(phase) - 1.0),
        -w * amplitude * math.sin(phase),
        -w * w * amplitude * math.cos(phase),
    )


def internal_force(state, kf):
    p_contact = state.p_contact_in_palm
    p_centroid = p_contact.sum(axis=0) / p_contact.shape[0]
    f_palm = kf * (p_centroid - p_contact)
    return (f_palm[:, None, :] @ state.R_contact_to_palm).reshape(-1)


def desired_object_acceleration(state, reference, kp, kd):
    phi_object = euler_from_matrix(state.R_object_to_palm)
    r_object = np.concatenate((state.p_object_in_palm, phi_object))
    r_object_dot = euler_rates_from_twist(phi_object, state.twist_object)
    e = euler_pose_error(reference.r, r_object)
    e_dot = reference.r_dot - r_object_dot
    r_object_ddot = reference.r_ddot + kp * e + kd * e_dot
    x_ddot = acceleration_from_euler(phi_object, r_object_dot, r_object_ddot)
    return x_ddot, e, e_dot


def full_rank(contact_inertia_inv):
    try:
        pivots = np.diag(np.linalg.cholesky(contact_inertia_inv))
    except np.linalg.LinAlgError:
        return False
    return bool(pivots.min() ** 2 > RANK_TOLERANCE * contact_inertia_inv.diagonal().max())


def compute(state, reference, config, posture):
    """Return the fields of NominalOutput as a dict, and whether the rank check passed."""
    J_h = state.J_h
    rows, m = J_h.shape
    G = state.G
    M_h = state.M_h
    x_ddot_des, e, e_dot = desired_object_acceleration(state, reference, config.kp, config.kd)
    C_h_dq = state.h_bias - state.gravity_torque
    redundant = m > rows
    rhs_m = np.empty((m, rows + 1))
    rhs_m[:, :rows] = J_h.T
    rhs_m[:, rows] = C_h_dq
    solution_m = np.linalg.solve(M_h, rhs_m)
    X, M_inv_C_h_dq = solution_m[:, :rows], solution_m[:, rows]
    contact_inertia_inv = J_h @ X
    rank_ok = full_rank(contact_inertia_inv)
    rhs = np.empty((rows, 8 if redundant else 7))
    rhs[:, :6] = G.T
    rhs[:, 6] = J_h @ M_inv_C_h_dq + state.G_dot_T_twist - state.Jh_dot_dq
    if redundant:
        a_null = -config.null_space_kp * (state.q - posture) - config.null_space_kd * state.dq
        rhs[:, 7] = J_h @ a_null
    solution = np.linalg.solve(contact_inertia_inv, rhs)
    M_ho = state.M_o + G @ solution[:, :6]
    C_ho_x_dot = state.C_o_twist + G @ solution[:, 6]
    u_m = M_ho @ x_ddot_des + C_ho_x_dot - state.w_e
    if redundant:
        tau_null = M_h @ a_null - J_h.T @ solution[:, 7]
    else:
        tau_null = np.zeros(m)
    f_manipulation = G.T @ np.linalg.solve(G @ G.T, u_m)
    u_f = internal_force(state, config.kf)
    u = J_h.T @ (f_manipulation + u_f) + state.gravity_torque + tau_null
    fields = {
        'u': u,
        'u_manipulation_wrench': u_m,
        'u_internal': u_f,
        'u_null_space': tau_null,
        'pose_error': e,
        'pose_error_rate': e_dot,
        'object_acceleration_desired': x_ddot_des,
    }
    return fields, rank_ok
