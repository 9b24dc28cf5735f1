"""Compiled contact kernels of spherical fingertips rolling on a sphere object.

The object is a sphere of radius ``R_o`` about its frame's origin
(:class:`~grasp_safety_filter.model.surfaces.SphereSurface`), in a chart turned per contact
(``C = R_chart_to_object``): ``c_o(a, b) = R_o C (-cos a cos b, sin a, -cos a sin b)``, with
``M_co = diag(R_o, R_o cos a)``, ``K_co = I / R_o``, ``T_co = (0, -tan(a) / R_o)``. The
fingertips are spheres of radius R in the paper's chart, as in
:mod:`grasp_safety_filter.model.rolling_kernels`, whose per-contact helpers these kernels
share; the outputs are those of
:func:`~grasp_safety_filter.model.rolling_kernels.sphere_on_plane_contacts`, in the same
order (Montana's rolling equations in closed form).
"""

from __future__ import annotations

import math

import numpy as np

from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.rolling_kernels import (
    contact_on_object_surface,
    relative_rotation_in_contact,
)


@kernel
def sphere_on_sphere_geometry(
    p_fingertip_in_palm: np.ndarray,
    R_fingertip_to_palm: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    R_chart_to_object: np.ndarray,
    object_radius: np.ndarray,
    radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Contact geometry of spherical fingertips on a sphere object.

    Per contact: the fingertip centre in the object frame ``p = R_po^T (p_f - p_o)``, its
    distance ``d = |p|`` from the object's centre and direction in the chart
    ``n = C^T p / d``; the radial projection's coordinates (the chart's inverse Gauss map)

        xi_co = (a_o, b_o) = (asin n_y, atan2(-n_z, -n_x))

    the object's Gauss frame there ``C [rho1, rho2, n](a_o, b_o)`` (object frame), and
    through :func:`~grasp_safety_filter.model.rolling_kernels.contact_on_object_surface`
    ``xi_cf``, psi, ``R_fc``, ``R_pc`` and the contact point; the penetration is
    ``R - (d - R_o)``.

    Args:
        p_fingertip_in_palm: Fingertip sphere centres, (n, 3), m.
        R_fingertip_to_palm: Fingertip frame orientations, (n, 3, 3).
        p_object_in_palm: Object centre (its centre of mass), (3,), m.
        R_object_to_palm: Object orientation, (3, 3).
        R_chart_to_object: Each contact's chart C of the object sphere, (n, 3, 3).
        object_radius: The object's radius R_o per contact, (n,), m.
        radius: Fingertip radii, (n,), m.

    Returns:
        ``xi_cf`` (n, 2), ``xi_co`` (n, 2), ``psi`` (n,), ``penetration`` (n,),
        ``p_contact_in_palm`` (n, 3), ``R_contact_to_palm`` (n, 3, 3),
        ``R_contact_to_fingertip`` (n, 3, 3).

    Raises:
        ValueError: A fingertip centre is the object's centre (no direction to project on).
    """
    n = p_fingertip_in_palm.shape[0]
    xi_cf = np.empty((n, 2))
    xi_co = np.empty((n, 2))
    psi = np.empty(n)
    penetration = np.empty(n)
    p_contact = np.empty((n, 3))
    R_pc = np.empty((n, 3, 3))
    R_fc = np.empty((n, 3, 3))
    p = np.empty(3)
    frame_in_chart = np.empty((3, 3))
    F = np.empty((3, 3))
    R_surface = np.empty((3, 3))
    M = np.empty((3, 3))
    for i in range(n):
        for r in range(3):
            total = 0.0
            for c in range(3):
                total += R_object_to_palm[c, r] * (p_fingertip_in_palm[i, c] - p_object_in_palm[c])
            p[r] = total
        distance_to_centre = math.sqrt(p[0] * p[0] + p[1] * p[1] + p[2] * p[2])
        if not distance_to_centre > 0.0:
            raise ValueError("sphere_on_sphere: a fingertip centre is the object's centre")
        C = R_chart_to_object[i]
        # The unit direction's chart components C^T (p / d).
        u_x = p[0] / distance_to_centre
        u_y = p[1] / distance_to_centre
        u_z = p[2] / distance_to_centre
        n_x = C[0, 0] * u_x + C[1, 0] * u_y + C[2, 0] * u_z
        n_y = C[0, 1] * u_x + C[1, 1] * u_y + C[2, 1] * u_z
        n_z = C[0, 2] * u_x + C[1, 2] * u_y + C[2, 2] * u_z
        a = math.asin(min(max(n_y, -1.0), 1.0))
        b = math.atan2(-n_z, -n_x)
        xi_co[i, 0], xi_co[i, 1] = a, b
        penetration[i] = radius[i] - (distance_to_centre - object_radius[i])
        sa, ca, sb, cb = math.sin(a), math.cos(a), math.sin(b), math.cos(b)
        # [rho1, rho2, n] in the chart: (sa cb, ca, sa sb), (sb, 0, -cb), (-ca cb, sa, -ca sb).
        K = frame_in_chart
        K[0, 0], K[0, 1], K[0, 2] = sa * cb, sb, -ca * cb
        K[1, 0], K[1, 1], K[1, 2] = ca, 0.0, sa
        K[2, 0], K[2, 1], K[2, 2] = sa * sb, -cb, -ca * sb
        for r in range(3):
            for c in range(3):
                F[r, c] = C[r, 0] * K[0, c] + C[r, 1] * K[1, c] + C[r, 2] * K[2, c]
        psi[i] = contact_on_object_surface(
            R_object_to_palm, F, R_fingertip_to_palm[i], p_fingertip_in_palm[i], radius[i],
            R_surface, M, xi_cf[i], R_fc[i], R_pc[i], p_contact[i],
        )
    return xi_cf, xi_co, psi, penetration, p_contact, R_pc, R_fc


@kernel
def sphere_on_sphere_rates(
    xi_cf: np.ndarray,
    xi_co: np.ndarray,
    psi: np.ndarray,
    w_relative_in_contact: np.ndarray,
    object_radius: np.ndarray,
    radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Montana's rates of spherical fingertips rolling on a sphere object, in closed form.

    With ``w = R_cp (w_f - w_o)``, the charts' metrics ``M_cf = diag(R, R cos a_f)``,
    ``M_co = diag(R_o, R_o cos a_o)``, and ``R_psi K_co R_psi = I / R_o`` (``R_psi`` is a
    reflection, ``R_psi² = I``), ``A = K_cf + R_psi K_co R_psi = I / r`` with
    ``r = R R_o / (R + R_o)``, constant, so ``A_dot = 0``:

        sliding = M_cf xi_cf_dot = r (-w_y, w_x)
        xi_cf_dot = sliding / (R, R cos a_f),   xi_co_dot = R_psi sliding / (R_o, R_o cos a_o)
        psi_dot = w_z - tan(a_f) sliding_2 / R - tan(a_o) (R_psi sliding)_2 / R_o
        H_cf = r [[0, -1 / R, 0], [1 / (R cos a_f), 0, 0]]
        H_cf_dot w = (0, tan(a_f) a_f_dot b_f_dot)
        Omega = (-sliding_2 / R, sliding_1 / R, -tan(a_f) sliding_2 / R)

    with ``R_psi = [[cos psi, -sin psi], [-sin psi, -cos psi]]``; rad/s, m/s.

    Returns:
        ``xi_cf_dot`` (n, 2), ``xi_co_dot`` (n, 2), ``psi_dot`` (n,), ``H_cf`` (n, 2, 3),
        ``H_cf_dot_w`` (n, 2), ``sliding_velocity`` (n, 2) and ``Omega`` (n, 3).
    """
    n = xi_cf.shape[0]
    xi_cf_dot = np.empty((n, 2))
    xi_co_dot = np.empty((n, 2))
    psi_dot = np.empty(n)
    H_cf = np.zeros((n, 2, 3))
    H_cf_dot_w = np.empty((n, 2))
    sliding = np.empty((n, 2))
    Omega = np.empty((n, 3))
    for i in range(n):
        R_f, R_o = radius[i], object_radius[i]
        r = R_f * R_o / (R_f + R_o)
        w_x = w_relative_in_contact[i, 0]
        w_y = w_relative_in_contact[i, 1]
        w_z = w_relative_in_contact[i, 2]
        cos_a, tan_a = math.cos(xi_cf[i, 0]), math.tan(xi_cf[i, 0])
        cos_psi, sin_psi = math.cos(psi[i]), math.sin(psi[i])
        sliding_x, sliding_y = -r * w_y, r * w_x
        a_dot, b_dot = sliding_x / R_f, sliding_y / (R_f * cos_a)
        xi_cf_dot[i, 0], xi_cf_dot[i, 1] = a_dot, b_dot
        on_object_x = cos_psi * sliding_x - sin_psi * sliding_y
        on_object_y = -sin_psi * sliding_x - cos_psi * sliding_y
        xi_co_dot[i, 0] = on_object_x / R_o
        xi_co_dot[i, 1] = on_object_y / (R_o * math.cos(xi_co[i, 0]))
        torsion_cf = -tan_a / R_f * sliding_y
        psi_dot[i] = w_z + torsion_cf - math.tan(xi_co[i, 0]) / R_o * on_object_y
        H_cf[i, 0, 1] = -r / R_f
        H_cf[i, 1, 0] = r / (R_f * cos_a)
        H_cf_dot_w[i, 0], H_cf_dot_w[i, 1] = 0.0, tan_a * a_dot * b_dot
        sliding[i, 0], sliding[i, 1] = sliding_x, sliding_y
        Omega[i, 0], Omega[i, 1], Omega[i, 2] = -sliding_y / R_f, sliding_x / R_f, torsion_cf
    return xi_cf_dot, xi_co_dot, psi_dot, H_cf, H_cf_dot_w, sliding, Omega


