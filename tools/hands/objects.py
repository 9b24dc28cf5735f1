"""The grasped object and where the fingertips touch it: a random box or sphere above the palm.

The palm frame P has z up (gravity along -z); the object frame O sits at the object's centre,
turned about z by a random yaw. A box has three edge lengths and a sphere a diameter of
3–10 cm; the object's lowest point is 1–3 cm above the palm plane ``z = 0``.

The thumb touches the object first in contact order; the other fingers face it:

- box: the thumb on one of the four side faces, the other fingers on the opposite face (at
  least one) or on the two faces beside it, every contact at least its fingertip radius
  (plus up to 3 mm) inside its face's edges;
- sphere: the thumb anywhere around the equator (elevation -0.3 to 0.5 rad), the others
  spread over 0.6–1.8 rad of azimuth around the opposite direction, so that the mean of
  their normals points against the thumb's (drawn again unless ``n_thumb . mean(n_others)
  <= -0.2``).

Fingertip spheres of radius 6–15 mm (at most the smallest half edge less 3 mm on a box) must
not overlap: the contacts are drawn again while two spheres come closer than 2 mm, and after
30 such draws the whole draw is refused (:class:`DrawRejectedError`).
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

#: Side faces of a box: label -> (axis, sign) of the outward normal in O.
SIDE_FACES = {'+x': (0, 1.0), '-x': (0, -1.0), '+y': (1, 1.0), '-y': (1, -1.0)}
#: Opposite and adjacent side faces.
OPPOSITE = {'+x': '-x', '-x': '+x', '+y': '-y', '-y': '+y'}
ADJACENT = {'+x': ('+y', '-y'), '-x': ('+y', '-y'), '+y': ('+x', '-x'), '-y': ('+x', '-x')}
#: Object size (box edge or sphere diameter), m.
SIZE_RANGE = (0.03, 0.10)
#: Fingertip sphere radius, m.
TIP_RADIUS_RANGE = (0.006, 0.015)
#: Least clearance between two fingertip spheres, m.
TIP_CLEARANCE = 0.002
#: Least ``-n_thumb . mean(n_others)``: the thumb's normal against the others' mean (a box's
#: is 0.25 at the least: one of four fingers on the opposite face, three beside it).
OPPOSITION = 0.2


class DrawRejectedError(Exception):
    """A draw that cannot become a valid grasp; its message is the short reason counted."""


@dataclass(frozen=True)
class ObjectDesign:
    """The object, its pose in the palm frame and its friction.

    Attributes:
        shape: ``"box"`` or ``"sphere"``.
        edge_lengths: Box edges along O's x, y, z, m; a sphere's diameter three times.
        mass: kg.
        friction_coefficient: μ of every contact.
        p_object_in_palm: Centre of O in P, (3,), m.
        yaw: O's rotation about P's z axis, rad.
    """

    shape: str
    edge_lengths: tuple[float, float, float]
    mass: float
    friction_coefficient: float
    p_object_in_palm: np.ndarray
    yaw: float

    @property
    def R_object_to_palm(self) -> np.ndarray:
        """Rotation of O in P, (3, 3)."""
        c, s = math.cos(self.yaw), math.sin(self.yaw)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    @property
    def quaternion_xyzw(self) -> list[float]:
        """O's orientation in P as ``(x, y, z, w)``."""
        return [0.0, 0.0, math.sin(0.5 * self.yaw), math.cos(0.5 * self.yaw)]

    @property
    def radius(self) -> float:
        """A sphere's radius, m."""
        return 0.5 * self.edge_lengths[0]


@dataclass(frozen=True)
class Contacts:
    """Where each fingertip touches the object, thumb first.

    Attributes:
        p_contact_in_palm: Contact points, (n, 3), m.
        n_outward_in_palm: The object's outward unit normals there, (n, 3).
        tip_radius: Fingertip sphere radii, (n,), m.
        faces: Each contact's box face label (``"+x"``...), or ``""`` on a sphere.
    """

    p_contact_in_palm: np.ndarray
    n_outward_in_palm: np.ndarray
    tip_radius: np.ndarray
    faces: tuple[str, ...]

    @property
    def p_tip_centre_in_palm(self) -> np.ndarray:
        """Fingertip sphere centres: one radius out of the surface, (n, 3), m."""
        return self.p_contact_in_palm + self.tip_radius[:, np.newaxis] * self.n_outward_in_palm


