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

:func:`stabilised_rate` reads the model's terms from a GraspState, the one the controller
read at a step's start or the one :class:`~hand_sim_node.stage.PlantRate` computes at a
Runge–Kutta stage.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.quaternion import quaternion_derivative
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
        state: The model's terms, a :class:`~grasp_safety_filter.model.grasp_state.GraspState`
            (reads ``dq``, ``twist_object``, ``J_h``, ``G``, ``B_ho``, ``penetration`` and
            the affine maps ``contact_force``, ``joint_acceleration``,
            ``object_acceleration``).
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
