"""Contacts of spherical fingertips evaluated by compiled closed forms, and which to use.

:class:`~grasp_safety_filter.model.contact_stack.ContactStack` evaluates Montana's kinematics
for any surfaces with stacked numpy calls. For spherical fingertips on flat faces (the
paper's cube) or on a sphere object, the same formulas have closed forms, evaluated contact
by contact in compiled kernels (:mod:`grasp_safety_filter.model.rolling_kernels`,
:mod:`grasp_safety_filter.model.sphere_object_kernels`): the same outputs, in the same order.
:func:`contact_stack` picks the evaluation for a grasp's contacts.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from grasp_safety_filter.model.contact_stack import (
    ContactStack,
    StackedContactGeometry,
    StackedRollingRates,
)
from grasp_safety_filter.model.packed_terms import sphere_on_plane_terms, sphere_on_sphere_terms
from grasp_safety_filter.model.rolling import ContactPair
from grasp_safety_filter.model.rolling_kernels import (
    sphere_on_plane_contacts,
    sphere_on_plane_geometry,
    sphere_on_plane_rates,
)
from grasp_safety_filter.model.sphere_object_kernels import (
    sphere_on_sphere_contacts,
    sphere_on_sphere_geometry,
    sphere_on_sphere_rates,
)
from grasp_safety_filter.model.surface_stacks import FlatStack, SphereStack
from grasp_safety_filter.model.surfaces import FlatSurface, SphereSurface


class ClosedFormStack(ContactStack):
    """Spherical fingertips on one kind of object surface, by compiled closed forms.

    A subclass names its kernels (``geometry_kernel``, ``contacts_kernel``), each taking the
    fingertips' and object's poses (and twists) followed by :attr:`surface_arrays`, its
    one-pass terms kernel (``terms_kernel``: :mod:`grasp_safety_filter.model.packed_terms`,
    which takes :attr:`surface_arrays` in the same place), and gives :meth:`rolling_rates`.
    """

    geometry_kernel: Any
    contacts_kernel: Any
    terms_kernel: Any
    _surface_arrays: tuple[np.ndarray, ...]

    @property
    def surface_arrays(self) -> tuple[np.ndarray, ...]:
        """Return the kernels' constants: the object surfaces', then the fingertip radii, m."""
        return self._surface_arrays

    def geometry(
        self,
        p_fingertip_in_palm: np.ndarray,
        R_fingertip_to_palm: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
    ) -> StackedContactGeometry:
        """:meth:`ContactStack.geometry`, by the compiled closed forms."""
        return StackedContactGeometry(
            *self.geometry_kernel(
                p_fingertip_in_palm,
                R_fingertip_to_palm,
                p_object_in_palm,
                R_object_to_palm,
                *self._surface_arrays,
            )
        )

    def kinematics(
        self,
        p_fingertip_in_palm: np.ndarray,
        R_fingertip_to_palm: np.ndarray,
        twist_fingertip: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        twist_object: np.ndarray,
    ) -> tuple[StackedContactGeometry, StackedRollingRates]:
        """:meth:`ContactStack.kinematics` in one compiled pass."""
        arrays = self.contacts_kernel(
            p_fingertip_in_palm,
            R_fingertip_to_palm,
            twist_fingertip,
            p_object_in_palm,
            R_object_to_palm,
            twist_object,
            *self._surface_arrays,
        )
        return StackedContactGeometry(*arrays[:7]), StackedRollingRates(*arrays[7:])


class SphereOnPlaneStack(ClosedFormStack):
    """Spherical fingertips on flat object faces (the paper's cube).

    :func:`~grasp_safety_filter.model.rolling_kernels.sphere_on_plane_geometry` and
    :func:`~grasp_safety_filter.model.rolling_kernels.sphere_on_plane_rates`, whose
    docstrings give the formulas.

    Args:
        contacts: The contact pairs; every object surface must be a
            :class:`~grasp_safety_filter.model.surfaces.FlatSurface`.
    """

    geometry_kernel = staticmethod(sphere_on_plane_geometry)
    contacts_kernel = staticmethod(sphere_on_plane_contacts)
    terms_kernel = staticmethod(sphere_on_plane_terms)

    def __init__(self, contacts: Sequence[ContactPair]) -> None:
        super().__init__(contacts)
        if not isinstance(self.object_surfaces, FlatStack):
            raise TypeError('SphereOnPlaneStack: every object surface must be a FlatSurface')
        self._radius = np.ascontiguousarray(self.fingertips.radius, dtype=float)
        #: Each face's origin (n, 3), m, and ``[e1, e2, n]`` (n, 3, 3) in the object frame,
        #: and each fingertip's radius (n,), m.
        self._surface_arrays = (
            np.ascontiguousarray(self.object_surfaces.origin, dtype=float),
            np.array(self.object_surfaces.frame(None), dtype=float),
            self._radius,
        )

    def rolling_rates(
        self, geometry: StackedContactGeometry, w_relative_in_contact: np.ndarray
    ) -> StackedRollingRates:
        """:meth:`ContactStack.rolling_rates`, by the compiled closed forms."""
        return StackedRollingRates(
            *sphere_on_plane_rates(
                geometry.xi_cf, geometry.psi, w_relative_in_contact, self._radius
            )
        )


class SphereOnSphereStack(ClosedFormStack):
    """Spherical fingertips on a sphere object (one chart per contact).

    :func:`~grasp_safety_filter.model.sphere_object_kernels.sphere_on_sphere_geometry` and
    :func:`~grasp_safety_filter.model.sphere_object_kernels.sphere_on_sphere_rates`, whose
    docstrings give the formulas.

    Args:
        contacts: The contact pairs; every object surface must be a
            :class:`~grasp_safety_filter.model.surfaces.SphereSurface` about the object's
            origin.
    """

    geometry_kernel = staticmethod(sphere_on_sphere_geometry)
    contacts_kernel = staticmethod(sphere_on_sphere_contacts)
    terms_kernel = staticmethod(sphere_on_sphere_terms)

    def __init__(self, contacts: Sequence[ContactPair]) -> None:
        super().__init__(contacts)
        if not isinstance(self.object_surfaces, SphereStack):
            raise TypeError('SphereOnSphereStack: every object surface must be a SphereSurface')
        self._radius = np.ascontiguousarray(self.fingertips.radius, dtype=float)
        self._object_radius = np.ascontiguousarray(self.object_surfaces.radius, dtype=float)
        #: Each contact's chart orientation ``R_chart_to_object`` (n, 3, 3), the object's
        #: radius per contact (n,), m, and each fingertip's radius (n,), m.
        self._surface_arrays = (
            np.array(self.object_surfaces.R_chart_to_body, dtype=float),
            self._object_radius,
            self._radius,
        )

    def rolling_rates(
        self, geometry: StackedContactGeometry, w_relative_in_contact: np.ndarray
    ) -> StackedRollingRates:
        """:meth:`ContactStack.rolling_rates`, by the compiled closed forms."""
        return StackedRollingRates(
            *sphere_on_sphere_rates(
                geometry.xi_cf,
                geometry.xi_co,
                geometry.psi,
                w_relative_in_contact,
                self._object_radius,
                self._radius,
            )
        )


def contact_stack(contacts: Sequence[ContactPair]) -> ContactStack:
    """Stack ``contacts`` for batched evaluation.

    The closed forms of :class:`SphereOnPlaneStack` when every object surface is flat, of
    :class:`SphereOnSphereStack` when every one is a sphere, else the general
    :class:`~grasp_safety_filter.model.contact_stack.ContactStack`.
    """
    kinds = {type(contact.object_surface) for contact in contacts}
    if kinds == {FlatSurface}:
        return SphereOnPlaneStack(contacts)
    if kinds == {SphereSurface}:
        return SphereOnSphereStack(contacts)
    return ContactStack(contacts)
