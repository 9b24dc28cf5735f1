"""The plant's state rate: the integrator's stage function, from a configuration or a GraspState.

The simulator integrates ``x = (q, dq, p_o, quat_o, x_o_dot)`` (see
:mod:`hand_sim_node.simulator`) with the contact forces of the rolling constraint plus a
Baumgarte correction:

    f_c = B_ho^-1 (J_h M_h^-1 (u - h) + J_h_dot dq - G_dot^T x_o_dot - G^T x_free
                   + K_v e + K_p [0, 0, δ_i]_i),            x_free = M_o^-1 (w_e - C_o x_o_dot)
    ddq = M_h^-1 (u - h) - M_h^-1 J_h^T f_c,                 x_o_ddot = x_free + M_o^-1 G f_c

Two evaluations of the same equations:

- :meth:`PlantRate.from_state` at the step's start, where a full :class:`GraspState` exists
  (the state the controller read): its affine maps ``u ↦ f_c, ddq, x_o_ddot`` give the
  unstabilised rates, and only the correction ``B_ho^-1 (K_v e + K_p δ)`` is solved for.
  ``M_h^-1 J_h^T`` is read off the contact-force map, whose matrix is ``B_ho^-1 J_h M_h^-1``.
- :meth:`PlantRate.at` at the intermediate Runge–Kutta stages, from the configuration: the
  model's kinematic and dynamic terms for the one torque ``u``, without the torque-affine
  matrices and the contact coordinates' second derivatives (which only the safety filter's
  barriers need) and without building a read-only GraspState. It follows
  :meth:`GraspModel.state` term by term; the tests check that both agree.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from scipy.linalg.lapack import dgesv

from grasp_safety_filter.model.arrays import matvec
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.quaternion import quaternion_derivative
from grasp_safety_filter.model.rolling import contact_stack

# skew(v)_ij = -eps_ijk v_k as a (9, 3) matrix: stacked cross-product matrices in one matmul.
_SKEW_FROM_VECTOR = np.array(
    [
        [0.0, 0.0, 0.0],
        [0.0, 0.0, -1.0],
        [0.0, 1.0, 0.0],
        [0.0, 0.0, 1.0],
        [0.0, 0.0, 0.0],
        [-1.0, 0.0, 0.0],
        [0.0, -1.0, 0.0],
        [1.0, 0.0, 0.0],
        [0.0, 0.0, 0.0],
    ]
)


def _skew(v: np.ndarray) -> np.ndarray:
    """Cross-product matrices ``v×`` of stacked vectors (k, 3), shape (k, 3, 3)."""
    return (v @ _SKEW_FROM_VECTOR.T).reshape(*v.shape[:-1], 3, 3)


def _rotation_matrix(quaternion_xyzw: np.ndarray) -> np.ndarray:
    """``model.quaternion.rotation_matrix`` in floats, the same bits at half the cost, (3, 3).

    The same steps: the norm from numpy's dot (as np.linalg.norm), then Eigen's
    ``toRotationMatrix`` of the normalised quaternion written out (its numpy and Pinocchio
    round trip costs ~5 µs a stage). The tests check the bits on random quaternions.

    Raises:
        ValueError: The quaternion is zero or not finite.

    """
    norm = math.sqrt(float(quaternion_xyzw.dot(quaternion_xyzw)))
    if not (math.isfinite(norm) and norm >= 1e-12):
        raise ValueError(
            f'quaternion: expected a non-zero finite quaternion, got {quaternion_xyzw}'
        )
    x, y, z, w = (quaternion_xyzw / norm).tolist()
    tx, ty, tz = 2.0 * x, 2.0 * y, 2.0 * z
    twx, twy, twz = tx * w, ty * w, tz * w
    txx, txy, txz = tx * x, ty * x, tz * x
    tyy, tyz, tzz = ty * y, tz * y, tz * z
    return np.array(
        [
            [1.0 - (tyy + tzz), txy - twz, txz + twy],
            [txy + twz, 1.0 - (txx + tzz), tyz - twx],
            [txz - twy, tyz + twx, 1.0 - (txx + tyy)],
        ]
    )


def _solve(A: np.ndarray, b: np.ndarray) -> np.ndarray:
    """``A^-1 b`` by LAPACK's gesv, without np.linalg.solve's per-call checks (~8 µs).

    Raises:
        numpy.linalg.LinAlgError: A is singular.

    """
    _, _, solution, info = dgesv(A, b)
    if info != 0:
        raise np.linalg.LinAlgError(f'B_ho is singular (LAPACK gesv info {info})')
    return solution


def baumgarte_correction(
    J_h: np.ndarray,
    G: np.ndarray,
    dq: np.ndarray,
    twist_object: np.ndarray,
    penetration: np.ndarray,
    position_gain: float,
    velocity_gain: float,
) -> np.ndarray:
    """``K_v e + K_p [0, 0, δ_i]_i`` with ``e = J_h dq - G^T x_o_dot``, shape (3n,), m/s².

    Args:
        J_h: Hand Jacobian (3n, m).
        G: Grasp map (6, 3n).
        dq: Joint velocities (m,), rad/s.
        twist_object: Object twist (6,), palm coordinates.
        penetration: Normal interpenetration per contact (n,), m.
        position_gain: ``K_p``, 1/s².
        velocity_gain: ``K_v``, 1/s.

    """
    correction = velocity_gain * (J_h @ dq - G.T @ twist_object)
    correction[2::3] += position_gain * penetration
    return correction


class PlantRate:
    """The state rate ``x_dot`` of the grasp model under a joint torque held constant.

    Args:
        model: A ``GraspModel`` (reads ``hand``, ``object``, ``contacts``, ``n_joints``,
            ``n_contacts``).

    """

    def __init__(self, model: Any) -> None:
        self._model = model
        self._hand = model.hand
        self._object = model.object
        self._m = model.n_joints
        self._n = model.n_contacts
        # Scratch arrays of `at` (nothing returned aliases them).
        self._work = tuple(np.empty((k, self._n, 3)) for k in (2, 2, 2, 4, 4))
        self._contact_pairs: list[Any] | None = None
        self._contact_stack: Any = None

    def _contacts(self) -> Any:
        """Return the model's contacts stacked (a model may choose them at its first state)."""
        pairs = self._model.contacts
        if pairs is not self._contact_pairs:
            self._contact_pairs, self._contact_stack = pairs, contact_stack(pairs)
        return self._contact_stack

    def from_state(
        self,
        state: GraspState,
        effort: np.ndarray,
        quaternion_xyzw: np.ndarray,
        position_gain: float,
        velocity_gain: float,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Rate at a full grasp state, and the stabilised contact forces.

        Args:
            state: Model terms at the state.
            effort: Joint torque u, shape (m,), N·m.
            quaternion_xyzw: The state's orientation quaternion as integrated.
            position_gain: ``K_p`` of the stabilisation, 1/s².
            velocity_gain: ``K_v`` of the stabilisation, 1/s.

        Returns:
            ``x_dot`` (2m + 13,) and ``f_c`` (3n,), contact frames, N.

        Raises:
            numpy.linalg.LinAlgError: B_ho is singular.

        """
        f_c = state.contact_force(effort)
        ddq = state.joint_acceleration(effort)
        x_o_ddot = state.object_acceleration(effort)
        if position_gain != 0.0 or velocity_gain != 0.0:
            stabilisation = baumgarte_correction(
                state.J_h,
                state.G,
                state.dq,
                state.twist_object,
                state.penetration,
                position_gain,
                velocity_gain,
            )
            # np.linalg.solve as before: the reported contact forces stay bit for bit.
            correction = np.linalg.solve(state.B_ho, stabilisation)
            f_c = f_c + correction
            # contact_force.matrix = B_ho^-1 J_h M_h^-1 (B_ho, M_h symmetric), so
            # M_h^-1 J_h^T correction = matrix^T B_ho correction = matrix^T stabilisation.
            ddq = ddq - state.contact_force.matrix.T @ stabilisation
            M_o_inv = self._object.inverse_inertia_matrix(state.R_object_to_palm)
            x_o_ddot = x_o_ddot + M_o_inv @ (state.G @ correction)
        return self._assemble(state.dq, ddq, state.twist_object, quaternion_xyzw, x_o_ddot), f_c

    def at(
        self, x: np.ndarray, effort: np.ndarray, position_gain: float, velocity_gain: float
    ) -> np.ndarray:
        """Rate at the flat state ``x`` (layout of ``SimState.to_vector``), shape (2m + 13,).

        Raises:
            numpy.linalg.LinAlgError: B_ho is singular.
            ValueError: The quaternion is zero or not finite.

        """
        m, n = self._m, self._n
        dq = x[m : 2 * m]
        p_o = x[2 * m : 2 * m + 3]
        quaternion = x[2 * m + 3 : 2 * m + 7]
        twist_o = x[2 * m + 7 :]
        R_o = _rotation_matrix(quaternion)
        v_o, w_o = twist_o[:3], twist_o[3:]
        hand = self._hand.terms(x[:m], dq)
        p_f, R_pf, J_s = hand.p_fingertip_in_palm, hand.R_fingertip_to_palm, hand.J_fingertip
        v_f, w_f = hand.twist_fingertip[:, :3], hand.twist_fingertip[:, 3:]

        contacts = self._contacts()
        geometry = contacts.geometry(p_f, R_pf, p_o, R_o)
        R_pc = geometry.R_contact_to_palm
        R_cp = R_pc.transpose(0, 2, 1)
        rates = contacts.rolling_rates(geometry, matvec(R_cp, w_f - w_o))
        p_c = geometry.p_contact_in_palm
        # Finger-side and object-side quantities stacked along a first axis of 2 (and the
        # four cross products below along one of 4), filled into preallocated arrays: one
        # numpy call per formula for both sides (np.stack costs ~10 µs).
        lever, w_fo, v_fo, left, right = self._work
        np.subtract(p_c, p_f, out=lever[0])
        np.subtract(p_c, p_o, out=lever[1])
        skew_fc, skew_oc = skews = _skew(lever)
        J_h = (R_cp @ (J_s[:, :3] - skew_fc @ J_s[:, 3:])).reshape(3 * n, m)
        G = np.concatenate((R_pc, skew_oc @ R_pc), axis=1).transpose(1, 0, 2).reshape(6, -1)

        # J_h_dot dq - G_dot^T x_o_dot (GraspModel.state has the derivation), with
        # -(p_fc×) alpha_f0 = alpha_f0 × p_fc:
        #   R_cp (a_f0 + alpha_f0 × p_fc + w_f × (p_c_dot - v_f) - w_o × (p_c_dot - v_o)
        #         - w_c × (v_cf - v_co)),   v_cf = v_f + w_f × p_fc,  v_co = v_o + w_o × p_oc.
        w_fo[0], w_fo[1] = w_f, w_o
        v_fo[0], v_fo[1] = v_f, v_o
        v_cfo = v_fo - matvec(skews, w_fo)  # material velocities at the contact
        p_c_dot = v_cfo[0] + matvec(R_pc[:, :, :2], rates.sliding_velocity)
        a_f0, alpha_f0 = hand.J_fingertip_dot_dq[:, :3], hand.J_fingertip_dot_dq[:, 3:]
        left[0], left[1:3] = alpha_f0, w_fo
        np.add(w_f, matvec(R_pc, rates.frame_angular_velocity), out=left[3])  # w_c
        right[0] = lever[0]
        np.subtract(p_c_dot, v_fo, out=right[1:3])
        np.subtract(v_cfo[0], v_cfo[1], out=right[3])
        crosses = matvec(_skew(left), right)
        relative_rate = matvec(
            R_cp, a_f0 + crosses[0] + crosses[1] - crosses[2] - crosses[3]
        ).reshape(-1)

        rigid_object = self._object
        M_o_inv = rigid_object.inverse_inertia_matrix(R_o)
        bias = rigid_object.bias_wrench(R_o, twist_o)
        x_free = M_o_inv @ (rigid_object.external_wrench() - bias)
        M_h_inv = hand.M_h_inverse
        ddq_free = M_h_inv @ (effort - hand.h_bias)
        M_h_inv_J_hT = M_h_inv @ J_h.T
        M_o_inv_G = M_o_inv @ G
        B_ho = J_h @ M_h_inv_J_hT + G.T @ M_o_inv_G
        rhs = J_h @ ddq_free + (relative_rate - G.T @ x_free)
        if position_gain != 0.0 or velocity_gain != 0.0:
            rhs += baumgarte_correction(
                J_h, G, dq, twist_o, geometry.penetration, position_gain, velocity_gain
            )
        f_c = _solve(B_ho, rhs)
        ddq = ddq_free - M_h_inv_J_hT @ f_c
        x_o_ddot = M_o_inv_G @ f_c + x_free
        return self._assemble(dq, ddq, twist_o, quaternion, x_o_ddot)

    @staticmethod
    def _assemble(
        dq: np.ndarray,
        ddq: np.ndarray,
        twist_object: np.ndarray,
        quaternion_xyzw: np.ndarray,
        x_o_ddot: np.ndarray,
    ) -> np.ndarray:
        """``x_dot = (dq, ddq, v_o, quat_dot, x_o_ddot)``."""
        return np.concatenate(
            (
                dq,
                ddq,
                twist_object[:3],
                quaternion_derivative(quaternion_xyzw, twist_object[3:]),
                x_o_ddot,
            )
        )
