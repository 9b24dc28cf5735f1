"""Compiled per-contact kernels of the rolling contacts (:mod:`grasp_safety_filter.model.rolling`).

Spherical fingertips in the paper's chart (:class:`~grasp_safety_filter.model.surfaces.
SphereSurface`, ``c(a, b) = R (-cos a cos b, sin a, -cos a sin b)``), evaluated contact by
contact in compiled loops (:mod:`grasp_safety_filter.model.compiled`): a few float
operations per contact, where numpy would spend a call of ~1 µs on each array of three.
"""

from __future__ import annotations

import math

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def _fingertip_frame(
    R_object_contact_to_fingertip: np.ndarray,
    xi_cf: np.ndarray,
    R_contact_to_fingertip: np.ndarray,
) -> float:
    """One contact of :func:`fingertip_contact_frames`; writes ``xi_cf``, ``R_fc``; returns psi."""
    M = R_object_contact_to_fingertip
    # The fingertip's outward normal is the opposite of the object's (M's third column).
    a = math.asin(min(max(-M[1, 2], -1.0), 1.0))
    b = math.atan2(M[2, 2], M[0, 2])
    sa, ca, sb, cb = math.sin(a), math.cos(a), math.sin(b), math.cos(b)
    rho1_x, rho1_y, rho1_z = sa * cb, ca, sa * sb
    xi_cf[0] = a
    xi_cf[1] = b
    # The Gauss frame [rho1, rho2, n]: rho2 = (sb, 0, -cb), n = (-ca cb, sa, -ca sb).
    R = R_contact_to_fingertip
    R[0, 0], R[0, 1], R[0, 2] = rho1_x, sb, -ca * cb
    R[1, 0], R[1, 1], R[1, 2] = rho1_y, 0.0, sa
    R[2, 0], R[2, 1], R[2, 2] = rho1_z, -cb, -ca * sb
    # psi = atan2(-rho1 · y_o, rho1 · x_o), x_o and y_o M's first two columns.
    return math.atan2(
        -(rho1_x * M[0, 1] + rho1_y * M[1, 1] + rho1_z * M[2, 1]),
        rho1_x * M[0, 0] + rho1_y * M[1, 0] + rho1_z * M[2, 0],
    )