@kernel
def sphere_on_sphere_contacts(
    p_fingertip_in_palm: np.ndarray,
    R_fingertip_to_palm: np.ndarray,
    twist_fingertip: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    R_chart_to_object: np.ndarray,
    object_radius: np.ndarray,
    radius: np.ndarray,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
]:
    """:func:`sphere_on_sphere_geometry`, then :func:`sphere_on_sphere_rates` of the motion.

    The relative rotation in each contact frame is ``w = R_pc^T (w_f - w_o)``
    (:func:`~grasp_safety_filter.model.rolling_kernels.relative_rotation_in_contact`).

    Returns:
        The seven arrays of :func:`sphere_on_sphere_geometry`, then the seven of
        :func:`sphere_on_sphere_rates`.
    """
    xi_cf, xi_co, psi, penetration, p_contact, R_pc, R_fc = sphere_on_sphere_geometry(
        p_fingertip_in_palm,
        R_fingertip_to_palm,
        p_object_in_palm,
        R_object_to_palm,
        R_chart_to_object,
        object_radius,
        radius,
    )
    w = relative_rotation_in_contact(twist_fingertip, twist_object, R_pc)
    xi_cf_dot, xi_co_dot, psi_dot, H_cf, H_cf_dot_w, sliding, Omega = sphere_on_sphere_rates(
        xi_cf, xi_co, psi, w, object_radius, radius
    )
    return (
        xi_cf, xi_co, psi, penetration, p_contact, R_pc, R_fc,
        xi_cf_dot, xi_co_dot, psi_dot, H_cf, H_cf_dot_w, sliding, Omega,
    )
