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

One implementation: the model's terms (:meth:`GraspModel.state`), then the formulas above
compiled in :func:`~hand_sim_node.stabilisation.stabilised_rate`. :meth:`PlantRate.from_state`
takes the state the controller read at the step's start; :meth:`PlantRate.at` computes the
state at the intermediate Runge–Kutta stages, from the configuration.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.quaternion import rotation_matrix
from hand_sim_node.stabilisation import stabilised_rate


class PlantRate:
    """The state rate ``x_dot`` of the grasp model under a joint torque held constant.

    Args:
        model: A ``GraspModel`` (reads ``state``, ``object``, ``n_joints``, ``soft_finger``,
            ``torsional_compliance``).

    """

    def __init__(self, model: Any) -> None:
        self._model = model
        self._object = model.object
        self._m = model.n_joints

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
        M_o_inv = self._object.dynamics(state.R_object_to_palm, state.twist_object)[1]
        return stabilised_rate(
            state, effort, quaternion_xyzw, M_o_inv, position_gain, velocity_gain,
            self._model.soft_finger, self._model.torsional_compliance,
        )

    def at(
        self, x: np.ndarray, effort: np.ndarray, position_gain: float, velocity_gain: float
    ) -> np.ndarray:
        """Rate at the flat state ``x`` (layout of ``SimState.to_vector``), shape (2m + 13,).

        The model's terms at ``x`` (:meth:`GraspModel.state`, with the orientation of the
        normalised quaternion), then :meth:`from_state`'s formulas with the quaternion as
        integrated.

        Raises:
            numpy.linalg.LinAlgError: B_ho is singular.
            ValueError: The quaternion is zero or not finite.

        """
        m = self._m
        quaternion = x[2 * m + 3 : 2 * m + 7]
        state = self._model.state(
            0.0, x[:m], x[m : 2 * m], x[2 * m : 2 * m + 3], rotation_matrix(quaternion),
            x[2 * m + 7 :],
        )
        return self.from_state(state, effort, quaternion, position_gain, velocity_gain)[0]
