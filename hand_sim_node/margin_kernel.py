"""The event monitor's per-step arithmetic, compiled (:mod:`hand_sim_node.events`).

A step's margins are ~7n + 2m numbers: as numpy calls, nearly all of their cost is the
calls' own overhead. :func:`flat_margins` computes every margin and its violation flag in
one pass, for :class:`~hand_sim_node.events.EventMonitor` (numpy's ``hypot``,
``fmin``/``fmax`` semantics).
"""

from __future__ import annotations

import math

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def flat_margins(
    xi_cf: np.ndarray,
    forces: np.ndarray,
    q: np.ndarray,
    xi_co: np.ndarray,
    workspace_low: np.ndarray,
    workspace_high: np.ndarray,
    joint_lower_limits: np.ndarray,
    joint_upper_limits: np.ndarray,
    friction_coefficient: np.ndarray,
    face_half_widths: np.ndarray,
    closed: np.ndarray,
    torsion: np.ndarray,
    torsional_friction: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return every margin (7n + 2m,), ``beta`` (n,) and the violation flags (7n + 2m,).

    Args:
        xi_cf: Fingertip coordinates ``(a, b)`` per contact, (n, 2), rad.
        forces: Contact forces ``(f_x, f_y, f_n)`` per contact, (n, 3), N.
        q: Joint angles, (m,), rad.
        xi_co: Object surface coordinates per contact, (n, 2), m; (0, 2): unknown.
        workspace_low: ``(a_min, b_min)`` per contact, (n, 2), rad.
        workspace_high: ``(a_max, b_max)`` per contact, (n, 2), rad.
        joint_lower_limits: ``q_min``, (m,), rad.
        joint_upper_limits: ``q_max``, (m,), rad.
        friction_coefficient: ``mu_i``, (n,).
        face_half_widths: ``(h_u, h_v)`` per contact, (n, 2), m; (0, 2): unknown.
        closed: Margins violated at 0 (else below 0), (7n + 2m,).
        torsion: Soft fingers' torsions ``tau_i`` about the contact normals, (n,), N·m;
            (0,): point contacts, or torsions unknown.
        torsional_friction: Soft fingers' ``mu_t,i``, (n,), m; (0,): point contacts.

    Margins, family after family: workspace ``a - a_min, a_max - a, b - b_min, b_max - b``;
    joints ``q - q_min, q_max - q``; slip ``mu_i - beta_i`` with ``beta_i = |f_t| / f_n``
    (inf where ``f_n <= 0``, NaN where ``f_n`` is not finite), for soft fingers with known
    torsions ``mu_i - max(beta_i, mu_i |tau_i| / (mu_t,i f_n))`` (numpy's ``maximum``: NaN
    if either is); separation ``f_n``; object face ``min(h_u - |u|, h_v - |v|)`` (NaN if
    unknown). A NaN margin is not violated.
    """
    n, m = xi_cf.shape[0], q.shape[0]
    values = np.empty(7 * n + 2 * m)
    beta = np.empty(n)
    for i in range(n):
        for axis in range(2):
            values[4 * i + 2 * axis] = xi_cf[i, axis] - workspace_low[i, axis]
            values[4 * i + 2 * axis + 1] = workspace_high[i, axis] - xi_cf[i, axis]
    at = 4 * n
    for j in range(m):
        values[at + 2 * j] = q[j] - joint_lower_limits[j]
        values[at + 2 * j + 1] = joint_upper_limits[j] - q[j]
    at += 2 * m
    known_faces = face_half_widths.shape[0] == n and xi_co.shape[0] == n
    soft = torsion.shape[0] == n and torsional_friction.shape[0] == n
    for i in range(n):
        normal = forces[i, 2]
        if not math.isfinite(normal):
            beta[i] = np.nan
        elif normal > 0.0:
            beta[i] = np.hypot(forces[i, 0], forces[i, 1]) / normal
        else:
            beta[i] = np.inf
        slip = beta[i]
        if soft and normal > 0.0:
            # Torsion over its bound, scaled to the force cone's: mu |tau| / (mu_t f_n).
            spin = friction_coefficient[i] * abs(torsion[i]) / (torsional_friction[i] * normal)
            if not (spin <= slip or math.isnan(slip)):
                slip = spin
        values[at + i] = friction_coefficient[i] - slip
        values[at + n + i] = normal
        if known_faces:
            u = face_half_widths[i, 0] - abs(xi_co[i, 0])
            v = face_half_widths[i, 1] - abs(xi_co[i, 1])
            # numpy's minimum: NaN if either is.
            values[at + 2 * n + i] = u if (u <= v or math.isnan(u)) else v
        else:
            values[at + 2 * n + i] = np.nan
    violated = np.empty(values.shape[0], dtype=np.bool_)
    for k in range(values.shape[0]):
        violated[k] = values[k] < 0.0 or (closed[k] and values[k] == 0.0)
    return values, beta, violated
