"""Object workspace: rolling contact points stay on their object surface, with a margin."""

from __future__ import annotations

from collections.abc import Callable, Sequence
import math
from typing import Any

import numpy as np

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints.base import (
    check_rows,
    finite_scalar,
    validate_names,
)
from grasp_safety_filter.control.constraints.box_barrier import BoxBarrier, planar_box
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.fingertip_workspace import GraspConfigError
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.surfaces import face_label, FlatSurface, SphereSurface, Surface

#: Row labels of a contact on a box face (chart coordinates (u, v), m), in row order.
FACE_ROWS: tuple[str, ...] = ('u_min', 'u_max', 'v_min', 'v_max')

#: Row labels of a contact on a sphere object (chart coordinates (a, b), rad), in row order.
SPHERE_ROWS: tuple[str, ...] = ('a_min', 'a_max', 'b_min', 'b_max')

#: Centre ``(a, b)`` of a sphere object's chart: the contact's normal when the chart was chosen.
SPHERE_CHART_CENTRE = (0.0, -math.pi / 2)


def object_surface_box(
    contact: str,
    surface: Surface,
    margin: float,
    sphere_half_widths: tuple[float, float],
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Return the box the contact's object coordinates must stay in, and its row labels.

    On a box face ``|u| <= h_u, |v| <= h_v`` (:attr:`FlatSurface.half_widths`, m) the box is
    ``|u| <= h_u - margin, |v| <= h_v - margin``. On a sphere object, in the contact's chart
    (centre ``(0, -pi/2)``, poles at ``a = ±pi/2``, cut at ``b = ±pi``), it is
    ``|a| <= w_a, |b + pi/2| <= w_b`` for ``sphere_half_widths = (w_a, w_b)``, rad.

    Args:
        contact: The contact's name (for error messages).
        surface: The object surface the contact is on.
        margin: Distance kept from a face's edges, m (> 0).
        sphere_half_widths: ``(w_a, w_b)``, each in (0, pi/2), rad.

    Returns:
        Lower and upper bounds, shape (2,) each, and the contact's four row labels.

    Raises:
        GraspConfigError: The margin leaves no face, or the chart box reaches a pole or the
            cut; the message names the contact, the face and the values.
    """
    if isinstance(surface, FlatSurface):
        half = np.asarray(surface.half_widths, dtype=float)
        label = face_label(surface) or 'plane'
        if not np.all(np.isfinite(half)):
            raise GraspConfigError(
                f'object_workspace: contact {contact!r}: expected a face of finite extent, got '
                f'the unbounded plane {label} (half widths {half.tolist()} m)'
            )
        if not margin < float(half.min()):
            raise GraspConfigError(
                f"'object_workspace.margin': contact {contact!r} on face {label}: expected a "
                f'margin smaller than every half extent of the face {half.tolist()} m, got '
                f'{margin!r} m'
            )
        return -(half - margin), half - margin, FACE_ROWS
    if isinstance(surface, SphereSurface):
        parameters = ('sphere_a_half_width', 'sphere_b_half_width')
        for name, width in zip(parameters, sphere_half_widths, strict=True):
            if not 0.0 < width < math.pi / 2:
                raise GraspConfigError(
                    f"'object_workspace.{name}': contact {contact!r} on the sphere: expected a "
                    f"half width in (0, pi/2) rad, off the chart's poles and cut, got {width!r}"
                )
        centre = np.array(SPHERE_CHART_CENTRE)
        widths = np.array(sphere_half_widths, dtype=float)
        return centre - widths, centre + widths, SPHERE_ROWS
    raise GraspConfigError(
        f'object_workspace: contact {contact!r}: expected a box face or a sphere, got '
        f'{type(surface).__name__}'
    )


class ObjectWorkspaceBarrier(BoxBarrier):
    """Keep each contact's object coordinates ``xi_co,i = (x_i, y_i)`` inside a box.

    Four barriers per contact i (rows in this order, contact-major), with the box
    ``lower_i <= xi_co,i <= upper_i``::

        x_min: h = x_i - lower_i,x     h_dot =  x_i_dot     h_ddot(u) =  x_i_ddot(u)
        x_max: h = upper_i,x - x_i     h_dot = -x_i_dot     h_ddot(u) = -x_i_ddot(u)
        y_min: h = y_i - lower_i,y     h_dot =  y_i_dot     h_ddot(u) =  y_i_ddot(u)
        y_max: h = upper_i,y - y_i     h_dot = -y_i_dot     h_ddot(u) = -y_i_ddot(u)

    each with ``B = h_dot + alpha_1(h)`` and the constraint::

        h_ddot(u) + alpha_1'(h) h_dot + alpha_2(B) >= 0

    with ``xi_co,i = state.xi_co[i]``, rates ``state.xi_co_dot[i]`` and ``u ↦ xi_co_ddot``
    = ``state.xi_co_ddot`` (the differentiated rolling equations). On a box face
    ``(x, y) = (u, v)``, h in m and rows in m/s²; :meth:`on_surfaces` shrinks the face by a
    margin. On a sphere object ``(x, y) = (a, b)`` in the contact's chart, h in rad and rows
    in rad/s². Row names ``"object_workspace/<contact>/u_min"`` (``u_max``, ``v_min``,
    ``v_max``; ``a_min``... on a sphere).

    A grasp model whose box faces are chosen at the first configuration it is given
    (``model.contact_faces: ["nearest"]``) gives each contact's face only then:
    :meth:`for_model` checks the margin against every face of the box at construction and
    takes each contact's bounds from its face at the first state.
    """

    family = 'object_workspace'
    state_fields = ('xi_co', 'xi_co_dot', 'xi_co_ddot')
    #: A packed state holds ``u ↦ xi_co_ddot`` too, in the surface's closed form
    #: (:func:`~grasp_safety_filter.model.packed_terms.packed_fields`).
    packed_fields = ('xi_co', 'xi_co_dot', 'xi_co_ddot_augmented')

    def __init__(
        self,
        contact_names: Sequence[str],
        lower: np.ndarray,
        upper: np.ndarray,
        row_labels: Sequence[Sequence[str]] | None = None,
        alpha1: ClassKFunction | None = None,
        alpha2: ClassKFunction | None = None,
    ) -> None:
        """Build the barrier rows of every contact.

        Args:
            contact_names: The n contact names, in the model's contact order.
            lower: Lower bounds on ``xi_co``, shape (n, 2) (m on a face, rad on a sphere).
            upper: Upper bounds, shape (n, 2), each > its lower bound.
            row_labels: Per contact, its four row labels (default :data:`FACE_ROWS`).
            alpha1: Extended class-K function of h (default cubic, gain 1).
            alpha2: Extended class-K function of B (default cubic, gain 1).

        Raises:
            ValueError: An argument is malformed; the message names it and the contact.
        """
        self.contact_names = validate_names(contact_names, 'contact_names')
        n = len(self.contact_names)
        bounds = {}
        for name, value in (('lower', lower), ('upper', upper)):
            array = np.array(value, dtype=float)
            if array.shape != (n, 2) or not np.all(np.isfinite(array)):
                raise ValueError(
                    f"'{name}': expected finite bounds of shape ({n}, 2), got {array.tolist()}"
                )
            bounds[name] = array
        for i in np.flatnonzero(np.any(bounds['upper'] <= bounds['lower'], axis=1)):
            raise ValueError(
                f"'upper': expected upper > lower for contact {self.contact_names[i]!r}, got "
                f"lower {bounds['lower'][i].tolist()} and upper {bounds['upper'][i].tolist()}"
            )
        labels = [tuple(FACE_ROWS)] * n if row_labels is None else [tuple(r) for r in row_labels]
        if len(labels) != n or any(len(r) != 4 for r in labels):
            raise ValueError(f"'row_labels': expected four labels per contact ({n}), got {labels}")
        self.lower, self.upper = bounds['lower'], bounds['upper']
        self._alphas = (alpha1, alpha2)
        # Gives the contacts' surfaces once the model has chosen them (see for_model).
        self._pending_surfaces: Callable[[], Sequence[Surface]] | None = None
        self._pending_parameters: tuple[float, tuple[float, float]] = (0.0, (0.0, 0.0))
        names = tuple(
            f'{self.family}/{contact}/{row}'
            for contact, rows in zip(self.contact_names, labels, strict=True)
            for row in rows
        )
        super().__init__(
            **planar_box(self.lower, self.upper),
            names=names,
            alpha1=alpha1 if alpha1 is not None else ClassKFunction(),
            alpha2=alpha2 if alpha2 is not None else ClassKFunction(),
        )

    @classmethod
    def on_surfaces(
        cls,
        contact_names: Sequence[str],
        surfaces: Sequence[Surface],
        margin: float,
        sphere_half_widths: tuple[float, float],
        alpha1: ClassKFunction | None = None,
        alpha2: ClassKFunction | None = None,
    ) -> ObjectWorkspaceBarrier:
        """Build the barrier of contacts on these object surfaces (:func:`object_surface_box`).

        Args:
            contact_names: The n contact names.
            surfaces: Each contact's object surface (a box face or a sphere chart).
            margin: Distance kept from a face's edges, m (> 0).
            sphere_half_widths: ``(w_a, w_b)`` of a sphere chart's box, rad.
            alpha1: Extended class-K function of h (default cubic, gain 1).
            alpha2: Extended class-K function of B (default cubic, gain 1).

        Raises:
            GraspConfigError: The margin or the half widths do not fit a contact's surface.
        """
        names = validate_names(contact_names, 'contact_names')
        margin = finite_scalar(margin, 'object_workspace.margin', 0.0, inclusive=False)
        if len(surfaces) != len(names):
            raise ValueError(
                f"'surfaces': expected one object surface per contact ({len(names)}), got "
                f'{len(surfaces)}'
            )
        boxes = [
            object_surface_box(name, surface, margin, sphere_half_widths)
            for name, surface in zip(names, surfaces, strict=True)
        ]
        return cls(
            names,
            [box[0] for box in boxes],
            [box[1] for box in boxes],
            [box[2] for box in boxes],
            alpha1,
            alpha2,
        )

    @classmethod
    def for_model(
        cls,
        model: Any,
        margin: float,
        sphere_half_widths: tuple[float, float],
        alpha1: ClassKFunction | None = None,
        alpha2: ClassKFunction | None = None,
    ) -> ObjectWorkspaceBarrier:
        """Build the barrier of a grasp model's contacts (:meth:`on_surfaces`).

        When the model has not chosen its contacts' box faces yet, the margin is checked
        against the smallest half extent of the box (every face's extents are at least
        that) and each contact's bounds are taken from its face at the first state.

        Args:
            model: A ``GraspModel``: ``contact_names``, ``contacts_bound``, ``contacts``
                and ``object_shape``.
            margin: Distance kept from a face's edges, m (> 0).
            sphere_half_widths: ``(w_a, w_b)`` of a sphere chart's box, rad.
            alpha1: Extended class-K function of h (default cubic, gain 1).
            alpha2: Extended class-K function of B (default cubic, gain 1).

        Raises:
            GraspConfigError: The margin or the half widths do not fit the object.
        """
        if model.contacts_bound:
            surfaces = [contact.object_surface for contact in model.contacts]
            return cls.on_surfaces(
                model.contact_names, surfaces, margin, sphere_half_widths, alpha1, alpha2
            )
        shape = model.object_shape
        if not shape.has_faces:
            surfaces = [SphereSurface(shape.radius)] * len(model.contact_names)
            return cls.on_surfaces(
                model.contact_names, surfaces, margin, sphere_half_widths, alpha1, alpha2
            )
        # Every face's half extents are at least half the box's shortest edge.
        half = 0.5 * float(min(shape.edge_lengths))
        if not margin < half:
            raise GraspConfigError(
                f"'object_workspace.margin': expected a margin smaller than every half extent "
                f"of every face of the {shape.kind} (the contacts' faces are chosen at the first "
                f'configuration), the smallest {half!r} m, got {margin!r} m'
            )
        # Until the faces are chosen, a square face of that half extent stands in.
        stand_in = FlatSurface(np.zeros(3), np.eye(3)[0], np.eye(3)[1], half_width=half)
        barrier = cls.on_surfaces(
            model.contact_names,
            [stand_in] * len(model.contact_names),
            margin,
            sphere_half_widths,
            alpha1,
            alpha2,
        )
        barrier._pending_surfaces = lambda: [c.object_surface for c in model.contacts]
        barrier._pending_parameters = (margin, sphere_half_widths)
        return barrier

    def _bind_surfaces(self) -> None:
        """Take each contact's bounds from the surface the model has chosen for it."""
        surfaces = self._pending_surfaces()
        margin, sphere_half_widths = self._pending_parameters
        bound = self.on_surfaces(
            self.contact_names, surfaces, margin, sphere_half_widths, *self._alphas
        )
        self.__dict__.update(bound.__dict__)

    def coordinates(self, state: GraspState) -> tuple[np.ndarray, np.ndarray, AffineMap]:
        """``(xi_co, xi_co_dot)`` flattened contact-major, and ``u ↦ xi_co_ddot``."""
        if self._pending_surfaces is not None:
            self._bind_surfaces()
        n = len(self.contact_names)
        check_rows(state.xi_co, n, 'xi_co')
        check_rows(state.xi_co_dot, n, 'xi_co_dot')
        check_rows(state.xi_co_ddot.offset, 2 * n, 'xi_co_ddot')
        return state.xi_co.reshape(-1), state.xi_co_dot.reshape(-1), state.xi_co_ddot
