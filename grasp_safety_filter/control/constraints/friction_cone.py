"""No slip: contact forces inside friction pyramids inscribed in the friction cones (eq. 9, 14)."""

from __future__ import annotations

from collections.abc import Sequence
import math

import numpy as np

from grasp_safety_filter.control.constraints.base import (
    BarrierValues,
    check_block,
    check_rows,
    CheckedBlock,
    ConstraintRows,
    finite_scalar,
    rows_of,
    validate_names,
)
from grasp_safety_filter.model.compiled import kernel
from grasp_safety_filter.model.grasp_state import GraspState

#: The l_s-face pyramid inscribed in the circular cone (the paper's).
INSCRIBED = 'inscribed'
#: The 4-face pyramid ``|f_x| + |f_y| <= mu f_n`` (inside a pyramidal contact model's cone).
DIAMOND = 'diamond'
#: The admissible ``no_slip.cone`` values.
FRICTION_CONES = (INSCRIBED, DIAMOND)
#: The largest relative friction margin (``no_slip.friction_margin``).
MAX_FRICTION_MARGIN = 0.9
#: A soft finger's row pair per face: the torsion term's sign and its row-name suffix.
TORSION_SIGNS = ((1.0, 'torsion+'), (-1.0, 'torsion-'))


def positive_per_contact(
    value: float | Sequence[float] | np.ndarray, contact_names: Sequence[str], parameter: str
) -> np.ndarray:
    """``value`` as one finite coefficient > 0 per contact, (n,), read-only.

    Args:
        value: One number for every contact, or one per contact (length 1 or n).
        contact_names: The n contact names, for the messages.
        parameter: The argument's name, for the messages.

    Raises:
        ValueError: Naming ``parameter`` and, for a bad value, its contact and the value.
    """
    n = len(contact_names)
    try:
        array = np.broadcast_to(np.array(value, dtype=float), (n,)).copy()
    except (TypeError, ValueError):
        raise ValueError(
            f"'{parameter}': expected one number or {n} (one per contact), got {value!r}"
        ) from None
    for contact, coefficient in zip(contact_names, array.tolist(), strict=True):
        if not (math.isfinite(coefficient) and coefficient > 0.0):
            raise ValueError(
                f"'{parameter}' of contact {contact!r}: expected a finite number > 0, "
                f'got {coefficient!r}'
            )
    array.setflags(write=False)
    return array