@kernel
def fingertip_contact_frames(
    R_object_contact_to_fingertip: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Find where spherical fingertips touch the object surfaces.

    From the object surfaces' Gauss frames at the contacts, in the fingertip frames
    (k, 3, 3): the fingertip normal is the opposite of the object's, ``xi_cf`` its inverse
    Gauss map (``a = asin(n_y)``, ``b = atan2(-n_z, -n_x)``), the contact frame the
    sphere's Gauss frame there, and ``psi = atan2(-x_c · y_o, x_c · x_o)``.

    Returns:
        ``xi_cf`` (k, 2), rad; ``psi`` (k,), rad; ``R_contact_to_fingertip`` (k, 3, 3).
    """
    k = R_object_contact_to_fingertip.shape[0]
    xi_cf = np.empty((k, 2))
    psi = np.empty(k)
    R_contact_to_fingertip = np.empty((k, 3, 3))
    for i in range(k):
        psi[i] = _fingertip_frame(
            R_object_contact_to_fingertip[i], xi_cf[i], R_contact_to_fingertip[i]
        )
    return xi_cf, psi, R_contact_to_fingertip


@kernel
def contact_on_object_surface(
    R_object_to_palm: np.ndarray,
    R_object_contact_to_object: np.ndarray,
    R_fingertip_to_palm: np.ndarray,
    p_fingertip_in_palm: np.ndarray,
    radius: float,
    R_object_contact_to_palm: np.ndarray,
    R_object_contact_to_fingertip: np.ndarray,
    xi_cf: np.ndarray,
    R_contact_to_fingertip: np.ndarray,
    R_contact_to_palm: np.ndarray,
    p_contact_in_palm: np.ndarray,
) -> float:
    """One fingertip's contact frame, from the object surface's Gauss frame at the contact.

    ``R_po F`` is the surface's frame in the palm (``F = R_object_contact_to_object``), ``M =
    R_pf^T R_po F`` in the fingertip; :func:`fingertip_contact_frames` of M gives ``xi_cf``,
    ``R_fc`` and psi; then ``R_pc = R_pf R_fc`` and the contact point ``p_f + R n_c`` (on a
    sphere the contact point is R along the contact normal).

    Args:
        R_object_to_palm: Object orientation, (3, 3).
        R_object_contact_to_object: The surface's ``[rho1, rho2, n]`` at the contact, object
            frame, (3, 3).
        R_fingertip_to_palm: The fingertip's orientation, (3, 3).
        p_fingertip_in_palm: Its sphere centre, (3,), m.
        radius: Its radius, m.
        R_object_contact_to_palm: Scratch, (3, 3): ``R_po F`` on return.
        R_object_contact_to_fingertip: Scratch, (3, 3): M on return.
        xi_cf: Written: the fingertip coordinates, (2,), rad.
        R_contact_to_fingertip: Written: ``R_fc``, (3, 3).
        R_contact_to_palm: Written: ``R_pc``, (3, 3).
        p_contact_in_palm: Written: the contact point, (3,), m.

    Returns:
        psi, rad.
    """
    F = R_object_contact_to_object
    R_plane = R_object_contact_to_palm
    M = R_object_contact_to_fingertip
    for r in range(3):
        for c in range(3):
            R_plane[r, c] = (
                R_object_to_palm[r, 0] * F[0, c]
                + R_object_to_palm[r, 1] * F[1, c]
                + R_object_to_palm[r, 2] * F[2, c]
            )
    R_f = R_fingertip_to_palm
    for r in range(3):
        for c in range(3):
            M[r, c] = (
                R_f[0, r] * R_plane[0, c]
                + R_f[1, r] * R_plane[1, c]
                + R_f[2, r] * R_plane[2, c]
            )
    psi = _fingertip_frame(M, xi_cf, R_contact_to_fingertip)
    R_fc = R_contact_to_fingertip
    for r in range(3):
        for c in range(3):
            R_contact_to_palm[r, c] = (
                R_f[r, 0] * R_fc[0, c] + R_f[r, 1] * R_fc[1, c] + R_f[r, 2] * R_fc[2, c]
            )
        p_contact_in_palm[r] = p_fingertip_in_palm[r] + radius * R_contact_to_palm[r, 2]
    return psi


@kernel
def relative_rotation_in_contact(
    twist_fingertip: np.ndarray, twist_object: np.ndarray, R_contact_to_palm: np.ndarray
) -> np.ndarray:
    """``w = R_pc^T (w_f - w_o)`` per contact, (n, 3), rad/s.

    With ``w_f = twist_fingertip[:, 3:]`` (n, 3) and ``w_o = twist_object[3:]`` (palm frame).
    """
    R_pc = R_contact_to_palm
    n = R_pc.shape[0]
    w = np.empty((n, 3))
    for i in range(n):
        w_x = twist_fingertip[i, 3] - twist_object[3]
        w_y = twist_fingertip[i, 4] - twist_object[4]
        w_z = twist_fingertip[i, 5] - twist_object[5]
        for c in range(3):
            w[i, c] = R_pc[i, 0, c] * w_x + R_pc[i, 1, c] * w_y + R_pc[i, 2, c] * w_z
    return w


@kernel
def sphere_on_plane_geometry(
    p_fingertip_in_palm: np.ndarray,
    R_fingertip_to_palm: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    plane_origin: np.ndarray,
    plane_frame: np.ndarray,
    radius: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Contact geometry of spherical fingertips on planes of the object.

    Per contact: the sphere centre in the object frame ``p = R_po^T (p_f - p_o)``, its
    in-plane coordinates and height ``[e1, e2, n]^T (p - origin) = (xi_co, distance)``, the
    plane's frame in the palm ``R_po [e1, e2, n]`` and, through
    :func:`fingertip_contact_frames`, ``xi_cf``, ``psi``, ``R_fc``; ``R_pc = R_pf R_fc``,
    the contact point ``p_f + R n_c`` and the penetration ``R - distance``.

    Args:
        p_fingertip_in_palm: Fingertip sphere centres, (n, 3), m.
        R_fingertip_to_palm: Fingertip frame orientations, (n, 3, 3).
        p_object_in_palm: Object centre of mass, (3,), m.
        R_object_to_palm: Object orientation, (3, 3).
        plane_origin: Each plane's origin in the object frame, (n, 3), m.
        plane_frame: Each plane's ``[e1, e2, n]`` in the object frame, (n, 3, 3).
        radius: Fingertip radii, (n,), m.

    Returns:
        ``xi_cf`` (n, 2), ``xi_co`` (n, 2), ``psi`` (n,), ``penetration`` (n,),
        ``p_contact_in_palm`` (n, 3), ``R_contact_to_palm`` (n, 3, 3),
        ``R_contact_to_fingertip`` (n, 3, 3).
    """
    n = p_fingertip_in_palm.shape[0]
    xi_cf = np.empty((n, 2))
    xi_co = np.empty((n, 2))
    psi = np.empty(n)
    penetration = np.empty(n)
    p_contact = np.empty((n, 3))
    R_pc = np.empty((n, 3, 3))
    R_fc = np.empty((n, 3, 3))
    offset = np.empty(3)
    R_plane = np.empty((3, 3))
    M = np.empty((3, 3))
    for i in range(n):
        # p - origin, with p = R_po^T (p_f - p_o).
        for r in range(3):
            total = 0.0
            for c in range(3):
                total += R_object_to_palm[c, r] * (p_fingertip_in_palm[i, c] - p_object_in_palm[c])
            offset[r] = total - plane_origin[i, r]
        F = plane_frame[i]
        for j in range(2):
            xi_co[i, j] = F[0, j] * offset[0] + F[1, j] * offset[1] + F[2, j] * offset[2]
        distance = F[0, 2] * offset[0] + F[1, 2] * offset[1] + F[2, 2] * offset[2]
        penetration[i] = radius[i] - distance
        psi[i] = contact_on_object_surface(
            R_object_to_palm, plane_frame[i], R_fingertip_to_palm[i], p_fingertip_in_palm[i],
            radius[i], R_plane, M, xi_cf[i], R_fc[i], R_pc[i], p_contact[i],
        )
    return xi_cf, xi_co, psi, penetration, p_contact, R_pc, R_fc


@kernel
def sphere_on_plane_rates(
    xi_cf: np.ndarray, psi: np.ndarray, w_relative_in_contact: np.ndarray, radius: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Montana's rates of spherical fingertips rolling on planes, in closed form.

    With ``w = R_cp (w_f - w_o)`` and the sphere chart's ``M_cf = diag(R, R cos a)``,
    ``K_cf = I / R``, ``T_cf = (0, -tan(a) / R)`` on a plane (``M_co = I``, ``K_co = 0``):

        sliding = M_cf xi_cf_dot = R (-w_y, w_x)
        xi_cf_dot = (-w_y, w_x / cos a),      xi_co_dot = R_psi sliding
        psi_dot = w_z - tan(a) w_x
        H_cf = [[0, -1, 0], [1 / cos a, 0, 0]],   H_cf_dot w = (0, tan(a) a_dot b_dot)
        Omega = (-w_x, -w_y, -tan(a) w_x)

    with ``R_psi = [[cos psi, -sin psi], [-sin psi, -cos psi]]``.

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
        a = xi_cf[i, 0]
        w_x = w_relative_in_contact[i, 0]
        w_y = w_relative_in_contact[i, 1]
        w_z = w_relative_in_contact[i, 2]
        cos_a, tan_a = math.cos(a), math.tan(a)
        cos_psi, sin_psi = math.cos(psi[i]), math.sin(psi[i])
        sliding_x, sliding_y = -radius[i] * w_y, radius[i] * w_x
        a_dot, b_dot = -w_y, w_x / cos_a
        xi_cf_dot[i, 0], xi_cf_dot[i, 1] = a_dot, b_dot
        xi_co_dot[i, 0] = cos_psi * sliding_x - sin_psi * sliding_y
        xi_co_dot[i, 1] = -sin_psi * sliding_x - cos_psi * sliding_y
        psi_dot[i] = w_z - tan_a * w_x
        H_cf[i, 0, 1] = -1.0
        H_cf[i, 1, 0] = 1.0 / cos_a
        H_cf_dot_w[i, 0], H_cf_dot_w[i, 1] = 0.0, tan_a * a_dot * b_dot
        sliding[i, 0], sliding[i, 1] = sliding_x, sliding_y
        Omega[i, 0], Omega[i, 1], Omega[i, 2] = -w_x, -w_y, -tan_a * w_x
    return xi_cf_dot, xi_co_dot, psi_dot, H_cf, H_cf_dot_w, sliding, Omega


@kernel
def sphere_on_plane_contacts(
    p_fingertip_in_palm: np.ndarray,
    R_fingertip_to_palm: np.ndarray,
    twist_fingertip: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    plane_origin: np.ndarray,
    plane_frame: np.ndarray,
    radius: np.ndarray,
) -> tuple[
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
    np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray,
]:
    """:func:`sphere_on_plane_geometry`, then :func:`sphere_on_plane_rates` of the motion.

    The relative rotation in each contact frame is ``w = R_pc^T (w_f - w_o)``, with the
    angular velocities ``w_f = twist_fingertip[:, 3:]`` (n, 3) and ``w_o = twist_object[3:]``
    (palm frame, rad/s).

    Returns:
        The seven arrays of :func:`sphere_on_plane_geometry`, then the seven of
        :func:`sphere_on_plane_rates`.
    """
    xi_cf, xi_co, psi, penetration, p_contact, R_pc, R_fc = sphere_on_plane_geometry(
        p_fingertip_in_palm,
        R_fingertip_to_palm,
        p_object_in_palm,
        R_object_to_palm,
        plane_origin,
        plane_frame,
        radius,
    )
    w = relative_rotation_in_contact(twist_fingertip, twist_object, R_pc)
    xi_cf_dot, xi_co_dot, psi_dot, H_cf, H_cf_dot_w, sliding, Omega = sphere_on_plane_rates(
        xi_cf, psi, w, radius
    )
    return (
        xi_cf, xi_co, psi, penetration, p_contact, R_pc, R_fc,
        xi_cf_dot, xi_co_dot, psi_dot, H_cf, H_cf_dot_w, sliding, Omega,
    )


@kernel
def object_coordinate_rate_terms(
    xi_cf: np.ndarray,
    xi_co: np.ndarray,
    psi: np.ndarray,
    xi_cf_dot: np.ndarray,
    xi_co_dot: np.ndarray,
    psi_dot: np.ndarray,
    sliding_velocity: np.ndarray,
    radius: np.ndarray,
    object_radius: np.ndarray,
    flat: bool,
) -> tuple[np.ndarray, np.ndarray]:
    """How the object coordinates' second derivative follows from the fingertip's.

    Montana's equations give both sides the sliding velocity, ``M_co xi_co_dot = R_psi M_cf
    xi_cf_dot``; differentiated, per contact,

        xi_co_ddot = A xi_cf_ddot + c,        A = M_co^-1 R_psi M_cf
        c = M_co^-1 (R_psi_dot sliding + R_psi M_cf_dot xi_cf_dot - M_co_dot xi_co_dot)

    with ``M_cf = diag(R, R cos a_f)``, ``M_cf_dot = diag(0, -R sin(a_f) a_f_dot)``,
    ``R_psi = [[c, -s], [-s, -c]]`` and ``R_psi_dot = psi_dot [[-s, -c], [-c, s]]``. A flat
    face's chart is Cartesian (``M_co = I``, ``M_co_dot = 0``; c in m/s²); a sphere object's
    is ``M_co = diag(R_o, R_o cos a_o)`` (c in rad/s²).

    Args:
        xi_cf: Fingertip contact coordinates, (n, 2), rad.
        xi_co: Object contact coordinates, (n, 2) (m on a face, rad on a sphere).
        psi: Angle between the surfaces' first tangent axes, (n,), rad.
        xi_cf_dot: Their rates, (n, 2), rad/s.
        xi_co_dot: Their rates, (n, 2).
        psi_dot: Its rate, (n,), rad/s.
        sliding_velocity: ``M_cf xi_cf_dot``, (n, 2), m/s.
        radius: Each fingertip's radius, (n,), m.
        object_radius: The object's radius per contact, (n,), m (not read when ``flat``).
        flat: Whether the object surfaces are flat faces (else a sphere).

    Returns:
        ``A`` (n, 2, 2) and ``c`` (n, 2).
    """
    n = radius.shape[0]
    A = np.empty((n, 2, 2))
    bias = np.empty((n, 2))
    for i in range(n):
        R_f, a_f = radius[i], xi_cf[i, 0]
        s, c = math.sin(psi[i]), math.cos(psi[i])
        M_cf_x, M_cf_y = R_f, R_f * math.cos(a_f)
        if flat:
            M_co_x, M_co_y, object_y = 1.0, 1.0, 0.0
        else:
            R_o, a_o = object_radius[i], xi_co[i, 0]
            M_co_x, M_co_y = R_o, R_o * math.cos(a_o)
            object_y = -R_o * math.sin(a_o) * xi_co_dot[i, 0] * xi_co_dot[i, 1]
        # M_cf_dot xi_cf_dot and M_co_dot xi_co_dot: only their second entries are nonzero.
        fingertip_y = -R_f * math.sin(a_f) * xi_cf_dot[i, 0] * xi_cf_dot[i, 1]
        sliding_x, sliding_y = sliding_velocity[i, 0], sliding_velocity[i, 1]
        bias[i, 0] = (psi_dot[i] * (-s * sliding_x - c * sliding_y) - s * fingertip_y) / M_co_x
        bias[i, 1] = (
            psi_dot[i] * (-c * sliding_x + s * sliding_y) - c * fingertip_y - object_y
        ) / M_co_y
        A[i, 0, 0], A[i, 0, 1] = c * M_cf_x / M_co_x, -s * M_cf_y / M_co_x
        A[i, 1, 0], A[i, 1, 1] = -s * M_cf_x / M_co_y, -c * M_cf_y / M_co_y
    return A, bias
