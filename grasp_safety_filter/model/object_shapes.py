"""The grasped object's shape: a box (a cube the special case) or a sphere, and its surfaces.

An :class:`ObjectShape` gives the object's inertia and, per contact, the surface a fingertip
touches, found from where the fingertip is:

- a box of edge lengths ``(l_x, l_y, l_z)`` (object frame O, centred on the centre of mass):
  the face nearest the fingertip sphere's centre ``p`` (O components), the one whose plane
  it lies farthest in front of, ``argmax_k,s (s p_k - l_k / 2)``
  (:func:`nearest_box_face`; for a centre outside the box and over a face, that face);
- a sphere of radius R_o: the sphere in a chart turned per contact so that its centre
  ``(a, b) = (0, -pi/2)`` is the contact's normal at the configuration the surfaces are
  chosen at, ``n = p / |p|`` (:func:`sphere_chart_centred_on`). The chart's poles
  (``|c_b| = 0``) and its cut ``b = ±pi`` are then a quarter circle (``pi R_o / 2``) away
  from that contact point, never in the contact region.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from grasp_safety_filter.model.rigid_object import RigidObject
from grasp_safety_filter.model.surfaces import (
    box_face,
    CUBE_FACE_AXES,
    face_label,
    FlatSurface,
    SphereSurface,
    Surface,
)

#: The shapes ``model.object.shape`` names.
OBJECT_SHAPES = ('cube', 'box', 'sphere')


def nearest_box_face(p_in_object: np.ndarray, edge_lengths: Sequence[float]) -> str:
    """Label (``"+x"``...) of the face of the box whose plane ``p`` lies farthest in front of.

    ``argmax over faces (s p_k - l_k / 2)`` for the face ``s e_k`` (s = ±1): the signed
    distance of ``p`` from the face's plane, positive outside.
    """
    p = np.asarray(p_in_object, dtype=float)
    half = 0.5 * np.asarray(edge_lengths, dtype=float)
    distances = {
        label: sign * p[axis] - half[axis] for label, (axis, sign) in CUBE_FACE_AXES.items()
    }
    return max(distances, key=distances.__getitem__)


def sphere_chart_centred_on(normal: np.ndarray) -> np.ndarray:
    """``R_chart_to_body`` whose chart centre is the unit direction ``normal`` (body frame).

    The columns ``(x_K, y_K, z_K)``: ``z_K = normal``; ``x_K`` the body axis least aligned
    with ``normal``, made orthogonal to it and normalised; ``y_K = z_K × x_K``.
    """
    z = np.asarray(normal, dtype=float)
    z = z / np.linalg.norm(z)
    axis = np.eye(3)[int(np.argmin(np.abs(z)))]
    x = axis - (axis @ z) * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


@dataclass(frozen=True)
class ObjectShape:
    """The object's shape and its dimensions, m.

    Attributes:
        kind: ``"cube"``, ``"box"`` or ``"sphere"``.
        edge_lengths: ``(l_x, l_y, l_z)`` of a box or cube; None for a sphere.
        radius: R_o of a sphere; None for a box.
    """

    kind: str
    edge_lengths: tuple[float, float, float] | None = None
    radius: float | None = None

    def __post_init__(self) -> None:
        if self.kind not in OBJECT_SHAPES:
            raise ValueError(f'expected one of {list(OBJECT_SHAPES)}, got {self.kind!r}')
        sizes = (self.radius,) if self.kind == 'sphere' else self.edge_lengths
        if sizes is None or not all(np.isfinite(x) and x > 0.0 for x in sizes):
            raise ValueError(
                f'expected positive finite dimensions of a {self.kind}, got {sizes!r}'
            )

    @property
    def has_faces(self) -> bool:
        """A box or cube: contacts are on flat faces."""
        return self.kind != 'sphere'

    def rigid_object(self, mass: float, gravity: np.ndarray) -> RigidObject:
        """Return the solid homogeneous body of this shape and ``mass`` (kg).

        Cube ``I = m l² / 6 I3``; box ``I = m / 12 diag(l_y² + l_z², l_x² + l_z², l_x² + l_y²)``;
        sphere ``I = 2/5 m R_o² I3``.
        """
        if self.kind == 'cube':
            return RigidObject.cube(mass, self.edge_lengths[0], gravity)
        if self.kind == 'sphere':
            return RigidObject.sphere(mass, 2.0 * self.radius, gravity)
        lx, ly, lz = self.edge_lengths
        inertia = mass / 12.0 * np.diag([ly**2 + lz**2, lx**2 + lz**2, lx**2 + ly**2])
        return RigidObject(mass, inertia, gravity)

    def face(self, label: str) -> FlatSurface:
        """Return the face ``label`` of a box or cube (:func:`box_face`)."""
        return box_face(label, self.edge_lengths)

    def nearest_face(self, p_in_object: np.ndarray) -> str:
        """:func:`nearest_box_face` of a box or cube."""
        return nearest_box_face(p_in_object, self.edge_lengths)

    def surface_at(self, p_in_object: np.ndarray) -> Surface:
        """Return the surface a fingertip centred at ``p`` (object frame, m) touches.

        A box's nearest face, or the sphere in a chart centred on ``p / |p|``.
        """
        if self.has_faces:
            return self.face(self.nearest_face(p_in_object))
        p = np.asarray(p_in_object, dtype=float)
        distance = float(np.linalg.norm(p))
        if distance == 0.0:
            raise ValueError("a fingertip centre is at the sphere object's centre")
        return SphereSurface(self.radius, sphere_chart_centred_on(p / distance))

    def describe(self, surface: Surface) -> str:
        """``"face +x"`` for a face of this box, ``"sphere"`` for the sphere."""
        if isinstance(surface, FlatSurface):
            label = face_label(surface)
            return 'plane' if label is None else f'face {label}'
        return 'sphere'