def draw_object(rng: np.random.Generator) -> ObjectDesign:
    """Draw a box or a sphere of 3–10 cm, 0.05–0.3 kg, μ 0.6–1.0, 1–3 cm above the palm."""
    shape = 'box' if rng.random() < 0.6 else 'sphere'
    if shape == 'box':
        edges = tuple(float(x) for x in rng.uniform(*SIZE_RANGE, size=3))
    else:
        diameter = float(rng.uniform(*SIZE_RANGE))
        edges = (diameter, diameter, diameter)
    mass = float(rng.uniform(0.05, 0.3))
    mu = float(rng.uniform(0.6, 1.0))
    clearance = float(rng.uniform(0.01, 0.03))
    p_object = np.array([0.0, 0.0, clearance + 0.5 * edges[2]])
    yaw = float(rng.uniform(-math.pi, math.pi)) if shape == 'box' else 0.0
    return ObjectDesign(shape, edges, mass, mu, p_object, yaw)  # type: ignore[arg-type]


def draw_contacts(
    rng: np.random.Generator, obj: ObjectDesign, n_fingers: int, attempts: int = 30
) -> Contacts:
    """Draw each finger's fingertip radius and contact, the thumb's first (module docstring).

    The contact points are drawn again (the radii kept) while two spheres overlap.

    Raises:
        DrawRejectedError: The spheres overlapped in each of ``attempts`` draws.
    """
    if obj.shape == 'box':
        half_min = 0.5 * min(obj.edge_lengths)
        radius_max = min(TIP_RADIUS_RANGE[1], half_min - 0.003)
    else:
        radius_max = TIP_RADIUS_RANGE[1]
    radii = rng.uniform(TIP_RADIUS_RANGE[0], radius_max, size=n_fingers)
    R = obj.R_object_to_palm
    for _ in range(attempts):
        if obj.shape == 'box':
            p_in_object, n_in_object, faces = _box_contacts(rng, obj, radii)
        else:
            p_in_object, n_in_object = _sphere_contacts(rng, obj, n_fingers)
            faces = ('',) * n_fingers
        contacts = Contacts(
            p_contact_in_palm=obj.p_object_in_palm + p_in_object @ R.T,
            n_outward_in_palm=n_in_object @ R.T,
            tip_radius=radii,
            faces=faces,
        )
        centres = contacts.p_tip_centre_in_palm
        gaps = np.linalg.norm(centres[:, np.newaxis] - centres[np.newaxis], axis=2)
        gaps -= radii[:, np.newaxis] + radii[np.newaxis]
        normals = contacts.n_outward_in_palm
        opposed = normals[0] @ normals[1:].mean(axis=0) <= -OPPOSITION
        if opposed and np.all(gaps[np.triu_indices(n_fingers, 1)] >= TIP_CLEARANCE):
            return contacts
    raise DrawRejectedError('fingertips overlap')


def _box_contacts(
    rng: np.random.Generator, obj: ObjectDesign, radii: np.ndarray
) -> tuple[np.ndarray, np.ndarray, tuple[str, ...]]:
    """Contact points and normals on the box's side faces (O frame), and their faces."""
    thumb_face = list(SIDE_FACES)[int(rng.integers(4))]
    faces = [thumb_face, OPPOSITE[thumb_face]]
    for _ in range(radii.size - 2):
        if rng.random() < 0.5:
            faces.append(OPPOSITE[thumb_face])
        else:
            faces.append(ADJACENT[thumb_face][int(rng.integers(2))])
    half = 0.5 * np.asarray(obj.edge_lengths)
    points, normals = [], []
    for face, radius in zip(faces, radii, strict=True):
        axis, sign = SIDE_FACES[face]
        normal = np.zeros(3)
        normal[axis] = sign
        margin = radius + rng.uniform(0.0, 0.003)
        point = normal * half[axis]
        for other in (1 - axis, 2):  # the face's in-plane axes: the other side axis, and z
            reach = max(half[other] - margin, 0.0)
            point[other] = rng.uniform(-reach, reach)
        points.append(point)
        normals.append(normal)
    return np.array(points), np.array(normals), tuple(faces)


def _sphere_contacts(
    rng: np.random.Generator, obj: ObjectDesign, n_fingers: int
) -> tuple[np.ndarray, np.ndarray]:
    """Contact points and normals on the sphere (O frame), the thumb opposing the others."""
    thumb_azimuth = rng.uniform(-math.pi, math.pi)
    span = rng.uniform(0.6, 1.8)
    others = n_fingers - 1
    offsets = np.linspace(-0.5 * span, 0.5 * span, others) + rng.uniform(-0.1, 0.1, others)
    azimuths = np.concatenate(([thumb_azimuth], thumb_azimuth + math.pi + offsets))
    elevations = rng.uniform(-0.3, 0.5, size=n_fingers)
    normals = np.column_stack(
        (
            np.cos(elevations) * np.cos(azimuths),
            np.cos(elevations) * np.sin(azimuths),
            np.sin(elevations),
        )
    )
    return obj.radius * normals, normals
