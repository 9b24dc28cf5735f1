"""Fingertip workspace: rolling contacts stay on the fingertip surface (paper eq. 12, 22–26)."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
from numpy.typing import ArrayLike

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints.base import (
    check_rows,
    finite_vector,
    validate_names,
)
from grasp_safety_filter.control.constraints.box_barrier import BoxBarrier, planar_box
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.grasp_state import GraspState

#: Row labels per contact, in row order.
WORKSPACE_ROWS: tuple[str, ...] = ('a_min', 'a_max', 'b_min', 'b_max')


class FingertipWorkspaceBarrier(BoxBarrier):
    """Keep each contact's fingertip coordinates ``(a_i, b_i)`` inside a box.

    Four barriers per contact i (rows in this order, contact-major), with the contact's own
    box (each bound one value for every contact or one per contact)::

        a_min: h = a_i - a_min,i   h_dot =  a_i_dot     h_ddot(u) =  a_i_ddot(u)
        a_max: h = a_max,i - a_i   h_dot = -a_i_dot     h_ddot(u) = -a_i_ddot(u)
        b_min: h = b_i - b_min,i   h_dot =  b_i_dot     h_ddot(u) =  b_i_ddot(u)
        b_max: h = b_max,i - b_i   h_dot = -b_i_dot     h_ddot(u) = -b_i_ddot(u)

    each with ``B = h_dot + alpha_1(h)`` and the constraint::

        h_ddot(u) + alpha_1'(h) h_dot + alpha_2(B) >= 0

    with ``(a_i, b_i) = state.xi_cf[i]``, rates ``state.xi_cf_dot[i]`` and
    ``u ↦ (a_1_ddot, b_1_ddot, a_2_ddot, ...)`` = ``state.xi_cf_ddot`` (the differentiated
    rolling equations). Units: h in rad, rows in rad/s². For the paper's hemispherical
    fingertip the box is ``-pi/2 < a < pi/2, -pi < b < 0``; keep a away from ``+-pi/2``,
    where the surface parameterisation is singular. Row names:
    ``"fingertip_workspace/<contact>/a_min"`` (``a_max``, ``b_min``, ``b_max``).
    """

    family = 'fingertip_workspace'
    state_fields = ('xi_cf', 'xi_cf_dot', 'xi_cf_ddot')

    def __init__(
        self,
        contact_names: Sequence[str],
        a_min: float | ArrayLike,
        a_max: float | ArrayLike,
        b_min: float | ArrayLike,
        b_max: float | ArrayLike,
        alpha1: ClassKFunction | None = None,
        alpha2: ClassKFunction | None = None,
    ) -> None:
        """Build the barrier rows of every contact.

        Args:
            contact_names: The n contact (finger) names, in the model's contact order.
            a_min: Lower bound on the first fingertip coordinate a, rad: one for every
                contact or one per contact, (n,).
            a_max: Upper bound on a, rad, > a_min (one or n).
            b_min: Lower bound on the second fingertip coordinate b, rad (one or n).
            b_max: Upper bound on b, rad, > b_min (one or n).
            alpha1: Extended class-K function of h (default cubic, gain 1).
            alpha2: Extended class-K function of B (default cubic, gain 1).

        Raises:
            ValueError: An argument is malformed; the message names it.
        """
        self.contact_names = validate_names(contact_names, 'contact_names')
        n = len(self.contact_names)
        bounds = {
            name: finite_vector(value, n, name)
            for name, value in (
                ('a_min', a_min),
                ('a_max', a_max),
                ('b_min', b_min),
                ('b_max', b_max),
            )
        }
        for low, high in (('a_min', 'a_max'), ('b_min', 'b_max')):
            for contact, lo, hi in zip(
                self.contact_names, bounds[low].tolist(), bounds[high].tolist(), strict=True
            ):
                if not lo < hi:
                    raise ValueError(
                        f"'{high}' of contact {contact!r}: expected {high} > {low}, got "
                        f'{low} = {lo!r} and {high} = {hi!r}'
                    )
        #: Per contact, (n,) each, rad.
        self.a_min, self.a_max = bounds['a_min'], bounds['a_max']
        self.b_min, self.b_max = bounds['b_min'], bounds['b_max']
        names = tuple(
            f'{self.family}/{contact}/{row}'
            for contact in self.contact_names
            for row in WORKSPACE_ROWS
        )
        # xi_cf flattened contact-major: a_i at 2 i, b_i at 2 i + 1.
        super().__init__(
            **planar_box(
                np.column_stack((self.a_min, self.b_min)),
                np.column_stack((self.a_max, self.b_max)),
            ),
            names=names,
            alpha1=alpha1 if alpha1 is not None else ClassKFunction(),
            alpha2=alpha2 if alpha2 is not None else ClassKFunction(),
        )

    packed_fields = ('xi_cf', 'xi_cf_dot', 'xi_cf_ddot_augmented')

    def coordinates(self, state: GraspState) -> tuple[np.ndarray, np.ndarray, AffineMap]:
        """``(xi_cf, xi_cf_dot)`` flattened contact-major, and ``u ↦ xi_cf_ddot``."""
        n = len(self.contact_names)
        check_rows(state.xi_cf, n, 'xi_cf')
        check_rows(state.xi_cf_dot, n, 'xi_cf_dot')
        check_rows(state.xi_cf_ddot.offset, 2 * n, 'xi_cf_ddot')
        return state.xi_cf.reshape(-1), state.xi_cf_dot.reshape(-1), state.xi_cf_ddot
