"""The grasp's contact surfaces as the compiled pass takes them: its kernel and constants.

The model's contacts are spherical fingertips on one kind of object surface: the faces of a
box (the paper's cube) or a sphere about the object's centre of mass
(:class:`~grasp_safety_filter.model.object_shapes.ObjectShape`). :func:`compiled_contacts`
gives the one-pass terms kernel of that kind
(:func:`~grasp_safety_filter.model.packed_terms.sphere_on_plane_terms` or
:func:`~grasp_safety_filter.model.packed_terms.sphere_on_sphere_terms`) and the surfaces'
constants it takes, and refuses any other pairing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.model.packed_terms import sphere_on_plane_terms, sphere_on_sphere_terms
from grasp_safety_filter.model.rolling import ContactGeometry, ContactPair
from grasp_safety_filter.model.rolling_kernels import (
    object_coordinate_rate_terms,
    sphere_on_plane_geometry,
)
from grasp_safety_filter.model.sphere_object_kernels import sphere_on_sphere_geometry
from grasp_safety_filter.model.surfaces import FlatSurface, SphereSurface


@dataclass(frozen=True, eq=False)
class CompiledContacts:
    """Spherical fingertips on flat faces or on a sphere object, as the compiled pass takes them.

    Attributes:
        flat: True for flat faces, False for a sphere object.
        terms_kernel: The one-pass terms kernel of that kind.
        geometry_kernel: Its contact geometry alone (:func:`~grasp_safety_filter.model.
            rolling_kernels.sphere_on_plane_geometry` or :func:`~grasp_safety_filter.model.
            sphere_object_kernels.sphere_on_sphere_geometry`).
        surface_arrays: Its surface arguments: each face's origin (n, 3), m, and
            ``[e1, e2, n]`` (n, 3, 3) in the object frame; or each contact's chart
            ``R_chart_to_object`` (n, 3, 3) and the object's radius (n,), m; then each
            fingertip's radius (n,), m.
        fingertip_radius: Each fingertip's radius, (n,), m.
        object_radius: The object's radius per contact, (n,), m (zeros for flat faces).
    """

    flat: bool
    terms_kernel: Callable[..., None]
    geometry_kernel: Callable[..., tuple[np.ndarray, ...]]
    surface_arrays: tuple[np.ndarray, ...]
    fingertip_radius: np.ndarray
    object_radius: np.ndarray

    def geometry(
        self,
        p_fingertip_in_palm: np.ndarray,
        R_fingertip_to_palm: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
    ) -> list[ContactGeometry]:
        """Each contact's geometry at a configuration.

        Args:
            p_fingertip_in_palm: Fingertip sphere centres, (n, 3), m.
            R_fingertip_to_palm: Fingertip orientations, (n, 3, 3).
            p_object_in_palm: Object centre of mass, (3,), m.
            R_object_to_palm: Object orientation, (3, 3).

        Raises:
            ValueError: A fingertip centre is a sphere object's centre.
        """
        # New writable arrays: one specialisation of the kernel, whatever the caller's.
        arrays = self.geometry_kernel(
            np.array(p_fingertip_in_palm, dtype=float),
            np.array(R_fingertip_to_palm, dtype=float),
            np.array(p_object_in_palm, dtype=float),
            np.array(R_object_to_palm, dtype=float),
            *self.surface_arrays,
        )
        xi_cf, xi_co, psi, penetration, p_contact, R_pc, R_fc = arrays
        return [
            ContactGeometry(
                xi_cf[i], xi_co[i], float(psi[i]), float(penetration[i]), p_contact[i],
                R_pc[i], R_fc[i],
            )
            for i in range(xi_cf.shape[0])
        ]

    def object_rate_terms(
        self,
        xi_cf: np.ndarray,
        xi_co: np.ndarray,
        psi: np.ndarray,
        xi_cf_dot: np.ndarray,
        xi_co_dot: np.ndarray,
        psi_dot: np.ndarray,
        sliding_velocity: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray]:
        """Return ``(A, c)`` of ``xi_co_ddot = A xi_cf_ddot + c``, (n, 2, 2) and (n, 2).

        :func:`~grasp_safety_filter.model.rolling_kernels.object_coordinate_rate_terms` of
        these surfaces, whose docstring gives the arguments and units.
        """
        return object_coordinate_rate_terms(
            xi_cf,
            xi_co,
            psi,
            xi_cf_dot,
            xi_co_dot,
            psi_dot,
            sliding_velocity,
            self.fingertip_radius,
            self.object_radius,
            self.flat,
        )


def _array(values: Any) -> np.ndarray:
    """Return a new C-contiguous float64 array (the kernels' argument type)."""
    return np.ascontiguousarray(np.array(values, dtype=float))


def compiled_contacts(contacts: Sequence[ContactPair]) -> CompiledContacts:
    """Return the compiled pass's kernel and constants for ``contacts``.

    Raises:
        ValueError: A fingertip is not a sphere about its frame's origin, or the object
            surfaces are neither all flat faces nor all spheres about the object's origin.
    """
    if not contacts:
        raise ValueError('expected at least one contact')
    fingertips = [contact.fingertip for contact in contacts]
    if any(
        type(tip) is not SphereSurface
        or (tip.R_chart_to_body is not None and not np.allclose(tip.R_chart_to_body, np.eye(3)))
        for tip in fingertips
    ):
        raise ValueError("every fingertip must be a sphere in the paper's chart (SphereSurface)")
    radius = _array([tip.radius for tip in fingertips])
    surfaces = [contact.object_surface for contact in contacts]
    kinds = {type(surface) for surface in surfaces}
    if kinds == {FlatSurface}:
        frames = [surface.axes for surface in surfaces]
        return CompiledContacts(
            True,
            sphere_on_plane_terms,
            sphere_on_plane_geometry,
            (
                _array([surface.origin for surface in surfaces]),
                _array(frames),
                radius,
            ),
            radius,
            _array(np.zeros(len(surfaces))),
        )
    if kinds == {SphereSurface}:
        charts = [
            np.eye(3) if surface.R_chart_to_body is None else surface.R_chart_to_body
            for surface in surfaces
        ]
        object_radius = _array([surface.radius for surface in surfaces])
        return CompiledContacts(
            False,
            sphere_on_sphere_terms,
            sphere_on_sphere_geometry,
            (_array(charts), object_radius, radius),
            radius,
            object_radius,
        )
    raise ValueError(
        'the object surfaces must be all flat faces (a box) or all a sphere about the '
        f"object's centre, got {sorted(kind.__name__ for kind in kinds)}"
    )
