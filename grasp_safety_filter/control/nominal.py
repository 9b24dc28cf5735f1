"""Nominal in-hand manipulation control: computed torque, internal squeeze, null-space posture.

Model (DESIGN.md §3; f the contact forces on the object in the contact frames, 3n rows)::

    M_h ddq + C_h dq - tau_e = u - J_h^T f                        hand, m joints
    M_o x_o_ddot + C_o x_o_dot = G f + w_e                        object
    J_h ddq + J_h_dot dq = G^T x_o_ddot + G_dot^T x_o_dot         rolling (3n rows)

The paper's controller (eq. 19–21; Cole, Hauser & Sastry, IEEE TAC 34(4), 1989), for any
hand with m >= 3n joints and J_h of full row rank 3n::

    u_nom   = J_h^T (G^+ u_m + u_f) - tau_e + tau_null           (tau_e = -g(q))
    u_m     = M_ho x_o_ddot_des + C_ho x_o_dot - w_e
    x_o_ddot_des = P (r_ddot + K_p e + K_d e_dot) + P_dot r_o_dot
    u_f,i   = k_f (p_bar_c - p_c,i)
    M_ho    = M_o + G Lambda G^T
    C_ho x_o_dot = C_o x_o_dot + G Lambda (J_h M_h^-1 C_h dq + G_dot^T x_o_dot - J_h_dot dq)
    tau_null = N^T M_h (-k_null,p (q - q_posture) - k_null,d dq)

with the contact-space inertia ``Lambda = (J_h M_h^-1 J_h^T)^-1`` (3n × 3n), the
M_h-weighted right inverse ``J_bar = M_h^-1 J_h^T Lambda`` (``J_h J_bar = I``) and the
dynamically consistent null-space projector of joint velocities ``N = I - J_bar J_h``
(``J_h N = 0``); torques are projected with ``N^T = I - J_h^T Lambda J_h M_h^-1``. Since
``J_bar^T M_h J_bar = Lambda``, these are the paper's ``M_ho = M_o + G J_h^-T M_h J_h^-1 G^T``
and ``C_ho`` with ``J_h^-1`` replaced by ``J_bar``. For m = 3n, ``J_bar = J_h^-1``,
``Lambda = J_h^-T M_h J_h^-1`` and ``N = 0``: the paper's law.

Derivation. Solve the hand equation for ddq and put it into the rolling constraint:
``J_h M_h^-1 (u + tau_e - C_h dq) - Lambda^-1 f = G^T x_o_ddot + G_dot^T x_o_dot - J_h_dot dq``,
so

    f = J_bar^T (u + tau_e - C_h dq) - Lambda (G^T x_o_ddot + G_dot^T x_o_dot - J_h_dot dq).

``J_bar^T J_h^T = I`` and ``J_bar^T N^T = 0``: under the law, ``f = G^+ u_m + u_f -
J_bar^T C_h dq - Lambda (...)`` whatever tau_null is. With ``G G^+ = I`` and ``G u_f = 0``
the object equation becomes ``M_ho x_o_ddot + C_ho x_o_dot - w_e = u_m``, i.e.
``x_o_ddot = x_o_ddot_des`` and the Euler error obeys ``e_ddot + K_d e_dot + K_p e = 0``
exactly. Only the acceleration-level rolling constraint is used: the measured C_h dq and
J_h_dot dq enter, not ``C_h J_bar G^T x_o_dot``, which differs once dq has a null(J_h) part.
The Moore–Penrose ``J_h^+ = J_h^T (J_h J_h^T)^-1`` would not do: torques reach the contacts
through ``J_h M_h^-1``, and only the M_h-weighted inverse makes the range and null-space
torques act on the contacts and the object independently.

Null space. Rolling fixes ``J_h dq = G^T x_o_dot`` only; the m - 3n directions of
null(J_h) (internal finger motion, e.g. a finger turning about its contact point) are left to
tau_null. ``N M_h^-1 = M_h^-1 N^T`` and ``N^T J_h^T = 0`` give, from the hand equation,

    N ddq = N (-k_null,p (q - q_posture) - k_null,d dq) - M_h^-1 N^T C_h dq:

a posture spring and damper on the internal motion with gains per unit inertia (1/s², 1/s,
the same for any hand's masses), loading no contact and not moving the object. Only the
null-space parts ``N (q - q_posture)`` and ``N dq`` act: the term never resists the object's
motion. q_posture is the first joint positions the controller sees unless one is given.

Free fingers. A joint on no listed fingertip's chain (a finger that touches nothing) has zero
columns in J_h. With a fixed palm M_h is block-diagonal over the fingers, so its rows of
``J_bar = M_h^-1 J_h^T Lambda`` are zero, N is the identity on it and the law gives it
``u_free = g_free(q) + M_h,free (-k_null,p (q - q_posture) - k_null,d dq)``: gravity
compensation and the posture spring and damper, which hold the finger at q_posture and load
no contact. (A joint shared by several fingers, e.g. a wrist, is on their chains: not free.)

The controller's gains and reference choice, :class:`NominalConfig`, are in
:mod:`grasp_safety_filter.control.nominal_config` and importable from here as well.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from grasp_safety_filter.control import nominal_kernel
from grasp_safety_filter.control.nominal_config import NominalConfig
from grasp_safety_filter.control.pose_error import (
    acceleration_from_euler,
    euler_from_matrix,
    euler_pose_error,
    euler_rates_from_twist,
)
from grasp_safety_filter.control.reference import ReferenceSample
from grasp_safety_filter.model.grasp_state import GraspState

__all__ = ['RANK_TOLERANCE', 'NominalConfig', 'NominalController', 'NominalOutput']


@dataclass(frozen=True)
class NominalOutput:
    """One tick of the nominal controller.

    Attributes:
        u: Nominal joint torque u_nom, shape (m,), N·m.
        u_manipulation_wrench: u_m, the object wrench the hand must supply through the
            contacts, at the centre of mass in palm coordinates, shape (6,), (N, N·m).
        u_internal: Internal force u_f per contact in the contact frames, shape (3n,), N
            (in null(G)).
        u_null_space: tau_null, the joint torque of the null(J_h) posture and damping term,
            shape (m,), N·m (zero when m = 3n); included in ``u``.
        pose_error: e = r - r_o in Euler coordinates, shape (6,), m and rad.
        pose_error_rate: e_dot = r_dot - r_o_dot, shape (6,), m/s and rad/s.
        object_acceleration_desired: x_o_ddot_des = (a, alpha), palm coordinates, (6,).
        reference_stale: The reference sample was held (stale), see TopicReference.

    """

    u: np.ndarray
    u_manipulation_wrench: np.ndarray
    u_internal: np.ndarray
    u_null_space: np.ndarray
    pose_error: np.ndarray
    pose_error_rate: np.ndarray
    object_acceleration_desired: np.ndarray
    reference_stale: bool


#: J_h is reported rank-deficient when a pivot of the Cholesky factorisation of
#: ``Lambda^-1 = J_h M_h^-1 J_h^T`` (squared) falls below this fraction of its largest
#: diagonal entry: the M_h-weighted J_h then has a condition number above ~1e6 and the
#: torques would amplify rounding errors by more than ~1e12.
RANK_TOLERANCE = 1e-12


class NominalController:
    """Computed-torque object manipulation with an internal squeeze (Cole et al. 1989).

    :meth:`compute` is a function of the grasp state and reference sample, except that the
    null-space posture q_posture, when not given, is the joint positions of the first
    state it sees (then kept). Requires m >= 3n joints for n contacts, a hand Jacobian of
    full row rank 3n and a full-row-rank grasp map (three non-collinear contacts or more).

    Args:
        config: Gains (the reference fields are used by :meth:`NominalConfig.make_reference`).
        posture: q_posture, shape (m,), rad, in the model's joint order; None: the first
            joint positions seen.

    """

    def __init__(
        self, config: NominalConfig | None = None, posture: np.ndarray | None = None
    ) -> None:
        self.config = config if config is not None else NominalConfig()
        self._posture = None if posture is None else np.array(posture, dtype=float)

    @property
    def posture(self) -> np.ndarray | None:
        """q_posture of the null-space term, shape (m,), rad (None before the first state)."""
        return None if self._posture is None else self._posture.copy()

    def internal_force(self, state: GraspState) -> np.ndarray:
        """Squeeze ``u_f,i = k_f (p_bar_c - p_c,i)`` in the contact frames, shape (3n,), N.

        Its palm-frame components sum to zero and so do their moments about the object's
        centre of mass, ``sum_i (p_c,i - p_o) × k_f (p_bar_c - p_c,i)
        = k_f (p_bar_c - p_o) × sum_i (p_bar_c - p_c,i) = 0``: it lies in null(G).
        """
        _check_state(state)
        return nominal_kernel.internal_force(
            state.p_contact_in_palm, state.R_contact_to_palm, self.config.kf
        )

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
        _check_state(state)
        phi_object = euler_from_matrix(state.R_object_to_palm)
        r_object = np.concatenate((state.p_object_in_palm, phi_object))
        r_object_dot = euler_rates_from_twist(phi_object, state.twist_object)
        e = euler_pose_error(reference.r, r_object)
        e_dot = reference.r_dot - r_object_dot
        r_object_ddot = reference.r_ddot + self.config.kp * e + self.config.kd * e_dot
        return acceleration_from_euler(phi_object, r_object_dot, r_object_ddot), e, e_dot

    def compute(self, state: GraspState, reference: ReferenceSample) -> NominalOutput:
        """Nominal joint torque for the current grasp state and reference sample.

        Raises:
            ValueError: Fewer joints than contact constraint rows (m < 3n), a state array
                of the wrong shape or type, or a posture of the wrong length.
            numpy.linalg.LinAlgError: J_h is rank-deficient (rank < 3n), M_h is not
                positive definite, or G G^T is exactly singular.

        """
        rows, m = _check_state(state)
        if self._posture is None:
            self._posture = np.array(state.q, dtype=float)
        elif self._posture.shape != (m,):
            raise ValueError(
                f'NominalController: posture has {self._posture.size} joint angles, the hand '
                f'{m} joints'
            )
        config = self.config
        J_h, G, G_dot_T_twist, Jh_dot_dq = _point_contact_rows(state, rows)
        M_h = state.M_h
        # The solves are numpy's (nominal_kernel's docstring); the rest is compiled. With
        # X = M_h^-1 J_h^T: Lambda^-1 = J_h X, J_bar = X Lambda, J_h M_h^-1 = X^T.
        rhs_m = np.empty((m, rows + 1))
        rhs_m[:, :rows] = J_h.T
        rhs_m[:, rows] = state.h_bias - state.gravity_torque  # C_h dq
        solution_m = np.linalg.solve(M_h, rhs_m)
        contact_inertia_inv, rhs, a_null, full_rank = nominal_kernel.contact_space_terms(
            J_h, solution_m, G, G_dot_T_twist, Jh_dot_dq, state.q, self._posture,
            state.dq, config.null_space_kp, config.null_space_kd, RANK_TOLERANCE,
        )
        if not full_rank:
            _check_rank(J_h, contact_inertia_inv)
        # One solve with Lambda^-1 for G Lambda G^T, the C_ho term and, for a redundant
        # hand, Lambda J_h a_null (the range-space part of M_h a_null, see tau_null):
        #   [Lambda G^T | Lambda (J_h M_h^-1 C_h dq + G_dot^T x_dot - J_h_dot dq) | ...],
        # a_null = -k_null,p (q - q_posture) - k_null,d dq and
        # tau_null = N^T M_h a_null = M_h a_null - J_h^T Lambda J_h a_null.
        solution = np.linalg.solve(contact_inertia_inv, rhs)
        x_ddot_des, e, e_dot = self.desired_object_acceleration(state, reference)
        u_m, tau_null, G_G_T = nominal_kernel.object_wrench(
            x_ddot_des, state.M_o, state.C_o_twist, state.w_e, G, solution, M_h, J_h, a_null
        )
        # G has full row rank: its minimum-norm right inverse is G^+ = G^T (G G^T)^-1
        # (np.linalg.lstsq would take an SVD for the same 6 × 3n system).
        # -tau_e = g(q): gravity compensation of the fingers.
        u, u_f = nominal_kernel.joint_torque(
            G, np.linalg.solve(G_G_T, u_m), J_h, state.p_contact_in_palm,
            state.R_contact_to_palm, config.kf, state.gravity_torque, tau_null,
        )
        return NominalOutput(
            u=u,
            u_manipulation_wrench=u_m,
            u_internal=u_f,
            u_null_space=tau_null,
            pose_error=e,
            pose_error_rate=e_dot,
            object_acceleration_desired=x_ddot_des,
            reference_stale=reference.stale,
        )


#: The state arrays the law reads, in the order _check_state lists their shapes.
_STATE_ARRAYS = (
    'J_h', 'G', 'M_h', 'h_bias', 'gravity_torque', 'q', 'dq', 'G_dot_T_twist', 'Jh_dot_dq',
    'M_o', 'C_o_twist', 'w_e', 'p_object_in_palm', 'R_object_to_palm', 'twist_object',
    'p_contact_in_palm', 'R_contact_to_palm',
)


def _point_contact_rows(
    state: GraspState, rows: int
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """``J_h``, ``G``, ``G_dot^T x_o_dot`` and ``J_h_dot dq`` of the 3n force rows.

    The law plans contact forces (the paper's point contacts); with soft fingers the state
    also has n torsion rows, which it leaves out: the torques about the normals that the
    plant then transmits are bounded by the safety filter's friction rows.
    """
    J_h, G = state.J_h, state.G
    if J_h.shape[0] == rows:
        return J_h, G, state.G_dot_T_twist, state.Jh_dot_dq
    return (
        J_h[:rows],
        np.ascontiguousarray(G[:, :rows]),
        state.G_dot_T_twist[:rows],
        state.Jh_dot_dq[:rows],
    )


def _check_state(state: GraspState) -> tuple[int, int]:
    """Return (3n, m) of the state's arrays; ValueError naming any of the wrong shape or type.

    The compiled kernels do not check bounds: every array they read is checked here, and
    the hand must have m >= 3n joints for n contacts. Soft fingers' states have k = 4n
    wrench rows (:func:`_point_contact_rows`); point contacts' k = 3n.
    """
    J_h = state.J_h
    n = state.n_contacts
    if J_h.ndim != 2 or J_h.shape[0] not in (3 * n, 4 * n):
        raise ValueError(
            f'NominalController: state.J_h: expected shape (3n, m) or, with soft fingers, '
            f'(4n, m) for n = {n} contacts, got {J_h.shape}'
        )
    k, m = J_h.shape
    rows = 3 * n
    if m < rows:
        raise ValueError(
            f'NominalController: the hand has m = {m} joints for n = {rows // 3} contacts; '
            f'rolling contacts fix 3n = {rows} joint-velocity components, so the law needs '
            f'm >= 3n (with fewer joints the fingers cannot follow every object motion)'
        )
    arrays = [getattr(state, name) for name in _STATE_ARRAYS]
    expected = [
        (k, m), (6, k), (m, m), (m,), (m,), (m,), (m,), (k,), (k,), (6, 6), (6,),
        (6,), (3,), (3, 3), (6,), (n, 3), (n, 3, 3),
    ]
    if [a.shape for a in arrays] != expected or {a.dtype for a in arrays} != {_FLOAT}:
        for name, shape, array in zip(_STATE_ARRAYS, expected, arrays, strict=True):
            if array.shape != shape or array.dtype != _FLOAT:
                raise ValueError(
                    f'NominalController: state.{name}: expected float64 of shape {shape} '
                    f'(k = {k} contact rows, m = {m} joints), got {array.dtype} of shape '
                    f'{array.shape}'
                )
    return rows, m


_FLOAT = np.dtype(float)


def _check_rank(J_h: np.ndarray, contact_inertia_inv: np.ndarray) -> None:
    """Raise LinAlgError naming the rank if J_h has (numerically) less than full row rank.

    ``Lambda^-1 = J_h M_h^-1 J_h^T`` is positive definite exactly when J_h has rank 3n; a
    Cholesky pivot near zero (:data:`RANK_TOLERANCE`) or a failed factorisation means it is
    not. The singular values are computed only to word the error.
    """
    try:
        pivots = np.diag(np.linalg.cholesky(contact_inertia_inv))
        full_rank = pivots.min() ** 2 > RANK_TOLERANCE * contact_inertia_inv.diagonal().max()
    except np.linalg.LinAlgError:
        full_rank = False
    if full_rank:
        return
    rows, m = J_h.shape
    singular_values = np.linalg.svd(J_h, compute_uv=False)
    values = np.array2string(singular_values, precision=3)
    rank = np.linalg.matrix_rank(J_h)
    if rank < rows:
        raise np.linalg.LinAlgError(
            f'NominalController: the hand Jacobian J_h ({rows} x {m}) is rank-deficient: '
            f'rank {rank}, needs 3n = {rows}; singular values {values} m (a finger at a '
            f'singular configuration, or a contact no joint can move)'
        )
    raise np.linalg.LinAlgError(
        f'NominalController: Lambda^-1 = J_h M_h^-1 J_h^T ({rows} x {rows}) is not positive '
        f'definite to working precision: J_h ({rows} x {m}) is nearly rank-deficient '
        f'(singular values {values} m) or M_h is not positive definite'
    )
