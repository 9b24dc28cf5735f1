"""The nominal controller's per-tick arithmetic, compiled (law: :mod:`.nominal`).

Three kernels, in the order of a tick, around the three linear solves, which stay numpy's
``np.linalg.solve`` (LAPACK's dgesv as numpy links it; numba links scipy's LAPACK, whose
results can differ from numpy's in the last bit)::

    solve   M_h [X | M_h^-1 C_h dq] = [J_h^T | C_h dq]           (right-hand side: numpy)
    kernel  contact_space_terms: Lambda^-1 = J_h X, its rank check and the right-hand sides
    solve   Lambda^-1 S = [G^T | J_h M_h^-1 C_h dq + G_dot^T x_dot - J_h_dot dq | J_h a_null]
    kernel  object_wrench: u_m = M_ho x_o_ddot_des + C_ho x_o_dot - w_e, tau_null and G G^T
            (x_o_ddot_des from the pose error, :mod:`.pose_error`, outside)
    solve   (G G^T) y = u_m
    kernel  joint_torque: u_f and u = J_h^T (G^T y + u_f) + g + tau_null

Every product is ``np.dot`` on operands laid out as in the numpy expressions of the law;
numba hands them to BLAS's gemm and gemv (scipy's OpenBLAS) as numpy's ``@`` does (its own
OpenBLAS; ``G @ G.T`` by syrk), and test/test_nominal_kernel.py checks that the results are
equal to the last bit. The rank check's Cholesky factorisation is numba's (scipy's LAPACK):
a last-bit difference can only move a pivot that sits at the threshold, and the controller
checks a Lambda^-1 rejected here again with numpy's before it raises. Shapes are not checked
here (numba does not check bounds):
:class:`~grasp_safety_filter.control.nominal.NominalController` does.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def contact_space_terms(
    J_h: np.ndarray,
    solution_m: np.ndarray,
    G: np.ndarray,
    G_dot_T_twist: np.ndarray,
    Jh_dot_dq: np.ndarray,
    q: np.ndarray,
    q_posture: np.ndarray,
    dq: np.ndarray,
    null_space_kp: float,
    null_space_kd: float,
    rank_tolerance: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, bool]:
    """``Lambda^-1``, the right-hand sides of its solve, a_null, and whether J_h has full rank.

    Args:
        J_h: Hand Jacobian, (3n, m).
        solution_m: ``[M_h^-1 J_h^T | M_h^-1 C_h dq]``, (m, 3n + 1).
        G: Grasp map, (6, 3n).
        G_dot_T_twist: ``G_dot^T x_o_dot``, (3n,).
        Jh_dot_dq: ``J_h_dot dq``, (3n,).
        q: Joint angles, (m,), rad.
        q_posture: Null-space posture, (m,), rad.
        dq: Joint velocities, (m,), rad/s.
        null_space_kp: k_null,p, 1/s².
        null_space_kd: k_null,d, 1/s.
        rank_tolerance: Squared Cholesky pivot floor relative to the largest diagonal entry.

    Returns:
        ``Lambda^-1 = J_h M_h^-1 J_h^T`` (3n, 3n); the right-hand sides (3n, 7), with an
        eighth column ``J_h a_null`` for a redundant hand (m > 3n); ``a_null =
        -k_null,p (q - q_posture) - k_null,d dq`` (m,), rad/s² (zero for m = 3n); and
        whether ``Lambda^-1`` passed the Cholesky rank check.

    """
    rows, m = J_h.shape
    redundant = m > rows
    contact_inertia_inv = np.dot(J_h, np.ascontiguousarray(solution_m[:, :rows]))
    full_rank = True
    try:
        pivots = np.diag(np.linalg.cholesky(contact_inertia_inv))
        full_rank = pivots.min() ** 2 > rank_tolerance * np.diag(contact_inertia_inv).max()
    except Exception:  # numba's LinAlgError: not positive definite
        full_rank = False
    rhs = np.empty((rows, 8 if redundant else 7))
    rhs[:, :6] = G.T
    rhs[:, 6] = np.dot(J_h, np.ascontiguousarray(solution_m[:, rows])) + G_dot_T_twist - Jh_dot_dq
    a_null = np.zeros(m)
    if redundant:
        a_null = -null_space_kp * (q - q_posture) - null_space_kd * dq
        rhs[:, 7] = np.dot(J_h, a_null)
    return contact_inertia_inv, rhs, a_null, full_rank


@kernel
def object_wrench(
    x_ddot_des: np.ndarray,
    M_o: np.ndarray,
    C_o_twist: np.ndarray,
    w_e: np.ndarray,
    G: np.ndarray,
    solution: np.ndarray,
    M_h: np.ndarray,
    J_h: np.ndarray,
    a_null: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Return the object wrench u_m, the null-space torque and G G^T.

    Args:
        x_ddot_des: The desired object acceleration x_o_ddot_des, (6,), m/s² and rad/s².
        M_o: Object inertia, (6, 6).
        C_o_twist: ``C_o x_o_dot``, (6,).
        w_e: External wrench on the object, (6,), (N, N·m).
        G: Grasp map, (6, 3n).
        solution: The solution S of the ``Lambda^-1`` solve (module docstring), (3n, 7 or 8).
        M_h: Hand inertia, (m, m).
        J_h: Hand Jacobian, (3n, m).
        a_null: The null-space joint acceleration, (m,), rad/s².

    Returns:
        ``u_m`` (6,), ``tau_null`` (m,) N·m (zero for m = 3n) and ``G G^T`` (6, 6).
    """
    rows, m = J_h.shape
    M_ho = M_o + np.dot(G, np.ascontiguousarray(solution[:, :6]))
    C_ho_x_dot = C_o_twist + np.dot(G, np.ascontiguousarray(solution[:, 6]))
    u_m = np.dot(M_ho, x_ddot_des) + C_ho_x_dot - w_e
    if m > rows:
        tau_null = np.dot(M_h, a_null) - np.dot(J_h.T, np.ascontiguousarray(solution[:, 7]))
    else:
        tau_null = np.zeros(m)
    return u_m, tau_null, np.dot(G, G.T)


