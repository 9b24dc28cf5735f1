"""The grasp's contact dynamics at one instant, as two compiled passes.

From the hand's terms (Pinocchio), the object's and the contacts' geometry and rolling
rates, :func:`velocity_terms` and :func:`acceleration_terms` compute, on either side of the
solve of ``B_ho`` (:func:`~grasp_safety_filter.model.packed_pass.write_grasp_terms`;
DESIGN.md §3; the derivation is in
:mod:`grasp_safety_filter.model.grasp_model`), per contact i, with ``R_cp,i = R_pc,i^T``,
``p_fc,i = p_c,i - p_f,i`` and ``p_oc,i = p_c,i - p_o``:

    J_h,i = R_cp,i (J_v,i - p_fc,i × J_w,i),     G_i = [R_pc,i; p_oc,i × R_pc,i]
    w_c = w_f + R_pc Omega,   v_cf = v_f + w_f × p_fc,   v_co = v_o + w_o × p_oc,
    p_c_dot = v_cf + R_pc[:, :2] sliding
    J_h_dot dq      = R_cp (a_f0 - p_fc × alpha_f0 + w_f × (p_c_dot - v_f) - w_c × v_cf)
    G_dot^T x_o_dot = R_cp (w_o × (p_c_dot - v_o) - w_c × v_co)

With soft-finger contacts (``torsion``) each contact i also has a torsion row 3n + i, after
the 3n force rows: its wrench entry is the torque about the normal ``n_i = R_pc,i e_z`` that
the fingertip exerts on the object (N·m), and its constraint is no spin, ``n_i^T (w_f - w_o)
= 0``:

    J_h,3n+i = n_i^T J_w,i,     G_3n+i = [0; n_i]
    J_h_dot dq      = n_i^T alpha_f0 + (w_c × n_i)^T w_f
    G_dot^T x_o_dot = (w_c × n_i)^T w_o

and the torque-affine terms, as augmented matrices ``[matrix | offset]`` acting on (u, 1):

    B_ho = J_h M_h^-1 J_h^T + G^T M_o^-1 G
    B_ho f_c = J_h M_h^-1 (u - h) + J_h_dot dq - G_dot^T x_o_dot - G^T M_o^-1 (w_e - C_o x_o_dot)
    ddq = M_h^-1 (u - h - J_h^T f_c),   x_o_ddot = M_o^-1 (G f_c + w_e - C_o x_o_dot)
    xi_cf_ddot,i = H_cf,i R_cp,i (J_w,i ddq + alpha_f0,i - alpha_o - w_c × (w_f - w_o))
                   + H_cf_dot w

(soft fingers solve for ``f_c`` with compliant spin rows, or the least-squares solution of
minimum norm where rigid ones make ``B_ho`` singular:
:func:`~grasp_safety_filter.model.wrench_solve.wrench_solve`).

The sums over joints follow the hand's branches (:class:`~grasp_safety_filter.model.hand.
Branches`): row r of ``M_h^-1`` is zero outside joint r's span and contact i's rows of
``J_h`` outside its fingertip's span, so a product sums over the overlap of its factors'
spans only (none for two fingers of a hand whose fingers hang from the palm). The terms
left out are exact zeros: the answers are those of the full sums, bit for bit.
Plain loops compiled by numba (:mod:`grasp_safety_filter.model.compiled`): at these sizes
(k ≤ 16 rows, m ≤ 16 joints) two compiled passes, around LAPACK's solve of ``B_ho``, cost
less than the calls of the numpy expressions they replace. Units: SI; frames and conventions as in
:mod:`grasp_safety_filter.model.grasp_state`.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def row_contacts(n: int, k: int) -> np.ndarray:
    """Return each wrench row's contact: rows ``3i..3i+2`` and torsion row ``3n+i`` are i's."""
    contact = np.empty(k, dtype=np.intp)
    for row in range(k):
        contact[row] = row // 3 if row < 3 * n else row - 3 * n
    return contact


@kernel
def _cross(a: np.ndarray, b: np.ndarray, out: np.ndarray) -> None:
    """``out = a × b`` for 3-vectors."""
    out[0] = a[1] * b[2] - a[2] * b[1]
    out[1] = a[2] * b[0] - a[0] * b[2]
    out[2] = a[0] * b[1] - a[1] * b[0]


@kernel
def velocity_terms(
    J_fingertip: np.ndarray,
    twist_fingertip: np.ndarray,
    J_fingertip_dot_dq: np.ndarray,
    p_fingertip_in_palm: np.ndarray,
    M_h_inverse: np.ndarray,
    h_bias: np.ndarray,
    p_object_in_palm: np.ndarray,
    twist_object: np.ndarray,
    M_o_inverse: np.ndarray,
    C_o_twist: np.ndarray,
    w_e: np.ndarray,
    p_contact_in_palm: np.ndarray,
    R_contact_to_palm: np.ndarray,
    H_cf: np.ndarray,
    H_cf_dot_w: np.ndarray,
    sliding_velocity: np.ndarray,
    frame_angular_velocity: np.ndarray,
    joint_span: np.ndarray,
    fingertip_span: np.ndarray,
    torsion: bool,
) -> tuple[np.ndarray, ...]:
    """Everything up to ``B_ho f_c = rhs``: the Jacobians, rates, ``B_ho`` and ``rhs``.

    The first of the two compiled passes around the solve of ``B_ho``
    (:func:`~grasp_safety_filter.model.packed_pass.write_grasp_terms`). With ``torsion``,
    rows ``3n + i`` are contact i's torsion rows (module docstring).
    """
    n = J_fingertip.shape[0]
    m = J_fingertip.shape[2]
    k = 4 * n if torsion else 3 * n
    J_h = np.zeros((k, m))
    G = np.zeros((6, k))
    Jh_dot_dq = np.empty(k)
    G_dot_T_twist = np.empty(k)
    w_o = twist_object[3:]
    v_o = twist_object[:3]
    w_c = np.empty((n, 3))
    w_relative = np.empty((n, 3))
    p_fc = np.empty(3)
    p_oc = np.empty(3)
    tmp = np.empty(3)
    tmp2 = np.empty(3)
    v_cf = np.empty(3)
    v_co = np.empty(3)
    p_c_dot = np.empty(3)
    world = np.empty(3)
    for i in range(n):
        R = R_contact_to_palm[i]
        v_f = twist_fingertip[i, :3]
        w_f = twist_fingertip[i, 3:]
        for r in range(3):
            p_fc[r] = p_contact_in_palm[i, r] - p_fingertip_in_palm[i, r]
            p_oc[r] = p_contact_in_palm[i, r] - p_object_in_palm[r]
            w_relative[i, r] = w_f[r] - w_o[r]
        # J_h,i = R_cp (J_v - p_fc × J_w), column by column (zero off the fingertip's span).
        for j in range(fingertip_span[i, 0], fingertip_span[i, 1]):
            for r in range(3):
                tmp[r] = J_fingertip[i, 3 + r, j]
            _cross(p_fc, tmp, tmp2)
            for r in range(3):
                world[r] = J_fingertip[i, r, j] - tmp2[r]
            for r in range(3):
                J_h[3 * i + r, j] = R[0, r] * world[0] + R[1, r] * world[1] + R[2, r] * world[2]
        # G_i = [R_pc; p_oc × R_pc].
        for c in range(3):
            for r in range(3):
                G[r, 3 * i + c] = R[r, c]
                tmp[r] = R[r, c]
            _cross(p_oc, tmp, tmp2)
            for r in range(3):
                G[3 + r, 3 * i + c] = tmp2[r]
        # w_c = w_f + R_pc Omega; v_cf = v_f + w_f × p_fc; v_co = v_o + w_o × p_oc.
        Omega = frame_angular_velocity[i]
        for r in range(3):
            w_c[i, r] = w_f[r] + R[r, 0] * Omega[0] + R[r, 1] * Omega[1] + R[r, 2] * Omega[2]
        _cross(w_f, p_fc, tmp)
        _cross(w_o, p_oc, tmp2)
        for r in range(3):
            v_cf[r] = v_f[r] + tmp[r]
            v_co[r] = v_o[r] + tmp2[r]
            p_c_dot[r] = (
                v_cf[r]
                + R[r, 0] * sliding_velocity[i, 0]
                + R[r, 1] * sliding_velocity[i, 1]
            )
        # J_h_dot dq = R_cp (a_f0 - p_fc × alpha_f0 + w_f × (p_c_dot - v_f) - w_c × v_cf).
        a_f0 = J_fingertip_dot_dq[i, :3]
        alpha_f0 = J_fingertip_dot_dq[i, 3:]
        _cross(p_fc, alpha_f0, tmp)
        for r in range(3):
            world[r] = a_f0[r] - tmp[r]
            tmp2[r] = p_c_dot[r] - v_f[r]
        _cross(w_f, tmp2, tmp)
        for r in range(3):
            world[r] += tmp[r]
        _cross(w_c[i], v_cf, tmp)
        for r in range(3):
            world[r] -= tmp[r]
        for r in range(3):
            Jh_dot_dq[3 * i + r] = R[0, r] * world[0] + R[1, r] * world[1] + R[2, r] * world[2]
        # G_dot^T x_o_dot = R_cp (w_o × (p_c_dot - v_o) - w_c × v_co).
        for r in range(3):
            tmp2[r] = p_c_dot[r] - v_o[r]
        _cross(w_o, tmp2, world)
        _cross(w_c[i], v_co, tmp)
        for r in range(3):
            world[r] -= tmp[r]
        for r in range(3):
            G_dot_T_twist[3 * i + r] = (
                R[0, r] * world[0] + R[1, r] * world[1] + R[2, r] * world[2]
            )
        if torsion:
            # No spin about the normal n = z_c: n^T (w_f - w_o) = 0, whose rate is
            # n^T (alpha_f - alpha_o) + (w_c × n)^T (w_f - w_o) = 0 (n turns with w_c).
            t = 3 * n + i
            for j in range(fingertip_span[i, 0], fingertip_span[i, 1]):
                J_h[t, j] = (
                    R[0, 2] * J_fingertip[i, 3, j]
                    + R[1, 2] * J_fingertip[i, 4, j]
                    + R[2, 2] * J_fingertip[i, 5, j]
                )
            for r in range(3):
                G[3 + r, t] = R[r, 2]
                tmp2[r] = R[r, 2]
            _cross(w_c[i], tmp2, tmp)
            total = 0.0
            spin = 0.0
            for r in range(3):
                total += R[r, 2] * alpha_f0[r] + tmp[r] * w_f[r]
                spin += tmp[r] * w_o[r]
            Jh_dot_dq[t] = total
            G_dot_T_twist[t] = spin

    # ---- Torque-affine terms, [matrix | offset] on (u, 1).
    # Joint acceleration without contact forces: M_h^-1 [I | -h].
    ddq = np.empty((m, m + 1))
    for r in range(m):
        offset = 0.0
        for j in range(m):
            ddq[r, j] = M_h_inverse[r, j]
        for j in range(joint_span[r, 0], joint_span[r, 1]):
            offset -= M_h_inverse[r, j] * h_bias[j]
        ddq[r, m] = offset
    # Object acceleration from gravity and the bias wrench: M_o^-1 (w_e - C_o x_o_dot).
    x_ddot_free = np.empty(6)
    for r in range(6):
        total = 0.0
        for c in range(6):
            total += M_o_inverse[r, c] * (w_e[c] - C_o_twist[c])
        x_ddot_free[r] = total
    # Sums over the overlap of the factors' spans (module docstring).
    row_contact = row_contacts(n, k)
    M_h_inv_J_hT = np.empty((m, k))
    for r in range(m):
        for c in range(k):
            start, stop = fingertip_span[row_contact[c], 0], fingertip_span[row_contact[c], 1]
            total = 0.0
            for j in range(max(start, joint_span[r, 0]), min(stop, joint_span[r, 1])):
                total += M_h_inverse[r, j] * J_h[c, j]
            M_h_inv_J_hT[r, c] = total
    M_o_inv_G = np.empty((6, k))
    for r in range(6):
        for c in range(k):
            total = 0.0
            for j in range(6):
                total += M_o_inverse[r, j] * G[j, c]
            M_o_inv_G[r, c] = total
    B_ho = np.empty((k, k))
    for r in range(k):
        start, stop = fingertip_span[row_contact[r], 0], fingertip_span[row_contact[r], 1]
        for c in range(k):
            total = 0.0
            low = max(start, fingertip_span[row_contact[c], 0])
            for j in range(low, min(stop, fingertip_span[row_contact[c], 1])):
                total += J_h[r, j] * M_h_inv_J_hT[j, c]
            for j in range(6):
                total += G[j, r] * M_o_inv_G[j, c]
            B_ho[r, c] = total
    force_rhs = np.empty((k, m + 1))
    for r in range(k):
        start, stop = fingertip_span[row_contact[r], 0], fingertip_span[row_contact[r], 1]
        for c in range(m + 1):
            # ddq's column c < m is M_h^-1's: zero outside joint c's span.
            if c < m:
                low, high = max(start, joint_span[c, 0]), min(stop, joint_span[c, 1])
            else:
                low, high = start, stop
            total = 0.0
            for j in range(low, high):
                total += J_h[r, j] * ddq[j, c]
            force_rhs[r, c] = total
        total = 0.0
        for j in range(6):
            total += G[j, r] * x_ddot_free[j]
        force_rhs[r, m] += Jh_dot_dq[r] - G_dot_T_twist[r] - total
    return (
        J_h, G, Jh_dot_dq, G_dot_T_twist, B_ho, force_rhs, ddq, M_h_inv_J_hT, M_o_inv_G,
        x_ddot_free, w_c, w_relative,
    )


@kernel
def acceleration_terms(
    force: np.ndarray,
    ddq: np.ndarray,
    M_h_inv_J_hT: np.ndarray,
    M_o_inv_G: np.ndarray,
    x_ddot_free: np.ndarray,
    w_c: np.ndarray,
    w_relative: np.ndarray,
    J_fingertip: np.ndarray,
    J_fingertip_dot_dq: np.ndarray,
    R_contact_to_palm: np.ndarray,
    H_cf: np.ndarray,
    H_cf_dot_w: np.ndarray,
    joint_span: np.ndarray,
    fingertip_span: np.ndarray,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """From ``f_c``: ``ddq``, ``x_o_ddot`` and ``xi_cf_ddot`` (augmented, as returned)."""
    n = J_fingertip.shape[0]
    m = J_fingertip.shape[2]
    k = force.shape[0]
    tmp = np.empty(3)
    # ddq = M_h^-1 (u - h) - M_h^-1 J_h^T f_c;  x_o_ddot = M_o^-1 G f_c + x_ddot_free.
    # Row r of M_h^-1 J_h^T is zero on the rows of contacts whose spans miss joint r's: the
    # sum runs over the others' rows, in order.
    row_contact = row_contacts(n, k)
    coupling = np.empty(m + 1)
    for r in range(m):
        coupling[:] = 0.0
        for j in range(k):
            i = row_contact[j]
            if max(fingertip_span[i, 0], joint_span[r, 0]) < min(
                fingertip_span[i, 1], joint_span[r, 1]
            ):
                for c in range(m + 1):
                    coupling[c] += M_h_inv_J_hT[r, j] * force[j, c]
        for c in range(m + 1):
            ddq[r, c] -= coupling[c]
    x_ddot = np.empty((6, m + 1))
    for r in range(6):
        for c in range(m + 1):
            total = 0.0
            for j in range(k):
                total += M_o_inv_G[r, j] * force[j, c]
            x_ddot[r, c] = total
        x_ddot[r, m] += x_ddot_free[r]
    # xi_cf_ddot,i = (H_cf R_cp) (J_w ddq - alpha_o + [alpha_f0 - w_c × w_rel]) + H_cf_dot w.
    xi_ddot = np.empty((2 * n, m + 1))
    alpha = np.empty((3, m + 1))
    H_R = np.empty((2, 3))
    for i in range(n):
        R = R_contact_to_palm[i]
        for r in range(3):
            for c in range(m + 1):
                total = 0.0
                for j in range(fingertip_span[i, 0], fingertip_span[i, 1]):
                    total += J_fingertip[i, 3 + r, j] * ddq[j, c]
                alpha[r, c] = total - x_ddot[3 + r, c]
        _cross(w_c[i], w_relative[i], tmp)
        for r in range(3):
            alpha[r, m] += J_fingertip_dot_dq[i, 3 + r] - tmp[r]
        for a in range(2):
            for c in range(3):
                # (H_cf R_cp)[a, c] = sum_r H_cf[a, r] R_pc[c, r].
                H_R[a, c] = (
                    H_cf[i, a, 0] * R[c, 0] + H_cf[i, a, 1] * R[c, 1] + H_cf[i, a, 2] * R[c, 2]
                )
        for a in range(2):
            for c in range(m + 1):
                xi_ddot[2 * i + a, c] = (
                    H_R[a, 0] * alpha[0, c] + H_R[a, 1] * alpha[1, c] + H_R[a, 2] * alpha[2, c]
                )
            xi_ddot[2 * i + a, m] += H_cf_dot_w[i, a]
    return ddq, x_ddot, xi_ddot
