"""The per-tick grasp state: every model term of one instant, computed once, read-only.

Conventions (used throughout the package):

- ``P`` is the palm frame (inertial), ``O`` the object frame at its centre of mass,
  ``F_i`` the frame at the centre of fingertip sphere i (z out of the tip), ``C_i`` the
  contact frame (the fingertip surface's Gauss frame at the contact: z is the outward
  fingertip normal, pointing into the object).
- ``R_X_to_Y`` maps coordinates in frame X to coordinates in frame Y (the paper's
  ``R_yx``); ``p_a_in_X`` is the position of point a in frame X.
- Twists are ``(v, w)``: linear velocity of the frame origin, then angular velocity, both
  in palm coordinates (Pinocchio's LOCAL_WORLD_ALIGNED).
- Contact forces are per contact ``(f_x, f_y, f_n)`` in the contact frame ``C_i``: the
  force the fingertip applies *on the object*; ``f_n > 0`` pushes into the object.
- Stacked per-contact vectors are contact-major: ``[c1_x, c1_y, c1_z, c2_x, ...]``.
- Units: SI (m, rad, kg, s, N, N·m).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from functools import cached_property

import numpy as np

from grasp_safety_filter.model.affine import AffineMap


@dataclass(frozen=True, eq=False)
class GraspState:
    """All model terms of the hand–object–contact system at one instant.

    Built by :meth:`grasp_safety_filter.model.grasp_model.GraspModel.state`; constraint
    families, controllers and the simulator read it and never recompute or mutate it
    (its arrays are made read-only).

    Attributes:
        t: Time stamp, s.
        q: Joint angles, shape (m,), rad, in the model's joint order.
        dq: Joint velocities, shape (m,), rad/s.
        p_object_in_palm: Object centre of mass, shape (3,), m.
        R_object_to_palm: Object orientation, shape (3, 3).
        twist_object: Object twist ``x_o_dot = (v_o, w_o)`` in palm coordinates, shape (6,).
        p_fingertip_in_palm: Fingertip sphere centres, shape (n, 3), m.
        R_fingertip_to_palm: Fingertip frame orientations, shape (n, 3, 3).
        twist_fingertip: Fingertip frame twists ``(v_f, w_f)``, shape (n, 6).
        xi_cf: Contact coordinates ``(a, b)`` on each fingertip surface, shape (n, 2), rad.
        xi_co: Contact coordinates on each object surface, shape (n, 2) (m on a face).
        psi: Angle between the two surfaces' first tangent axes, shape (n,), rad.
        xi_cf_dot, xi_co_dot, psi_dot: Their rolling rates, shapes (n, 2), (n, 2), (n,).
        penetration: Signed normal interpenetration at each contact, shape (n,), m
            (0 when touching, > 0 when the fingertip sphere is inside the object surface).
        p_contact_in_palm: Contact points (on the fingertip surface), shape (n, 3), m.
        R_contact_to_palm: Contact frames ``R_pc``, shape (n, 3, 3).
        M_h: Hand joint-space inertia, shape (m, m), symmetric positive definite.
        h_bias: ``C_h dq - tau_e = C_h dq + g(q)``: Coriolis, centrifugal and gravity joint
            torques, shape (m,), N·m.
        gravity_torque: ``g(q) = -tau_e``, shape (m,), N·m.
        J_fingertip: Fingertip frame Jacobians ``J_s`` (LOCAL_WORLD_ALIGNED), (n, 6, m).
        J_h: Hand Jacobian, shape (k, m): ``dq ↦`` fingertip material velocity at each
            contact point, in contact frames (k = 3n); with soft fingers (k = 4n) then each
            fingertip's angular velocity about its contact normal, rows 3n .. 4n - 1.
        G: Grasp map, shape (6, k): contact wrench (contact frames) ↦ object wrench at
            the centre of mass (palm coordinates).
        Jh_dot_dq: ``J_h_dot @ dq`` (total time derivative along the rolling motion), (k,).
        G_dot_T_twist: ``G_dot^T @ x_o_dot``, shape (k,).
        M_o: Object inertia in palm coordinates, shape (6, 6).
        C_o_twist: ``C_o x_o_dot = (0, w × I w)``, shape (6,).
        w_e: External wrench on the object (gravity), shape (6,), (N, N·m).
        B_ho: ``J_h M_h^-1 J_h^T + G^T M_o^-1 G``, shape (k, k).
        contact_force: ``u ↦ f_c``, shape (k, m): ``(f_x, f_y, f_n)`` per contact in its
            contact frame (N), then with soft fingers the torque about each contact normal
            (N·m) (:mod:`~grasp_safety_filter.model.dynamics_kernel`).
        joint_acceleration: ``u ↦ ddq``, shape (m, m).
        object_acceleration: ``u ↦ x_o_ddot = (a_o, alpha_o)``, shape (6, m).
        xi_cf_ddot: ``u ↦ (a_1_ddot, b_1_ddot, a_2_ddot, ...)``, shape (2n, m).
        xi_co_rate_terms: Returns ``(M_co^-1 R_psi M_cf, c)`` of this instant, shapes
            (n, 2, 2) and (n, 2), with ``xi_co_ddot = M_co^-1 R_psi M_cf xi_cf_ddot + c``
            (:func:`~grasp_safety_filter.model.rolling_kernels.object_coordinate_rate_terms`).
        xi_co_ddot: ``u ↦`` second derivatives of ``xi_co`` (contact-major, like
            ``xi_cf_ddot``), shape (2n, m); m/s² on a face, rad/s² in a sphere chart.
            A property computed once, on first use, from ``xi_cf_ddot`` and
            ``xi_co_rate_terms``: a tick without an object-surface barrier does not pay
            for it (a packed state's one compiled pass writes it in closed form, a few
            dozen products).
    """

    t: float
    q: np.ndarray
    dq: np.ndarray
    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    twist_object: np.ndarray
    p_fingertip_in_palm: np.ndarray
    R_fingertip_to_palm: np.ndarray
    twist_fingertip: np.ndarray
    xi_cf: np.ndarray
    xi_co: np.ndarray
    psi: np.ndarray
    xi_cf_dot: np.ndarray
    xi_co_dot: np.ndarray
    psi_dot: np.ndarray
    penetration: np.ndarray
    p_contact_in_palm: np.ndarray
    R_contact_to_palm: np.ndarray
    M_h: np.ndarray
    h_bias: np.ndarray
    gravity_torque: np.ndarray
    J_fingertip: np.ndarray
    J_h: np.ndarray
    G: np.ndarray
    Jh_dot_dq: np.ndarray
    G_dot_T_twist: np.ndarray
    M_o: np.ndarray
    C_o_twist: np.ndarray
    w_e: np.ndarray
    B_ho: np.ndarray
    contact_force: AffineMap
    joint_acceleration: AffineMap
    object_acceleration: AffineMap
    xi_cf_ddot: AffineMap
    xi_co_rate_terms: Callable[[], tuple[np.ndarray, np.ndarray]]

    #: ``(buffer, layout)`` when the fields are views of one read-only buffer (all but
    #: ``t``, ``M_o``, ``C_o_twist`` and ``w_e``;
    #: :class:`~grasp_safety_filter.model.packed_state.PackedGraspState`), else None:
    #: compiled consumers may read the terms there
    #: (:class:`~grasp_safety_filter.model.packed_terms.PackedLayout` says where). Not a
    #: dataclass field (no annotation): constructors and copies never set it.
    packed_terms = None

    @cached_property
    def xi_co_ddot(self) -> AffineMap:
        """``u ↦ xi_co_ddot = M_co^-1 R_psi M_cf xi_cf_ddot(u) + c``, shape (2n, m)."""
        object_from_fingertip, bias = self.xi_co_rate_terms()
        n, m = object_from_fingertip.shape[0], self.xi_cf_ddot.matrix.shape[1]
        augmented = np.empty((n, 2, m + 1))
        augmented[:, :, :m] = self.xi_cf_ddot.matrix.reshape(n, 2, m)
        augmented[:, :, m] = self.xi_cf_ddot.offset.reshape(n, 2)
        result = object_from_fingertip @ augmented
        result[:, :, m] += bias
        result = result.reshape(2 * n, m + 1)
        result.setflags(write=False)
        return AffineMap(result[:, :m], result[:, m])

    @property
    def n_contacts(self) -> int:
        """Number of contacts n."""
        return self.xi_cf.shape[0]

    @property
    def n_joints(self) -> int:
        """Number of joints m."""
        return self.q.shape[0]

    def required_friction(self, f_c: np.ndarray) -> np.ndarray:
        """Return the required friction per contact for ``f_c`` (see :func:`required_friction`)."""
        return required_friction(np.asarray(f_c)[: 3 * self.n_contacts])


def required_friction(f_c: np.ndarray) -> np.ndarray:
    """Return the required friction ``beta_i = ||f_t,i|| / f_n,i`` per contact, shape (n,).

    ``f_c`` stacks ``(f_x, f_y, f_n)`` per contact in contact frames (a soft finger's torsion
    entries, which follow, are left out by :meth:`GraspState.required_friction`). ``inf`` where the
    normal force is not positive (the contact is separating); NaN where it is unknown.
    """
    forces = np.asarray(f_c, dtype=float).reshape(-1, 3)
    tangential = np.hypot(forces[:, 0], forces[:, 1])
    normal = forces[:, 2]
    with np.errstate(divide='ignore', invalid='ignore'):
        beta = np.where(normal > 0.0, tangential / np.where(normal > 0.0, normal, 1.0), np.inf)
    beta[np.isnan(normal)] = np.nan
    return beta
