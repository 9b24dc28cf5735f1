"""Oracle (tests only): Montana's rolling kinematics of one contact, numpy.

The per-contact formulas (Murray, Li & Sastry 1994, Section 5.6; the module docstring of
:mod:`grasp_safety_filter.model.rolling`) on a :class:`~grasp_safety_filter.model.rolling.
ContactPair`'s surfaces, through their differential geometry
(:mod:`grasp_safety_filter.model.surfaces`): the reference the stacked oracle
(:mod:`model_oracles`) is checked against.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from oracle_geometry import geometry_of

from grasp_safety_filter.model.rolling import ContactGeometry, ContactPair

# [-w_y, w_x] = ROLL_SELECT @ w: the tangential components of the relative rotation.
ROLL_SELECT = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0]])


def reflection(psi: float) -> np.ndarray:
    """``R_psi = [[cos psi, -sin psi], [-sin psi, -cos psi]]`` (det = -1, its own inverse)."""
    c, s = np.cos(psi), np.sin(psi)
    return np.array([[c, -s], [-s, -c]])


def reflection_rate(psi: float, psi_dot: float) -> np.ndarray:
    """Time derivative of :func:`reflection`."""
    c, s = np.cos(psi), np.sin(psi)
    return psi_dot * np.array([[-s, -c], [-c, s]])


@dataclass(frozen=True)
class RollingRates:
    """Montana's rolling rates of one contact and the pieces the second derivative reuses."""

    xi_cf_dot: np.ndarray
    xi_co_dot: np.ndarray
    psi_dot: float
    # H_cf = M_cf^-1 A^-1 ROLL_SELECT maps the relative rotation (contact frame) to xi_cf_dot.
    H_cf: np.ndarray
    # A^-1 with A = K_cf + R_psi K_co R_psi, kept for the derivative of H_cf.
    A_inv: np.ndarray
    M_cf_inv: np.ndarray


def contact_geometry(
    pair: ContactPair,
    p_fingertip_in_palm: np.ndarray,
    R_fingertip_to_palm: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
) -> ContactGeometry:
    """Contact coordinates from the configuration.

    The object point nearest the fingertip sphere's centre fixes ``xi_co`` and the
    normal; the fingertip contact point is where the fingertip's outward normal is the
    opposite of the object's (``xi_cf`` by the inverse Gauss map).
    """
    tip, surface = geometry_of(pair.fingertip), geometry_of(pair.object_surface)
    p_centre_in_object = R_object_to_palm.T @ (p_fingertip_in_palm - p_object_in_palm)
    xi_co, distance = surface.closest_point(p_centre_in_object)
    R_object_contact_to_palm = R_object_to_palm @ surface.frame(xi_co)
    n_object_in_palm = R_object_contact_to_palm[:, 2]
    xi_cf = tip.coordinates_of_normal(-R_fingertip_to_palm.T @ n_object_in_palm)
    R_contact_to_fingertip = tip.frame(xi_cf)
    R_contact_to_palm = R_fingertip_to_palm @ R_contact_to_fingertip
    x_contact, x_object, y_object = (
        R_contact_to_palm[:, 0],
        R_object_contact_to_palm[:, 0],
        R_object_contact_to_palm[:, 1],
    )
    psi = float(np.arctan2(-x_contact @ y_object, x_contact @ x_object))
    return ContactGeometry(
        xi_cf=xi_cf,
        xi_co=xi_co,
        psi=psi,
        penetration=tip.radius - distance,
        p_contact_in_palm=(
            p_fingertip_in_palm + R_fingertip_to_palm @ tip.point(xi_cf)
        ),
        R_contact_to_palm=R_contact_to_palm,
        R_contact_to_fingertip=R_contact_to_fingertip,
    )


def rolling_rates(
    pair: ContactPair, geometry: ContactGeometry, w_relative_in_contact: np.ndarray
) -> RollingRates:
    """Montana's rates for the relative rotation ``w = R_cp (w_f - w_o)``, rad/s."""
    tip, surface = geometry_of(pair.fingertip), geometry_of(pair.object_surface)
    xi_cf, xi_co, psi = geometry.xi_cf, geometry.xi_co, geometry.psi
    R_psi = reflection(psi)
    M_cf = tip.metric(xi_cf)
    M_co = surface.metric(xi_co)
    A = tip.curvature(xi_cf) + R_psi @ surface.curvature(xi_co) @ R_psi
    A_inv = np.linalg.inv(A)
    M_cf_inv = np.diag(1.0 / np.diag(M_cf))
    rolled = A_inv @ (ROLL_SELECT @ w_relative_in_contact)
    xi_cf_dot = M_cf_inv @ rolled
    xi_co_dot = np.linalg.solve(M_co, R_psi @ rolled)
    psi_dot = (
        w_relative_in_contact[2]
        + tip.torsion(xi_cf) @ M_cf @ xi_cf_dot
        + surface.torsion(xi_co) @ M_co @ xi_co_dot
    )
    return RollingRates(
        xi_cf_dot=xi_cf_dot,
        xi_co_dot=xi_co_dot,
        psi_dot=float(psi_dot),
        H_cf=M_cf_inv @ A_inv @ ROLL_SELECT,
        A_inv=A_inv,
        M_cf_inv=M_cf_inv,
    )


def H_cf_rate(pair: ContactPair, geometry: ContactGeometry, rates: RollingRates) -> np.ndarray:
    """Time derivative of ``H_cf = M_cf^-1 (K_cf + R_psi K_co R_psi)^-1 ROLL_SELECT``.

    d/dt M^-1 = -M^-1 M_dot M^-1,   d/dt A^-1 = -A^-1 A_dot A^-1,
    A_dot = K_cf_dot + R_psi_dot K_co R_psi + R_psi K_co_dot R_psi + R_psi K_co R_psi_dot
    """
    tip, surface = geometry_of(pair.fingertip), geometry_of(pair.object_surface)
    xi_cf, xi_co, psi = geometry.xi_cf, geometry.xi_co, geometry.psi
    R_psi = reflection(psi)
    R_psi_dot = reflection_rate(psi, rates.psi_dot)
    K_co = surface.curvature(xi_co)
    A_dot = (
        tip.curvature_rate(xi_cf, rates.xi_cf_dot)
        + R_psi_dot @ K_co @ R_psi
        + R_psi @ surface.curvature_rate(xi_co, rates.xi_co_dot) @ R_psi
        + R_psi @ K_co @ R_psi_dot
    )
    M_dot = tip.metric_rate(xi_cf, rates.xi_cf_dot)
    M_inv_dot = -rates.M_cf_inv @ M_dot @ rates.M_cf_inv
    A_inv_dot = -rates.A_inv @ A_dot @ rates.A_inv
    return (M_inv_dot @ rates.A_inv + rates.M_cf_inv @ A_inv_dot) @ ROLL_SELECT
