"""All rolling contacts of a grasp at once: Montana's kinematics on stacked arrays.

The formulas of :mod:`grasp_safety_filter.model.rolling`, evaluated for the n contacts of a
grasp together along a leading contact axis (one call per tick instead of one per contact).
:mod:`grasp_safety_filter.model.closed_form_stacks` evaluates them in compiled closed forms
for spherical fingertips on flat faces or on a sphere, and picks the evaluation for a grasp's
contacts (:func:`~grasp_safety_filter.model.closed_form_stacks.contact_stack`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grasp_safety_filter.model.arrays import matvec
from grasp_safety_filter.model.rolling import ContactPair, ROLL_SELECT
from grasp_safety_filter.model.rolling_kernels import fingertip_contact_frames
from grasp_safety_filter.model.surface_stacks import SphereStack, stack_surfaces


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
