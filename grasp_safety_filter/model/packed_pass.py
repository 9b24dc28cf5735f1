"""The one-pass grasp terms' shared stages after the contacts' kinematics.

Each one-pass kernel of :mod:`grasp_safety_filter.model.packed_terms` (one per kind of
object surface) forms the hand's and the object's terms, runs its surface's contact kernel,
then :func:`write_grasp_terms`, which solves the contact dynamics and writes every term into the
buffer in :func:`~grasp_safety_filter.model.packed_terms.packed_fields`' order, and
:func:`write_object_coordinate_acceleration`, the last term. The
stages are inlined into each kernel by numba (:data:`~grasp_safety_filter.model.compiled.
inline_kernel`): as calls, handing over their two dozen arrays cost the paper hand's pass
1.3 of its 10.5 µs. The pass stays one call from Python.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import inline_kernel, kernel
from grasp_safety_filter.model.dynamics_kernel import acceleration_terms, velocity_terms
from grasp_safety_filter.model.rolling_kernels import object_coordinate_rate_terms
from grasp_safety_filter.model.wrench_solve import wrench_solve

#: The object's terms: ``M_o``, ``M_o^-1`` (6, 6) and ``C_o x_o_dot`` (6,), palm frame.
ObjectTerms = tuple[np.ndarray, np.ndarray, np.ndarray]
#: The hand's terms in the model's order, as :func:`~grasp_safety_filter.model.hand_kernel.
#: hand_in_model_order` returns them.
HandTerms = tuple[np.ndarray, ...]


@kernel
def _put(out: np.ndarray, start: int, values: np.ndarray) -> int:
    """Copy a vector to ``out[start:]``; return the index after it."""
    for i in range(values.shape[0]):
        out[start + i] = values[i]
    return start + values.shape[0]


@kernel
def _put2(out: np.ndarray, start: int, values: np.ndarray) -> int:
    """Copy a matrix to ``out[start:]`` in C order; return the index after it.

    Indexed entry by entry: a reshaped view (``ravel``) costs a call into numba's runtime
    per array, more than copying the few entries.
    """
    rows, columns = values.shape
    for r in range(rows):
        for c in range(columns):
            out[start + r * columns + c] = values[r, c]
    return start + rows * columns


@kernel
def _put3(out: np.ndarray, start: int, values: np.ndarray) -> int:
    """Copy a 3-D array to ``out[start:]`` in C order; return the index after it."""
    blocks, rows, columns = values.shape
    for b in range(blocks):
        for r in range(rows):
            for c in range(columns):
                out[start + (b * rows + r) * columns + c] = values[b, r, c]
    return start + blocks * rows * columns


@inline_kernel
def write_grasp_terms(
    out: np.ndarray,
    object_terms: ObjectTerms,
    hand_terms: HandTerms,
    contacts: tuple[np.ndarray, ...],
    branches: tuple[np.ndarray, np.ndarray],
    q: np.ndarray,
    dq: np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    w_e: np.ndarray,
    torsion: bool,
    torsional_compliance: float,
) -> tuple[int, np.ndarray]:
    """Solve the contact dynamics and write the terms into ``out``, in ``packed_fields``' order.

    The contact dynamics are :mod:`~grasp_safety_filter.model.dynamics_kernel`'s two
    passes around the solve of ``B_ho``. Every term but the last,
    ``xi_co_ddot_augmented``, is written: its closed form is the object surface's, which the
    caller writes from what this returns.

    Args:
        out: The buffer (:attr:`~grasp_safety_filter.model.packed_terms.PackedLayout.size`,).
        object_terms: ``(M_o, M_o^-1, C_o x_o_dot)``, palm frame
            (:func:`~grasp_safety_filter.model.object_kernel.object_dynamics`).
        hand_terms: The hand's terms in the model's order
            (:func:`~grasp_safety_filter.model.hand_kernel.hand_in_model_order`).
        contacts: The contacts' geometry and rolling rates, the 14 arrays of
            :func:`~grasp_safety_filter.model.rolling_kernels.sphere_on_plane_contacts`.
        branches: Each joint's and each fingertip's span, (m, 2) and (n, 2)
            (:class:`~grasp_safety_filter.model.hand.Branches`).
        q: Joint angles, (m,), rad.
        dq: Joint velocities, (m,), rad/s.
        p_object_in_palm: Object centre of mass, (3,), m.
        R_object_to_palm: Object orientation, (3, 3).
        twist_object: ``(v_o, w_o)``, (6,).
        w_e: External wrench on the object, (6,).
        torsion: Soft-finger contacts (4n wrench entries, not 3n).
        torsional_compliance: Their relative torsional compliance rho.

    Returns:
        Where ``xi_co_ddot_augmented`` starts in ``out``, and ``u ↦ xi_cf_ddot``,
        ``[matrix | offset]`` (2n, m + 1).

    Raises:
        numpy.linalg.LinAlgError: B_ho is singular (a ``B_ho`` or right-hand side that is not
            finite gives NaN wrench and accelerations instead).
    """
    M_o, M_o_inverse, C_o_twist = object_terms
    joint_span, fingertip_span = branches
    p_f, R_f, J_s, twist_f, J_frames_dot_dq, M_h, M_h_inverse, h_bias, gravity = hand_terms
    # ---- Contact dynamics (dynamics_kernel: two passes around the solve of B_ho).
    (
        J_h, G, Jh_dot_dq, G_dot_T_twist, B_ho, force_rhs, ddq, M_h_inv_J_hT, M_o_inv_G,
        x_ddot_free, w_c, w_relative,
    ) = velocity_terms(
        J_s, twist_f, J_frames_dot_dq, p_f, M_h_inverse, h_bias, p_object_in_palm,
        twist_object, M_o_inverse, C_o_twist, w_e, contacts[4], contacts[5], contacts[10],
        contacts[11], contacts[12], contacts[13], joint_span, fingertip_span, torsion,
    )
    if not (np.isfinite(B_ho).all() and np.isfinite(force_rhs).all()):
        # Terms that overflowed (a huge but finite state): every term after the solve is
        # NaN, which the consumers refuse, rather than an error from the solve.
        force = np.full(force_rhs.shape, np.nan)
    elif torsion:
        force = wrench_solve(B_ho, force_rhs, torsional_compliance)
    else:
        force = np.linalg.solve(B_ho, force_rhs)
    ddq, x_ddot, xi_ddot = acceleration_terms(
        force, ddq, M_h_inv_J_hT, M_o_inv_G, x_ddot_free, w_c, w_relative,
        J_s, J_frames_dot_dq, contacts[5], contacts[10], contacts[11], joint_span,
        fingertip_span,
    )
    # ---- Into the buffer, in packed_fields' order.
    at = _put(out, 0, q)
    at = _put(out, at, dq)
    at = _put(out, at, p_object_in_palm)
    at = _put2(out, at, R_object_to_palm)
    at = _put(out, at, twist_object)
    at = _put2(out, at, p_f)
    at = _put3(out, at, R_f)
    at = _put2(out, at, twist_f)
    at = _put3(out, at, J_s)
    at = _put2(out, at, M_h)
    at = _put(out, at, h_bias)
    at = _put(out, at, gravity)
    at = _put2(out, at, contacts[0])  # xi_cf
    at = _put2(out, at, contacts[1])  # xi_co
    at = _put(out, at, contacts[2])  # psi
    at = _put(out, at, contacts[3])  # penetration
    at = _put2(out, at, contacts[4])  # p_contact
    at = _put3(out, at, contacts[5])  # R_pc
    at = _put3(out, at, contacts[6])  # R_fc
    at = _put2(out, at, contacts[7])  # xi_cf_dot
    at = _put2(out, at, contacts[8])  # xi_co_dot
    at = _put(out, at, contacts[9])  # psi_dot
    at = _put3(out, at, contacts[10])  # H_cf
    at = _put2(out, at, contacts[11])  # H_cf_dot_w
    at = _put2(out, at, contacts[12])  # sliding
    at = _put2(out, at, contacts[13])  # Omega
    at = _put2(out, at, J_h)
    at = _put2(out, at, G)
    at = _put(out, at, Jh_dot_dq)
    at = _put(out, at, G_dot_T_twist)
    at = _put2(out, at, B_ho)
    at = _put2(out, at, force)
    at = _put2(out, at, ddq)
    at = _put2(out, at, x_ddot)
    at = _put2(out, at, xi_ddot)
    at = _put2(out, at, M_o)
    return _put(out, at, C_o_twist), xi_ddot


@inline_kernel
def write_object_coordinate_acceleration(
    out: np.ndarray,
    at: int,
    contacts: tuple[np.ndarray, ...],
    xi_cf_ddot: np.ndarray,
    radius: np.ndarray,
    object_radius: np.ndarray,
    flat: bool,
) -> None:
    """Write ``u ↦ xi_co_ddot``, ``[matrix | offset]`` (2n, m + 1), C order, at ``out[at:]``.

    Per contact ``xi_co_ddot = A xi_cf_ddot + c``
    (:func:`~grasp_safety_filter.model.rolling_kernels.object_coordinate_rate_terms`), with
    ``xi_cf_ddot``'s rows ``[matrix | offset]``.

    Args:
        out: The packed buffer; entries ``at .. at + 2n (m + 1) - 1`` are written.
        at: Where ``xi_co_ddot_augmented`` starts in it.
        contacts: The contacts' 14 arrays (:func:`~grasp_safety_filter.model.rolling_kernels.
            sphere_on_plane_contacts`).
        xi_cf_ddot: ``u ↦ xi_cf_ddot``, ``[matrix | offset]`` (2n, m + 1).
        radius: Each fingertip's radius, (n,), m.
        object_radius: The object's radius per contact, (n,), m (not read when ``flat``).
        flat: Whether the object surfaces are flat faces (else a sphere).
    """
    A, bias = object_coordinate_rate_terms(
        contacts[0], contacts[1], contacts[2], contacts[7], contacts[8], contacts[9],
        contacts[12], radius, object_radius, flat,
    )
    columns = xi_cf_ddot.shape[1]
    m = columns - 1
    for i in range(radius.shape[0]):
        top, bottom = at + 2 * i * columns, at + (2 * i + 1) * columns
        for k in range(columns):
            out[top + k] = (
                A[i, 0, 0] * xi_cf_ddot[2 * i, k] + A[i, 0, 1] * xi_cf_ddot[2 * i + 1, k]
            )
            out[bottom + k] = (
                A[i, 1, 0] * xi_cf_ddot[2 * i, k] + A[i, 1, 1] * xi_cf_ddot[2 * i + 1, k]
            )
        out[top + m] += bias[i, 0]
        out[bottom + m] += bias[i, 1]
