"""The plant's state rate: the integrator's stage function, from a configuration or a GraspState.

The simulator integrates ``x = (q, dq, p_o, quat_o, x_o_dot)`` (see
:mod:`hand_sim_node.simulator`) with the contact forces of the rolling constraint plus a
Baumgarte correction:

    f_c = f_c(u) + B_ho^-1 (K_v e + K_p [0, 0, δ_i]_i),      e = J_h dq - G^T x_o_dot
    ddq = ddq(u) - M_h^-1 J_h^T (f_c - f_c(u)),
    x_o_ddot = x_o_ddot(u) + M_o^-1 G (f_c - f_c(u))

where ``f_c(u)``, ``ddq(u)`` and ``x_o_ddot(u)`` are the model's torque-affine terms (the
rolling constraint held exactly, DESIGN.md §3). ``M_h^-1 J_h^T`` is read off the
contact-force map, whose matrix is ``B_ho^-1 J_h M_h^-1`` (``B_ho``, ``M_h`` symmetric):
``M_h^-1 J_h^T c = matrix^T B_ho c``.

Two evaluations, one implementation: the model's compiled kernels, then the formulas above
compiled in :func:`~hand_sim_node.stabilisation.stabilised_rate`:

- :meth:`PlantRate.from_state` at the step's start, where a full :class:`GraspState` exists
  (the state the controller read) and holds the model's terms.
- :meth:`PlantRate.at` at the intermediate Runge–Kutta stages, from the configuration: the
  same compiled kernels :meth:`GraspModel.state` runs (the hand's terms, the contacts'
  kinematics, :func:`~grasp_safety_filter.model.contact_dynamics.contact_dynamics`), without
  building a read-only GraspState around them. For spherical fingertips on flat faces
  (the paper's grasp) they run inside two compiled calls around the solves of ``B_ho``
  (:func:`~hand_sim_node.stabilisation.sphere_on_plane_stage_rate`): the same bits
  without a Python round trip per kernel.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from typing import Any

import numpy as np

from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.closed_form_stacks import contact_stack, SphereOnPlaneStack
from grasp_safety_filter.model.contact_dynamics import contact_dynamics
from grasp_safety_filter.model.grasp_state import GraspState
from hand_sim_node.stabilisation import sphere_on_plane_stage_rate, stabilised_rate


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


@dataclass(frozen=True, slots=True, eq=False)
class StageTerms:
    """The model's terms at a Runge–Kutta stage that :func:`stabilised_rate` reads.

    The outputs of :func:`~grasp_safety_filter.model.contact_dynamics.contact_dynamics`,
    not copied (made read-only, as in a GraspState): the fields of a :class:`GraspState`
    that the plant's rate needs, without the terms only the safety filter reads.
    """

    dq: np.ndarray
    twist_object: np.ndarray
    penetration: np.ndarray
    J_h: np.ndarray
    G: np.ndarray
    B_ho: np.ndarray
    contact_force: AffineMap
    joint_acceleration: AffineMap
    object_acceleration: AffineMap


class PlantRate:
    """The state rate ``x_dot`` of the grasp model under a joint torque held constant.

    Args:
        model: A ``GraspModel`` (reads ``hand``, ``object``, ``contacts``, ``n_joints``).

    """

    def __init__(self, model: Any) -> None:
        self._model = model
        self._hand = model.hand
        self._object = model.object
        self._m = model.n_joints
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
            ``x_dot`` (2m + 13,) and ``f_c`` (k,: 3n or 4n), contact frames, N (N·m).

        Raises:
            numpy.linalg.LinAlgError: B_ho is singular.

        """
        M_o_inv = self._object.inverse_inertia_matrix(state.R_object_to_palm)
        return stabilised_rate(
            state, effort, quaternion_xyzw, M_o_inv, position_gain, velocity_gain,
            self._model.soft_finger, self._model.torsional_compliance,
        )

    def at(
        self, x: np.ndarray, effort: np.ndarray, position_gain: float, velocity_gain: float
    ) -> np.ndarray:
        """Rate at the flat state ``x`` (layout of ``SimState.to_vector``), shape (2m + 13,).

        The terms :meth:`GraspModel.state` computes, by the same calls, for this one state.

        Raises:
            numpy.linalg.LinAlgError: B_ho is singular.
            ValueError: The quaternion is zero or not finite.

        """
        m = self._m
        dq = x[m : 2 * m]
        p_o = x[2 * m : 2 * m + 3]
        quaternion = x[2 * m + 3 : 2 * m + 7]
        twist_o = x[2 * m + 7 :]
        R_o = _rotation_matrix(quaternion)
        stack = self._contacts()
        rigid_object = self._object
        M_o_inv = rigid_object.inverse_inertia_matrix(R_o)
        C_o_twist = rigid_object.bias_wrench(R_o, twist_o)
        if isinstance(stack, SphereOnPlaneStack):
            # The same kernels, the hand's terms included, in one compiled call before and
            # one after the solve. Flat faces only: other contacts (a sphere object's
            # compiled SphereOnSphereStack included) take the stages below.
            return sphere_on_plane_stage_rate(
                self._hand, x[:m], stack.surface_arrays, dq, p_o, R_o, twist_o, quaternion,
                M_o_inv, C_o_twist, rigid_object.external_wrench(), effort, position_gain,
                velocity_gain, self._model.soft_finger, self._model.torsional_compliance,
            )
        hand = self._hand.terms(x[:m], dq)
        p_f = hand.p_fingertip_in_palm
        geometry, rates = stack.kinematics(
            p_f, hand.R_fingertip_to_palm, hand.twist_fingertip, p_o, R_o, twist_o
        )
        J_h, G, _, _, B_ho, force, ddq, x_ddot, _ = contact_dynamics(
            hand.J_fingertip,
            hand.twist_fingertip,
            hand.J_fingertip_dot_dq,
            p_f,
            hand.M_h_inverse,
            hand.h_bias,
            p_o,
            twist_o,
            M_o_inv,
            C_o_twist,
            rigid_object.external_wrench(),
            geometry.p_contact_in_palm,
            geometry.R_contact_to_palm,
            rates.H_cf,
            rates.H_cf_dot_w,
            rates.sliding_velocity,
            rates.frame_angular_velocity,
            *self._hand.branches,
            self._model.soft_finger,
            self._model.torsional_compliance,
        )
        # Read-only, as in a GraspState: the compiled kernels then see one array type.
        for array in (dq, twist_o, geometry.penetration, J_h, G, B_ho, force, ddq, x_ddot):
            array.setflags(write=False)
        terms = StageTerms(
            dq,
            twist_o,
            geometry.penetration,
            J_h,
            G,
            B_ho,
            AffineMap(force[:, :m], force[:, m]),
            AffineMap(ddq[:, :m], ddq[:, m]),
            AffineMap(x_ddot[:, :m], x_ddot[:, m]),
        )
        return stabilised_rate(
            terms, effort, quaternion, M_o_inv, position_gain, velocity_gain,
            self._model.soft_finger, self._model.torsional_compliance,
        )[0]