@kernel
def internal_force(
    p_contact_in_palm: np.ndarray, R_contact_to_palm: np.ndarray, kf: float
) -> np.ndarray:
    """Squeeze ``u_f,i = k_f (p_bar_c - p_c,i)`` in the contact frames, (3n,), N.

    Args:
        p_contact_in_palm: Contact points, (n, 3), m.
        R_contact_to_palm: Contact frames, (n, 3, 3).
        kf: Squeeze gain k_f, N/m.

    """
    n = p_contact_in_palm.shape[0]
    # The centroid summed row after row, as numpy reduces along the first axis.
    p_sum = p_contact_in_palm[0].copy()
    for i in range(1, n):
        p_sum += p_contact_in_palm[i]
    p_centroid = p_sum / n
    u_f = np.empty(3 * n)
    for i in range(n):
        # R_pc^T f = (f^T R_pc)^T: the palm-frame squeeze in contact-frame components.
        f_palm = kf * (p_centroid - p_contact_in_palm[i])
        u_f[3 * i:3 * i + 3] = np.dot(f_palm, np.ascontiguousarray(R_contact_to_palm[i]))
    return u_f


@kernel
def joint_torque(
    G: np.ndarray,
    manipulation_multiplier: np.ndarray,
    J_h: np.ndarray,
    p_contact_in_palm: np.ndarray,
    R_contact_to_palm: np.ndarray,
    kf: float,
    gravity_torque: np.ndarray,
    tau_null: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """``u = J_h^T (G^+ u_m + u_f) + g + tau_null`` and the squeeze u_f.

    Args:
        G: Grasp map, (6, 3n).
        manipulation_multiplier: ``y = (G G^T)^-1 u_m``, (6,), so that ``G^+ u_m = G^T y``.
        J_h: Hand Jacobian, (3n, m).
        p_contact_in_palm: Contact points, (n, 3), m.
        R_contact_to_palm: Contact frames, (n, 3, 3).
        kf: Squeeze gain k_f, N/m.
        gravity_torque: ``g(q)``, (m,), N·m.
        tau_null: The null-space torque, (m,), N·m.

    Returns:
        ``u`` (m,), N·m, and ``u_f`` (3n,), N, in the contact frames.

    """
    u_f = internal_force(p_contact_in_palm, R_contact_to_palm, kf)
    f_manipulation = np.dot(G.T, manipulation_multiplier)
    u = np.dot(J_h.T, f_manipulation + u_f) + gravity_torque + tau_null
    return u, u_f
