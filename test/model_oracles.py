"""Oracles of the model (tests only): Montana's rolling kinematics as stacked numpy, any surfaces.

:class:`ContactStack` evaluates the formulas of :mod:`grasp_safety_filter.model.rolling` for
the n contacts of a grasp together along a leading contact axis, for any surfaces
(:mod:`oracle_surfaces`); :func:`staged_state` builds a :class:`GraspState` stage by stage
from it, Pinocchio's hand terms and the dynamics kernels. The product computes the same terms
in compiled closed forms for spherical fingertips on flat faces or on a sphere
(:mod:`grasp_safety_filter.model.packed_terms`); the tests compare the two to rounding.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from typing import Any

import numpy as np
from oracle_rolling import ROLL_SELECT
from oracle_surfaces import SphereStack, stack_surfaces
from stacked_arrays import matvec

from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.dynamics_kernel import acceleration_terms, velocity_terms
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.rolling import ContactPair
from grasp_safety_filter.model.rolling_kernels import fingertip_contact_frames
from grasp_safety_filter.model.wrench_solve import contact_wrench


def _reflections(psi: np.ndarray) -> np.ndarray:
    """:func:`~grasp_safety_filter.model.rolling.reflection` of each angle, (k, 2, 2)."""
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[c, -s], [-s, -c]]).transpose(2, 0, 1)


def _inverse_2x2(A: np.ndarray) -> np.ndarray:
    """Inverses of stacked 2 × 2 matrices (k, 2, 2): ``[[d, -b], [-c, a]] / (a d - b c)``.

    The closed form avoids np.linalg.inv's per-call overhead, which dominates at this size.
    """
    a, b, c, d = A[:, 0, 0], A[:, 0, 1], A[:, 1, 0], A[:, 1, 1]
    return np.array([[d, -b], [-c, a]]).transpose(2, 0, 1) / (a * d - b * c)[:, None, None]


@dataclass(frozen=True)
class StackedContactGeometry:
    """The contact geometry of n contacts, each field stacked along a leading axis.

    The fields of :class:`~grasp_safety_filter.model.rolling.ContactGeometry`.

    Attributes:
        xi_cf, xi_co: (n, 2).
        psi, penetration: (n,).
        p_contact_in_palm: (n, 3).
        R_contact_to_palm, R_contact_to_fingertip: (n, 3, 3).
    """

    xi_cf: np.ndarray
    xi_co: np.ndarray
    psi: np.ndarray
    penetration: np.ndarray
    p_contact_in_palm: np.ndarray
    R_contact_to_palm: np.ndarray
    R_contact_to_fingertip: np.ndarray


@dataclass(frozen=True)
class StackedRollingRates:
    """Montana's rates of n contacts and the first-order terms their derivatives need.

    Attributes:
        xi_cf_dot, xi_co_dot: (n, 2).
        psi_dot: (n,).
        H_cf: ``M_cf^-1 A^-1 ROLL_SELECT``: relative rotation (contact frame) ↦ xi_cf_dot,
            (n, 2, 3).
        H_cf_dot_w: ``H_cf_dot w``, the part of xi_cf_ddot that does not come from the
            rate of w, (n, 2).
        sliding_velocity: ``M_cf xi_cf_dot``: velocity of the contact point over the
            fingertip, components along (rho1, rho2) of the contact frame, (n, 2), m/s.
        frame_angular_velocity: ``Omega`` with ``d/dt R_contact_to_fingertip = R_fc (Omega×)``,
            contact-frame components, (n, 3), rad/s.
    """

    xi_cf_dot: np.ndarray
    xi_co_dot: np.ndarray
    psi_dot: np.ndarray
    H_cf: np.ndarray
    H_cf_dot_w: np.ndarray
    sliding_velocity: np.ndarray
    frame_angular_velocity: np.ndarray


class ContactStack:
    """All contacts of a grasp, evaluated together.

    The formulas of :class:`ContactPair` on arrays with a leading contact axis: one numpy
    call per term instead of one per contact.

    The fingertips are spheres (as for :class:`ContactPair`), so ``c(xi_cf) = R n(xi_cf)``
    and ``K_cf = I / R`` is constant (``K_cf_dot = 0``); on flat object surfaces
    ``K_co = T_co = 0``, and those terms are skipped.

    Args:
        contacts: The contact pairs, in the grasp's contact order.
    """

    def __init__(self, contacts: Sequence[ContactPair]) -> None:
        self.fingertips = SphereStack([contact.fingertip for contact in contacts])
        self.object_surfaces = stack_surfaces([contact.object_surface for contact in contacts])
        self._K_cf = self.fingertips.curvature(np.zeros((len(contacts), 2)))
        # Flat object surfaces: A = K_cf + R_psi K_co R_psi = K_cf, a constant.
        self._A_inv_flat = np.linalg.inv(self._K_cf)

    def geometry(
        self,
        p_fingertip_in_palm: np.ndarray,
        R_fingertip_to_palm: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
    ) -> StackedContactGeometry:
        """Compute :meth:`ContactPair.geometry` of every contact.

        Args:
            p_fingertip_in_palm: Fingertip sphere centres, (n, 3), m.
            R_fingertip_to_palm: Fingertip orientations, (n, 3, 3).
            p_object_in_palm: Object centre of mass, (3,), m.
            R_object_to_palm: Object orientation, (3, 3).
        """
        # Rows of (p_f - p_o) R_o are R_o^T (p_f,i - p_o): the sphere centres in the object frame.
        p_centre_in_object = (p_fingertip_in_palm - p_object_in_palm) @ R_object_to_palm
        xi_co, distance = self.object_surfaces.closest_point(p_centre_in_object)
        R_object_contact_to_palm = R_object_to_palm @ self.object_surfaces.frame(xi_co)
        xi_cf, psi, R_contact_to_fingertip = fingertip_contact_frames(
            R_fingertip_to_palm.transpose(0, 2, 1) @ R_object_contact_to_palm
        )
        R_contact_to_palm = R_fingertip_to_palm @ R_contact_to_fingertip
        # On a sphere c(xi) = R n(xi): the contact point is R along the contact normal.
        p_contact_in_palm = (
            p_fingertip_in_palm + self.fingertips.radius[:, None] * R_contact_to_palm[:, :, 2]
        )
        return StackedContactGeometry(
            xi_cf=xi_cf,
            xi_co=xi_co,
            psi=psi,
            penetration=self.fingertips.radius - distance,
            p_contact_in_palm=p_contact_in_palm,
            R_contact_to_palm=R_contact_to_palm,
            R_contact_to_fingertip=R_contact_to_fingertip,
        )

    def kinematics(
        self,
        p_fingertip_in_palm: np.ndarray,
        R_fingertip_to_palm: np.ndarray,
        twist_fingertip: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        twist_object: np.ndarray,
    ) -> tuple[StackedContactGeometry, StackedRollingRates]:
        """:meth:`geometry` and the :meth:`rolling_rates` of the hand and object's motion.

        The relative rotation in each contact frame is ``R_cp,i (w_f,i - w_o)``.

        Args:
            p_fingertip_in_palm: Fingertip sphere centres, (n, 3), m.
            R_fingertip_to_palm: Fingertip orientations, (n, 3, 3).
            twist_fingertip: Fingertip twists ``(v_f, w_f)``, (n, 6), palm frame.
            p_object_in_palm: Object centre of mass, (3,), m.
            R_object_to_palm: Object orientation, (3, 3).
            twist_object: Object twist ``(v_o, w_o)``, (6,), palm frame.
        """
        geometry = self.geometry(
            p_fingertip_in_palm, R_fingertip_to_palm, p_object_in_palm, R_object_to_palm
        )
        w_relative = twist_fingertip[:, 3:] - twist_object[3:]
        # Rows w_rel,i^T R_pc,i = (R_cp,i w_rel,i)^T.
        w_in_contact = (w_relative[:, None, :] @ geometry.R_contact_to_palm).reshape(-1, 3)
        return geometry, self.rolling_rates(geometry, w_in_contact)

    def rolling_rates(
        self, geometry: StackedContactGeometry, w_relative_in_contact: np.ndarray
    ) -> StackedRollingRates:
        """:meth:`ContactPair.rolling_rates` of every contact, and ``H_cf_dot w``.

        ``H_cf_dot w`` follows :meth:`ContactPair.H_cf_rate` applied to w: with diagonal
        metrics and ``d/dt A^-1 = -A^-1 A_dot A^-1``,

            H_cf_dot w = -(M_cf_dot xi_cf_dot + A^-1 A_dot M_cf xi_cf_dot) / M_cf   (entrywise)
            A_dot = R_psi_dot K_co R_psi + R_psi K_co_dot R_psi + R_psi K_co R_psi_dot

        The fingertip frame turns along the surface as ``d/dt R_fc = R_fc (Omega×)``; from
        the definitions of K and T (surfaces module: ``dn/dt = [rho1, rho2] K M xi_dot``
        in the tangent plane, ``rho2 · d rho1/dt = T M xi_dot``),

            Omega = (-(K_cf M_cf xi_cf_dot)_2, (K_cf M_cf xi_cf_dot)_1, T_cf M_cf xi_cf_dot)

        Args:
            geometry: The contacts' geometry.
            w_relative_in_contact: ``R_cp (w_f - w_o)`` per contact, (n, 3), rad/s.
        """
        xi_cf, xi_co = geometry.xi_cf, geometry.xi_co
        w = w_relative_in_contact
        flat = self.object_surfaces.flat
        R_psi = _reflections(geometry.psi)
        M_cf = self.fingertips.metric(xi_cf)
        if flat:
            A_inv = self._A_inv_flat
        else:
            K_co = self.object_surfaces.curvature(xi_co)
            A_inv = _inverse_2x2(self._K_cf + R_psi @ K_co @ R_psi)
        # sliding = A^-1 [-w_y, w_x] = M_cf xi_cf_dot, and R_psi sliding = M_co xi_co_dot.
        sliding = matvec(A_inv, w @ ROLL_SELECT.T)
        sliding_on_object = matvec(R_psi, sliding)
        xi_cf_dot = sliding / M_cf
        xi_co_dot = sliding_on_object / self.object_surfaces.metric(xi_co)
        torsion_cf = np.einsum('ki,ki->k', self.fingertips.torsion(xi_cf), sliding)
        psi_dot = w[:, 2] + torsion_cf
        if not flat:
            psi_dot = psi_dot + np.einsum(
                'ki,ki->k', self.object_surfaces.torsion(xi_co), sliding_on_object
            )
        H_cf_dot_w = -self.fingertips.metric_rate(xi_cf, xi_cf_dot) * xi_cf_dot / M_cf
        if not flat:
            s, c = np.sin(geometry.psi), np.cos(geometry.psi)
            R_psi_dot = psi_dot[:, None, None] * np.array([[-s, -c], [-c, s]]).transpose(2, 0, 1)
            K_co_dot = self.object_surfaces.curvature_rate(xi_co, xi_co_dot)
            A_dot = R_psi_dot @ K_co @ R_psi + R_psi @ K_co_dot @ R_psi + R_psi @ K_co @ R_psi_dot
            H_cf_dot_w = H_cf_dot_w - matvec(A_inv, matvec(A_dot, sliding)) / M_cf
        K_sliding = matvec(self._K_cf, sliding)
        return StackedRollingRates(
            xi_cf_dot=xi_cf_dot,
            xi_co_dot=xi_co_dot,
            psi_dot=psi_dot,
            H_cf=(A_inv @ ROLL_SELECT) / M_cf[:, :, None],
            H_cf_dot_w=H_cf_dot_w,
            sliding_velocity=sliding,
            frame_angular_velocity=np.array([-K_sliding[:, 1], K_sliding[:, 0], torsion_cf]).T,
        )

    def object_rate_terms(
        self, geometry: StackedContactGeometry, rates: StackedRollingRates
    ) -> tuple[np.ndarray, np.ndarray]:
        """How the object coordinates' second derivative follows from the fingertip's.

        Montana's equations give both sides the sliding velocity,
        ``M_co xi_co_dot = R_psi M_cf xi_cf_dot``; differentiated,

            xi_co_ddot = M_co^-1 R_psi M_cf xi_cf_ddot
                         + M_co^-1 (R_psi_dot M_cf xi_cf_dot + R_psi M_cf_dot xi_cf_dot
                                    - M_co_dot xi_co_dot)

        Evaluated only when asked for (a barrier on the object surface), not every tick.

        Returns:
            ``M_co^-1 R_psi M_cf`` (n, 2, 2) and the second term (n, 2).
        """
        xi_cf, xi_co, psi = geometry.xi_cf, geometry.xi_co, geometry.psi
        s, c = np.sin(psi), np.cos(psi)
        R_psi = np.array([[c, -s], [-s, -c]]).transpose(2, 0, 1)
        R_psi_dot = rates.psi_dot[:, None, None] * np.array([[-s, -c], [-c, s]]).transpose(
            2, 0, 1
        )
        M_cf = self.fingertips.metric(xi_cf)
        M_co = self.object_surfaces.metric(xi_co)
        bias = (
            matvec(R_psi_dot, rates.sliding_velocity)
            + matvec(R_psi, self.fingertips.metric_rate(xi_cf, rates.xi_cf_dot) * rates.xi_cf_dot)
            - self.object_surfaces.metric_rate(xi_co, rates.xi_co_dot) * rates.xi_co_dot
        ) / M_co
        return R_psi * M_cf[:, None, :] / M_co[:, :, None], bias


def object_terms(
    rigid_object: Any, R_object_to_palm: np.ndarray, twist: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return ``(M_o, M_o^-1, C_o x_o_dot)`` in palm coordinates, by numpy products.

    The formulas of :mod:`grasp_safety_filter.model.object_kernel`.
    """
    R = np.asarray(R_object_to_palm, dtype=float)
    M_o, M_o_inverse = np.zeros((6, 6)), np.zeros((6, 6))
    M_o[:3, :3] = rigid_object.mass * np.eye(3)
    M_o_inverse[:3, :3] = np.eye(3) / rigid_object.mass
    M_o[3:, 3:] = R @ rigid_object.inertia_in_body @ R.T
    M_o_inverse[3:, 3:] = R @ np.linalg.inv(rigid_object.inertia_in_body) @ R.T
    w = np.asarray(twist, dtype=float)[3:]
    return M_o, M_o_inverse, np.concatenate((np.zeros(3), np.cross(w, M_o[3:, 3:] @ w)))