class FrictionPyramid:
    """Keep every contact force inside an l_s-face pyramid inscribed in its friction cone.

    With ``f_c(u) = state.contact_force(u)``, per contact ``(f_x, f_y, f_n)`` in the contact
    frame (the force on the object, ``f_n > 0`` pushing), for each contact i and face
    ``j = 0 .. l_s - 1``, ``th_j = 2 pi j / l_s``::

        cos(th_j) f_x,i(u) + sin(th_j) f_y,i(u) - mu_i cos(pi / l_s) f_n,i(u) <= -eps

    Each contact has its own mu_i (fingertips of different materials). The pyramid's faces
    touch the cone ``||f_t|| <= mu_i f_n`` along their centre lines (its
    apothem is ``mu cos(pi / l_s) f_n``), so every force satisfying all faces lies inside the
    cone: no slip is guaranteed, at the price of ``1 - cos(pi / l_s)`` of the friction
    (7.6 % for l_s = 8). ``eps >= 0`` (N) keeps the force away from the pyramid's boundary
    and hence ``f_n >= eps / (mu_i cos(pi / l_s)) > 0`` when ``eps > 0``: the contact is
    neither slipping nor separating. This is a relative-degree-zero constraint: the rows
    act on the force directly, no barrier dynamics.

    The margin per row is ``h_ij(u) = mu_i cos(pi / l_s) f_n,i - cos(th_j) f_x,i
    - sin(th_j) f_y,i`` (N, > 0 inside the pyramid); the row is ``h_ij(u) >= eps``.
    Row names: ``"no_slip/<contact>/face<j>"``.

    Two options for a plant whose friction is not the model's:

    - ``friction_margin`` m in [0, 0.9]: every row uses ``mu_i (1 - m)`` instead of mu_i (a
      relative margin, so one value fits contacts of different mu): the pyramid sits inside
      the cone of any plant whose friction is at least ``(1 - m)`` times the model's.
    - ``cone="diamond"``: instead of the l_s faces, the four rows
      ``s_x f_x,i + s_y f_y,i - mu_i f_n,i <= -eps`` for ``s_x, s_y`` in ``{+1, -1}``, i.e.
      ``|f_x| + |f_y| <= mu_i f_n - eps``: the pyramid spanned by ``(+-mu, 0, 1)`` and
      ``(0, +-mu, 1)``, which is a pyramidal contact model's own cone (MuJoCo's default
      ``cone="pyramidal"``, condim 3). The inscribed l_s-face pyramid is inside the circular
      cone but not inside that one (its vertex at ``th = pi / l_s`` has
      ``|f_x| + |f_y| = mu f_n (cos(pi / l_s) + sin(pi / l_s)) > mu f_n``); the diamond is
      inside both.

    Soft fingers (``torsional_friction`` mu_t, m, one per contact): the contact also
    transmits a torque tau_i about its normal, bounded by ``|tau_i| <= mu_t,i f_n,i``
    (Murray, Li and Sastry's soft-finger model); ``f_c`` then has 4n entries, the torques
    ``tau_1 .. tau_n`` (N·m) after the 3n forces. Each face row above is taken twice, once
    with each sign s in {+1, -1} of an added torsion term. With ``mu' = mu (1 - m)``,
    ``mu_t' = mu_t (1 - m)`` and ``a = mu' cos(pi / l_s)`` (inscribed) or ``a = mu'``
    (diamond), the rows of face j are::

        t_j . f_t,i + s (a / mu_t,i') tau_i - a f_n,i <= -eps

    with ``t_j = (cos th_j, sin th_j)`` (inscribed) or ``(s_x, s_y)`` (diamond). Together,
    with ``g(f_t) = max_j t_j . f_t / (a / mu')`` the pyramid's gauge::

        g(f_t) / mu' + |tau| / mu_t' <= f_n - eps / a

    - Inscribed: ``g(f_t) >= |f_t|`` (g's unit ball, the polygon, lies in the unit disc), so
      ``|f_t| / mu' + |tau| / mu_t' <= f_n``: every accepted wrench has ``|f_t| <= mu' f_n``
      and ``|tau| <= mu_t' f_n`` (the soft-finger cone) and, as an l1 norm bounds the l2
      norm, lies in the elliptic soft-finger cone ``f_t^2 / mu'^2 + tau^2 / mu_t'^2 <=
      f_n^2``.
    - Diamond: ``g(f_t) = |f_x| + |f_y|``, so the rows are exactly
      ``|f_x| / mu' + |f_y| / mu' + |tau| / mu_t' <= f_n - eps / mu'``: with eps = 0, the
      cone spanned by ``(+-mu', 0, 1, 0)``, ``(0, +-mu', 1, 0)`` and ``(0, 0, 1, +-mu_t')``,
      MuJoCo's pyramidal cone of condim 4 (``friction`` = (mu, ., mu_t)).

    The margin of each row is its left side negated, as without torsion (N). Row names:
    ``"no_slip/<contact>/face<j>/torsion+"`` and ``".../torsion-"`` (:data:`TORSION_SIGNS`),
    face by face. ``torsional_friction=None`` is the point contact: the rows, names and
    values are those above, to the bit.
    """

    family = 'no_slip'
    state_fields = ('contact_force',)
    #: :meth:`rows_into` reads a packed state in compiled code only.
    compiled_packed_rows = True

    def __init__(
        self,
        contact_names: Sequence[str],
        mu: float | Sequence[float] | np.ndarray,
        faces: int = 8,
        normal_force_margin: float = 0.0,
        friction_margin: float = 0.0,
        cone: str = INSCRIBED,
        torsional_friction: float | Sequence[float] | np.ndarray | None = None,
    ) -> None:
        """Build the pyramid faces of every contact.

        Args:
            contact_names: The n contact (finger) names, in the model's contact order.
            mu: Friction coefficient, > 0: one for all contacts or one per contact.
            faces: Number of pyramid faces l_s, an integer >= 3.
            normal_force_margin: The margin eps >= 0, N.
            friction_margin: The relative friction margin m in [0, 0.9]: rows use
                ``mu_i (1 - m)``.
            cone: :data:`INSCRIBED` (l_s faces) or :data:`DIAMOND` (4 rows, ``faces`` unused).
            torsional_friction: Soft fingers' torsional friction mu_t, > 0, m: one for all
                contacts or one per contact (two rows per face); None: point contacts.

        Raises:
            ValueError: An argument is malformed; the message names it.
        """
        self.contact_names = validate_names(contact_names, 'contact_names')
        n = len(self.contact_names)
        if isinstance(faces, bool) or not isinstance(faces, int | np.integer) or faces < 3:
            raise ValueError(f"'faces': expected an integer >= 3, got {faces!r}")
        self.faces = int(faces)
        self.mu = positive_per_contact(mu, self.contact_names, 'mu')
        self.torsional_friction = (
            None
            if torsional_friction is None
            else positive_per_contact(torsional_friction, self.contact_names, 'torsional_friction')
        )
        self.normal_force_margin = finite_scalar(normal_force_margin, 'normal_force_margin', 0.0)
        self.friction_margin = finite_scalar(friction_margin, 'friction_margin', 0.0)
        if self.friction_margin > MAX_FRICTION_MARGIN:
            raise ValueError(
                f"'friction_margin': expected a number in [0, {MAX_FRICTION_MARGIN}], "
                f'got {friction_margin!r}'
            )
        if cone not in FRICTION_CONES:
            raise ValueError(f"'cone': expected one of {list(FRICTION_CONES)}, got {cone!r}")
        self.cone = cone
        mu_rows = self.mu * (1.0 - self.friction_margin)
        if cone == DIAMOND:
            self.faces = 4
            tangential = np.array([[1.0, 1.0], [-1.0, 1.0], [-1.0, -1.0], [1.0, -1.0]])
            apothem = mu_rows
        else:
            theta = 2.0 * np.pi * np.arange(self.faces) / self.faces
            tangential = np.column_stack((np.cos(theta), np.sin(theta)))
            apothem = mu_rows * math.cos(math.pi / self.faces)
        # Face normals per contact, shape (n, faces, 3): rows [t_x, t_y, -apothem_i];
        # face j holds when  face_j . f <= -eps.
        face = np.empty((n, self.faces, 3))
        face[:, :, :2] = tangential
        face[:, :, 2] = -apothem[:, np.newaxis]
        names = [
            f'{self.family}/{contact}/face{j}'
            for contact in self.contact_names
            for j in range(self.faces)
        ]
        if self.torsional_friction is not None:
            # Each face twice, [t_x, t_y, -apothem_i, s apothem_i / mu_t,i']: (n, 2 faces, 4).
            torsion = apothem / (self.torsional_friction * (1.0 - self.friction_margin))
            signs = np.array([sign for sign, _ in TORSION_SIGNS])
            soft = np.empty((n, self.faces, len(signs), 4))
            soft[:, :, :, :3] = face[:, :, np.newaxis, :]
            soft[:, :, :, 3] = torsion[:, np.newaxis, np.newaxis] * signs
            face = soft.reshape(n, -1, 4)
            names = [f'{name}/{suffix}' for name in names for _, suffix in TORSION_SIGNS]
        self._negative_faces = -face
        #: Rows of f_c: 3n (point contacts) or 4n (soft fingers).
        self._force_rows = face.shape[2] * n
        self._packed_layout: object = None
        self._block = CheckedBlock()
        self._force_start = 0
        self.names = tuple(names)

    def rows(self, state: GraspState) -> ConstraintRows:
        """Rows ``h_ij(u) >= eps`` as ``A u >= lower``.

        With ``f_c(u) = F u + f_0`` and ``Lambda`` the face normals:
        ``A = -Lambda F`` and ``lower = eps + Lambda f_0`` (:meth:`rows_into`, on new arrays).
        """
        return rows_of(self, state, state.contact_force.matrix.shape[1])

    def rows_into(self, state: GraspState, A: np.ndarray, lower: np.ndarray, start: int) -> None:
        """Write :meth:`rows` into rows ``start:`` of the stacked ``A`` and ``lower``.

        From a packed state (``state.packed_terms``), the compiled rows read ``[F | f_0]``
        in its buffer, with no array made for ``contact_force``.
        """
        packed = getattr(state, 'packed_terms', None)
        if packed is not None:
            terms, layout = packed
            if layout is not self._packed_layout:
                # contact_force's shape, checked once per layout
                check_rows(state.contact_force.offset, self._force_rows, 'contact_force')
                self._packed_layout = layout
                self._force_start = layout.start('contact_force_augmented')
            self._block.check(A, lower, start, len(self.names), layout, self.family)
            pyramid_rows_packed(
                self._negative_faces,
                terms,
                self._force_start,
                self.normal_force_margin,
                A,
                lower,
                start,
            )
            return
        contact_force = state.contact_force
        check_rows(contact_force.offset, self._force_rows, 'contact_force')
        check_block(A, lower, start, len(self.names), contact_force.matrix.shape[1], self.family)
        pyramid_rows_into(
            self._negative_faces,
            contact_force.matrix,
            contact_force.offset,
            self.normal_force_margin,
            A,
            lower,
            start,
        )

    def values(self, state: GraspState, u: np.ndarray) -> BarrierValues:
        """Margins ``h_ij`` (N) at the contact forces ``f_c(u)`` the torque u produces."""
        n = len(self.contact_names)
        packed = getattr(state, 'packed_terms', None)
        if packed is None:
            forces = state.contact_force(u)
        else:
            # f_c(u) from the packed [F | f_0] (the views state.contact_force is made of,
            # without building that AffineMap: most of this call's time on a fresh state).
            m = packed[1].n_joints
            augmented = state.contact_force_augmented
            forces = augmented[:, :m] @ u + augmented[:, m]
        if self.torsional_friction is None:
            forces = forces.reshape(n, 3, 1)
        else:  # per contact (f_x, f_y, f_n, tau), as the rows read them
            forces = np.column_stack((forces[:3 * n].reshape(n, 3), forces[3 * n:]))[..., None]
        return BarrierValues(np.matmul(self._negative_faces, forces).reshape(-1), self.names)


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

    With ``N_i`` the negated face normals of contact i (rows × w)::

        A[i, j] = N_i[j] F_i,     lower[i, j] = eps - N_i[j] f_0,i

    rows contact-major, face by face, in one compiled loop instead of batched numpy
    products. ``F_i`` is rows ``3i .. 3i + 2`` of F (per contact ``(f_x, f_y, f_n)``) and,
    for soft fingers (w = 4), row ``3n + i`` (the torque tau_i about the contact normal).

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
