"""Nominal in-hand manipulation control: computed torque plus internal squeeze force.

The paper's nominal controller (eq. 19–21; Cole, Hauser & Sastry, IEEE TAC 34(4), 1989)::

    u_nom   = J_h^T (G^+ u_m + u_f) - tau_e                  (tau_e = -g(q))
    u_m     = M_ho x_o_ddot_des + C_ho x_o_dot - w_e
    x_o_ddot_des = P (r_ddot + K_p e + K_d e_dot) + P_dot r_o_dot
    u_f,i   = k_f (p_bar_c - p_c,i)

with ``M_ho = M_o + G J_h^-T M_h J_h^-1 G^T`` and
``C_ho x_o_dot = C_o x_o_dot + G J_h^-T (C_h dq + M_h J_h^-1 (G_dot^T x_o_dot - J_h_dot dq))``.

Under rolling contact (``J_h dq = G^T x_o_dot`` and its derivative) this makes the object's
Euler-coordinate error obey ``e_ddot + K_d e_dot + K_p e = 0`` exactly.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.control.pose_error import (
    acceleration_from_euler,
    euler_from_matrix,
    euler_pose_error,
    euler_rates_from_twist,
)
from grasp_safety_filter.control.reference import (
    PAPER_AMPLITUDE,
    PAPER_FREQUENCY,
    PaperReference,
    Pose,
    ReferenceSample,
    ReferenceSource,
    TopicReference,
)
from grasp_safety_filter.io.parameters import flatten_parameters, ParameterError
from grasp_safety_filter.io.schemas import NOMINAL_CONTROLLER_PARAMETERS
from grasp_safety_filter.model.grasp_state import GraspState


@dataclass(frozen=True)
class NominalConfig:
    """Gains and reference choice of the nominal controller (paper values by default).

    Attributes:
        kp: Proportional gain, K_p = kp I, 1/s².
        kd: Derivative gain, K_d = kd I, 1/s.
        kf: Squeeze gain k_f, N/m.
        reference_source: ``"paper"`` or ``"topic"``.
        amplitude: Paper reference amplitude, shape (6,), m and rad.
        frequency: Paper reference angular frequency, rad/s.
        timeout: Topic reference timeout, s.

    """

    kp: float = 1.0
    kd: float = 2.5
    kf: float = 10.0
    reference_source: str = 'paper'
    amplitude: tuple[float, ...] = PAPER_AMPLITUDE
    frequency: float = PAPER_FREQUENCY
    timeout: float = 0.5

    def __post_init__(self) -> None:
        values = {
            'gains.kp': self.kp,
            'gains.kd': self.kd,
            'gains.kf': self.kf,
            'reference.source': self.reference_source,
            'reference.amplitude': list(self.amplitude),
            'reference.frequency': self.frequency,
            'reference.timeout': self.timeout,
        }
        for spec in NOMINAL_CONTROLLER_PARAMETERS:
            spec.validate(values[spec.name])
        object.__setattr__(self, 'amplitude', tuple(float(a) for a in self.amplitude))

    @classmethod
    def from_parameters(cls, params: Mapping[str, Any]) -> NominalConfig:
        """Read the controller's parameters; missing ones take their defaults.

        Args:
            params: Parameter values by dotted name (``{"gains.kp": 1.0, ...}``) or as
                nested mappings (``{"gains": {"kp": 1.0}}``); other names are ignored.

        Raises:
            ParameterError: A value has the wrong type or is out of range; the message names
                the parameter, what was expected and what was received.

        """
        flat = flatten_parameters(params)
        values = {
            spec.name: spec.validate(flat[spec.name]) if spec.name in flat else spec.default
            for spec in NOMINAL_CONTROLLER_PARAMETERS
        }
        return cls(
            kp=float(values['gains.kp']),
            kd=float(values['gains.kd']),
            kf=float(values['gains.kf']),
            reference_source=values['reference.source'],
            amplitude=tuple(values['reference.amplitude']),
            frequency=float(values['reference.frequency']),
            timeout=float(values['reference.timeout']),
        )

    def make_reference(self, initial_pose: Pose, t0: float = 0.0) -> ReferenceSource:
        """Build the configured reference source, starting at the initial object pose at t0."""
        if self.reference_source == 'paper':
            return PaperReference(initial_pose, self.amplitude, self.frequency, t0)
        if self.reference_source == 'topic':
            return TopicReference(initial_pose, self.timeout)
        raise ParameterError(
            f"parameter 'reference.source': expected 'paper' or 'topic', got "
            f'{self.reference_source!r}'
        )


@dataclass(frozen=True)
class NominalOutput:
    """One tick of the nominal controller.

    Attributes:
        u: Nominal joint torque u_nom, shape (m,), N·m.
        u_manipulation_wrench: u_m, the object wrench the hand must supply through the
            contacts, at the centre of mass in palm coordinates, shape (6,), (N, N·m).
        u_internal: Internal force u_f per contact in the contact frames, shape (3n,), N
            (in null(G)).
        pose_error: e = r - r_o in Euler coordinates, shape (6,), m and rad.
        pose_error_rate: e_dot = r_dot - r_o_dot, shape (6,), m/s and rad/s.
        object_acceleration_desired: x_o_ddot_des = (a, alpha), palm coordinates, (6,).
        reference_stale: The reference sample was held (stale), see TopicReference.

    """

    u: np.ndarray
    u_manipulation_wrench: np.ndarray
    u_internal: np.ndarray
    pose_error: np.ndarray
    pose_error_rate: np.ndarray
    object_acceleration_desired: np.ndarray
    reference_stale: bool


class NominalController:
    """Computed-torque object manipulation with an internal squeeze (Cole et al. 1989).

    Stateless: :meth:`compute` is a pure function of the grasp state and reference sample.
    Requires a square hand Jacobian (m = 3n joints, the paper's hand: 9 joints, 3 contacts)
    and a full-row-rank grasp map (at least three non-collinear contacts).

    Args:
        config: Gains (the reference fields are used by :meth:`NominalConfig.make_reference`).

    """

    def __init__(self, config: NominalConfig | None = None) -> None:
        self.config = config if config is not None else NominalConfig()

    def internal_force(self, state: GraspState) -> np.ndarray:
        """Squeeze ``u_f,i = k_f (p_bar_c - p_c,i)`` in the contact frames, shape (3n,), N.

        Its palm-frame components sum to zero and so do their moments about the object's
        centre of mass, ``sum_i (p_c,i - p_o) × k_f (p_bar_c - p_c,i)
        = k_f (p_bar_c - p_o) × sum_i (p_bar_c - p_c,i) = 0``: it lies in null(G).
        """
        p_contact = state.p_contact_in_palm
        # The centroid as a sum (ndarray.mean costs several µs of bookkeeping at this size).
        p_centroid = p_contact.sum(axis=0) / p_contact.shape[0]
        f_palm = self.config.kf * (p_centroid - p_contact)
        # G acts on contact-frame forces: express each in C_i, R_pc^T f = (f^T R_pc)^T.
        return (f_palm[:, None, :] @ state.R_contact_to_palm).reshape(-1)

    def desired_object_acceleration(
        self, state: GraspState, reference: ReferenceSample
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``x_o_ddot_des``, the pose error e and its rate e_dot, each shape (6,).

        With ``r_o`` the object's Euler coordinates and ``x_o_dot = P(phi_o) r_o_dot``,
        ``x_o_ddot = P r_o_ddot + P_dot r_o_dot``. Choosing
        ``r_o_ddot = r_ddot + K_p e + K_d e_dot`` gives ``e_ddot + K_d e_dot + K_p e = 0``;
        the paper's ``P (r_ddot + K_p e + K_d e_dot)`` omits the ``P_dot r_o_dot`` term
        (Cole et al. keep it), which would leave an Euler-angle velocity-product
        disturbance ``-P^-1 P_dot r_o_dot`` in the error dynamics whenever the object turns
        about more than one axis.
        """
        phi_object = euler_from_matrix(state.R_object_to_palm)
        r_object = np.concatenate((state.p_object_in_palm, phi_object))
        r_object_dot = euler_rates_from_twist(phi_object, state.twist_object)
        e = euler_pose_error(reference.r, r_object)
        e_dot = reference.r_dot - r_object_dot
        r_object_ddot = reference.r_ddot + self.config.kp * e + self.config.kd * e_dot
        x_ddot = acceleration_from_euler(phi_object, r_object_dot, r_object_ddot)
        return x_ddot, e, e_dot

    def compute(self, state: GraspState, reference: ReferenceSample) -> NominalOutput:
        """Nominal joint torque for the current grasp state and reference sample.

        Raises:
            ValueError: The hand Jacobian is not square.
            numpy.linalg.LinAlgError: The hand Jacobian is exactly singular.

        """
        J_h = state.J_h
        if J_h.shape[0] != J_h.shape[1]:
            raise ValueError(
                f'NominalController: expected a square hand Jacobian (m = 3n), got J_h of '
                f'shape {J_h.shape}'
            )
        G = state.G
        M_h = state.M_h
        x_ddot_des, e, e_dot = self.desired_object_acceleration(state, reference)

        m = J_h.shape[1]
        # A = J_h^-1 G^T maps the object twist to joint rates on the constraint, so
        # G J_h^-T = A^T and M_ho = M_o + A^T M_h A.
        # Differentiating J_h dq = G^T x_dot: ddq = J_h^-1 (G^T x_ddot + G_dot^T x_dot
        # - J_h_dot dq); the velocity part of M_h ddq + C_h dq, pulled back through
        # G J_h^-T, is the C_ho x_dot term. Using the measured C_h dq and J_h_dot dq
        # (rather than C_h J_h^-1 G^T x_dot) keeps it exact even off the velocity
        # constraint, so only the acceleration-level rolling constraint is assumed.
        # One solve with J_h for both:
        #   [A | ddq_velocity] = J_h^-1 [G^T | G_dot^T x_dot - J_h_dot dq].
        rhs = np.empty((m, 7))
        rhs[:, :6] = G.T
        rhs[:, 6] = state.G_dot_T_twist - state.Jh_dot_dq
        solution = np.linalg.solve(J_h, rhs)
        A, ddq_velocity = solution[:, :6], solution[:, 6]
        M_ho = state.M_o + A.T @ M_h @ A
        C_h_dq = state.h_bias - state.gravity_torque
        C_ho_x_dot = state.C_o_twist + A.T @ (C_h_dq + M_h @ ddq_velocity)
        u_m = M_ho @ x_ddot_des + C_ho_x_dot - state.w_e

        # G has full row rank: its minimum-norm right inverse is G^+ = G^T (G G^T)^-1
        # (np.linalg.lstsq would take an SVD for the same 6 × 3n system).
        f_manipulation = G.T @ np.linalg.solve(G @ G.T, u_m)
        u_f = self.internal_force(state)
        # -tau_e = g(q): gravity compensation of the fingers.
        u = J_h.T @ (f_manipulation + u_f) + state.gravity_torque
        return NominalOutput(
            u=u,
            u_manipulation_wrench=u_m,
            u_internal=u_f,
            pose_error=e,
            pose_error_rate=e_dot,
            object_acceleration_desired=x_ddot_des,
            reference_stale=reference.stale,
        )