def staged_state(
    model: Any,
    t: float,
    q: np.ndarray,
    dq: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    contacts: ContactStack | None = None,
) -> GraspState:
    """Every model term at one instant, stage by stage, with numpy contact kinematics.

    Hand terms (Pinocchio, :meth:`HandModel.terms`), the contacts' geometry and rolling rates
    (:class:`ContactStack`, of ``model.contacts`` unless given), the object's terms
    (:func:`object_terms`), then the contact dynamics' two compiled passes around
    the solve of ``B_ho`` (:mod:`grasp_safety_filter.model.dynamics_kernel`, whose own
    oracle is :mod:`numpy_model_terms`).
    """
    m = model.n_joints
    model.bind_contacts(q, p_object_in_palm, R_object_to_palm)
    contacts = ContactStack(model.contacts) if contacts is None else contacts
    torsion, compliance = model.soft_finger, model.torsional_compliance
    q, dq = np.array(q, dtype=float), np.array(dq, dtype=float)
    p_o, R_o = np.array(p_object_in_palm, dtype=float), np.array(R_object_to_palm, dtype=float)
    twist_o = np.array(twist_object, dtype=float)
    hand = model.hand.terms(q, dq)
    p_f, R_pf, J_s = hand.p_fingertip_in_palm, hand.R_fingertip_to_palm, hand.J_fingertip
    geometry, rates = contacts.kinematics(p_f, R_pf, hand.twist_fingertip, p_o, R_o, twist_o)
    R_pc = geometry.R_contact_to_palm
    rigid_object = model.object
    M_o, M_o_inverse, C_o_twist = object_terms(rigid_object, R_o, twist_o)
    w_e = rigid_object.external_wrench()
    spans = model.hand.branches
    (
        J_h, G, Jh_dot_dq, G_dot_T_twist, B_ho, force_rhs, ddq, M_h_inv_J_hT, M_o_inv_G,
        x_ddot_free, w_c, w_relative,
    ) = velocity_terms(
        J_s, hand.twist_fingertip, hand.J_fingertip_dot_dq, p_f, hand.M_h_inverse,
        hand.h_bias, p_o, twist_o, M_o_inverse, C_o_twist, w_e,
        geometry.p_contact_in_palm, R_pc, rates.H_cf, rates.H_cf_dot_w,
        rates.sliding_velocity, rates.frame_angular_velocity, *spans, torsion,
    )
    force = contact_wrench(B_ho, force_rhs, torsion, compliance)
    ddq, x_ddot, xi_ddot = acceleration_terms(
        force, ddq, M_h_inv_J_hT, M_o_inv_G, x_ddot_free, w_c, w_relative, J_s,
        hand.J_fingertip_dot_dq, R_pc, rates.H_cf, rates.H_cf_dot_w, *spans,
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
