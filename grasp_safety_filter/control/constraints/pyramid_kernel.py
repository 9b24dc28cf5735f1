"""The rows of :class:`~grasp_safety_filter.control.constraints.friction_cone.FrictionPyramid`.

With ``f_c(u) = F u + f_0`` and ``N_i`` the negated face normals of contact i's pyramid
(rows × w)::

    A[i, j] = N_i[j] F_i,     lower[i, j] = eps - N_i[j] f_0,i

rows contact-major, face by face: one compiled loop (:mod:`grasp_safety_filter.model.compiled`)
instead of batched numpy products on (rows × w) blocks. The width w says the contact model:

- w = 3, point contacts: ``f_c`` has 3n entries, per contact ``(f_x, f_y, f_n)``
  (contact-major), and ``F_i`` is rows ``3i .. 3i + 2`` of ``F``;
- w = 4, soft fingers: ``f_c`` has 4n entries, the 3n above then the n torques
  ``tau_1 .. tau_n`` about the contact normals, and ``F_i`` is rows ``3i .. 3i + 2`` and
  ``3n + i``.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.compiled import kernel


@kernel
def pyramid_rows_into(
    negative_faces: np.ndarray,
    force_matrix: np.ndarray,
    force_offset: np.ndarray,
    normal_force_margin: float,
    A: np.ndarray,
    lower: np.ndarray,
    start: int,
) -> None:
    """Write the pyramid rows at rows ``start:`` of ``A`` (K, m) and ``lower`` (K,).

    Args:
        negative_faces: ``N``, (n, rows per contact, w), w = 3 (point) or 4 (soft finger).
        force_matrix: ``F``, (w n, m), N (and N·m for the torques) per N·m.
        force_offset: ``f_0``, (w n,), N (N·m).
        normal_force_margin: ``eps``, N.
        A: The stacked rows' matrix, K ≥ start + n rows per contact.
        lower: The stacked rows' lower bounds.
        start: The first row written.
    """
    n, faces = negative_faces.shape[0], negative_faces.shape[1]
    torsion = negative_faces.shape[2] == 4
    m = force_matrix.shape[1]
    for i in range(n):
        t = 3 * n + i  # tau_i's row (soft fingers)
        for j in range(faces):
            r = start + i * faces + j
            N0, N1, N2 = negative_faces[i, j, 0], negative_faces[i, j, 1], negative_faces[i, j, 2]
            if torsion:
                N3 = negative_faces[i, j, 3]
                for c in range(m):
                    A[r, c] = (
                        N0 * force_matrix[3 * i, c]
                        + N1 * force_matrix[3 * i + 1, c]
                        + N2 * force_matrix[3 * i + 2, c]
                        + N3 * force_matrix[t, c]
                    )
                lower[r] = normal_force_margin - (
                    N0 * force_offset[3 * i]
                    + N1 * force_offset[3 * i + 1]
                    + N2 * force_offset[3 * i + 2]
                    + N3 * force_offset[t]
                )
                continue
            for c in range(m):
                A[r, c] = (
                    N0 * force_matrix[3 * i, c]
                    + N1 * force_matrix[3 * i + 1, c]
                    + N2 * force_matrix[3 * i + 2, c]
                )
            lower[r] = normal_force_margin - (
                N0 * force_offset[3 * i]
                + N1 * force_offset[3 * i + 1]
                + N2 * force_offset[3 * i + 2]
            )


@kernel
def pyramid_rows(
    negative_faces: np.ndarray,
    force_matrix: np.ndarray,
    force_offset: np.ndarray,
    normal_force_margin: float,
) -> tuple[np.ndarray, np.ndarray]:
    """Return ``A`` (n rows per contact, m) and ``lower`` of the pyramid rows.

    Args:
        negative_faces: ``N``, (n, rows per contact, w), w = 3 (point) or 4 (soft finger).
        force_matrix: ``F``, (w n, m), N (N·m) per N·m.
        force_offset: ``f_0``, (w n,), N (N·m).
        normal_force_margin: ``eps``, N.
    """
    rows = negative_faces.shape[0] * negative_faces.shape[1]
    A = np.empty((rows, force_matrix.shape[1]))
    lower = np.empty(rows)
    pyramid_rows_into(
        negative_faces, force_matrix, force_offset, normal_force_margin, A, lower, 0
    )
    return A, lower


@kernel
def pyramid_rows_packed(
    negative_faces: np.ndarray,
    terms: np.ndarray,
    force_start: int,
    normal_force_margin: float,
    A: np.ndarray,
    lower: np.ndarray,
    start: int,
) -> None:
    """:func:`pyramid_rows_into` with ``[F | f_0]`` read from a packed buffer.

    ``F`` and ``f_0`` are views of ``terms`` (no copy), so the rows are the same arithmetic.

    Args:
        negative_faces: ``N``, (n, rows per contact, w), w = 3 (point) or 4 (soft finger).
        terms: The grasp state's packed terms
            (:class:`~grasp_safety_filter.model.packed_terms.PackedLayout`).
        force_start: Where ``[F | f_0]`` (w n, m + 1) starts in ``terms``.
        normal_force_margin: ``eps``, N.
        A: The stacked rows' matrix (K, m), K ≥ start + n rows per contact.
        lower: The stacked rows' lower bounds.
        start: The first row written.
    """
    rows = negative_faces.shape[2] * negative_faces.shape[0]
    m = A.shape[1]
    force = terms[force_start:force_start + rows * (m + 1)].reshape((rows, m + 1))
    pyramid_rows_into(
        negative_faces, force[:, :m], force[:, m], normal_force_margin, A, lower, start
    )
