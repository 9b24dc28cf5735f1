"""What a grasp looks like at one instant, in the palm frame: the shapes and arrows to draw.

:class:`SceneBuilder` turns a state of a :class:`~grasp_safety_filter.model.grasp_model.
GraspModel` (joint angles, the object's pose, optionally the contact forces) into a
:class:`GraspScene`: the hand's links as its URDF draws them (Pinocchio's visual geometry:
boxes, spheres, cylinders, capsules; the collision geometry where there is no visual), the
kinematic chain from joint to joint, the fingertip spheres and the object of the contact
model, and per contact its point, its normal (into the object) and the force on the object.
Everything is in the palm frame P, m and N. Pictures (:mod:`~grasp_safety_filter.view.
pictures`) and markers draw a scene; nothing here draws.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
import pinocchio as pin

#: Shapes of the URDF's geometry a scene carries (others, e.g. meshes, are left to the chain).
SHAPE_KINDS = ('box', 'sphere', 'cylinder', 'capsule')


@dataclass(frozen=True)
class Shape:
    """One solid of the scene.

    Attributes:
        kind: One of :data:`SHAPE_KINDS`.
        size: Box: half extents (3,); sphere: (radius,); cylinder and capsule:
            (radius, half length along the shape's z), m.
        R_shape_to_palm: Orientation, (3, 3).
        p_shape_in_palm: Centre, (3,), m.
        name: The URDF geometry's name, a contact's name or ``"object"``.
    """

    kind: str
    size: np.ndarray
    R_shape_to_palm: np.ndarray
    p_shape_in_palm: np.ndarray
    name: str


@dataclass(frozen=True)
class GraspScene:
    """A grasp at one instant, palm frame (module docstring).

    Attributes:
        t: Time, s.
        links: The URDF's solids.
        chain: Segments from each joint's parent joint to it, (J, 2, 3), m.
        p_joint_in_palm: Each model joint's origin, by joint name, m.
        fingertips: The contact model's fingertip spheres, one per contact.
        object: The object (box or sphere), None if the model has no object shape.
        p_contact_in_palm: Contact points, (n, 3), m.
        R_contact_to_palm: Contact frames, their z the normal into the object, (n, 3, 3).
        force_in_palm: Contact forces on the object, (n, 3), N; None if not given.
        contact_names: One per contact.
    """

    t: float
    links: tuple[Shape, ...]
    chain: np.ndarray
    p_joint_in_palm: dict[str, np.ndarray]
    fingertips: tuple[Shape, ...]
    object: Shape | None
    p_contact_in_palm: np.ndarray
    R_contact_to_palm: np.ndarray
    force_in_palm: np.ndarray | None
    contact_names: tuple[str, ...]

    @property
    def normal_in_palm(self) -> np.ndarray:
        """Unit contact normals, into the object, (n, 3)."""
        return self.R_contact_to_palm[:, :, 2]

    def points(self) -> np.ndarray:
        """Every point the scene must show (solids' centres widened by their size), (N, 3)."""
        return np.vstack([self.chain.reshape(-1, 3), *_extents(self.links), self.grasp_points()])

    def grasp_points(self) -> np.ndarray:
        """Return the points of the object, fingertips and contacts (widened alike), (N, 3)."""
        solids = [*self.fingertips] + ([self.object] if self.object else [])
        return np.vstack([self.p_contact_in_palm, *_extents(solids)])


def _extents(solids: Sequence[Shape]) -> list[np.ndarray]:
    """Return each solid's centre widened by its largest size, both ways, m."""
    return [s.p_shape_in_palm + sign * float(np.max(s.size)) for s in solids for sign in (-1, 1)]


def friction_cone(
    p_contact: np.ndarray, normal: np.ndarray, mu: float, height: float, segments: int = 16
) -> np.ndarray:
    """Return a friction cone's surface (3, 2, segments + 1): apex at the contact, m.

    The cone of the forces on the object the contact can transmit, ``|f_t| <= mu f_n``,
    ``height`` long along the normal (into the object); its rim closed (last = first).
    """
    e1 = np.cross(normal, [1.0, 0.0, 0.0] if abs(normal[0]) < 0.9 else [0.0, 1.0, 0.0])
    e1 /= np.linalg.norm(e1)
    e2 = np.cross(normal, e1)
    angle = np.linspace(0.0, 2.0 * np.pi, segments + 1)
    rim = normal[:, None] + mu * (np.outer(e1, np.cos(angle)) + np.outer(e2, np.sin(angle)))
    along = np.array([0.0, height])
    return p_contact[:, None, None] + rim[:, None, :] * along[None, :, None]


def _shape_of(geometry: Any) -> tuple[str, np.ndarray] | None:
    """Return a coal geometry's kind and size, or None for kinds a scene does not carry."""
    kind = type(geometry).__name__.lower()
    if kind == 'box':
        return kind, np.array(geometry.halfSide, dtype=float)
    if kind == 'sphere':
        return kind, np.array([geometry.radius])
    if kind in ('cylinder', 'capsule'):
        return kind, np.array([geometry.radius, geometry.halfLength])
    return None


class SceneBuilder:
    """Builds the scenes of one model (its URDF's geometry is read once).

    Args:
        model: A :class:`~grasp_safety_filter.model.grasp_model.GraspModel` whose hand knows
            its URDF (``hand.urdf_path``).
    """

    def __init__(self, model: Any) -> None:
        self.model = model
        hand = model.hand
        self._pin_model = hand.model
        self._pin_data = hand.model.createData()
        geometry = pin.buildGeomFromUrdf(
            hand.model, str(hand.urdf_path), pin.GeometryType.VISUAL
        )
        if geometry.ngeoms == 0:
            geometry = pin.buildGeomFromUrdf(
                hand.model, str(hand.urdf_path), pin.GeometryType.COLLISION
            )
        self._geometry = geometry
        self._geometry_data = pin.GeometryData(geometry)
        self._solids = [
            (index, shape)
            for index, item in enumerate(geometry.geometryObjects)
            if (shape := _shape_of(item.geometry)) is not None
        ]
        self._joint_ids = [hand.model.getJointId(name) for name in model.joint_names]

    def scene(
        self,
        t: float,
        q: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        force_in_contact: np.ndarray | None = None,
    ) -> GraspScene:
        """Return the scene at joint angles ``q`` (m,), rad, and the object's pose.

        ``force_in_contact``: contact forces on the object ``(f_x, f_y, f_n)``, contact
        frames, (n, 3), N.

        Raises:
            ValueError: The model refuses the configuration (shapes, a degenerate contact).
        """
        model, hand = self.model, self.model.hand
        q = np.asarray(q, dtype=float)
        # Geometry only (no dynamics): the model's contact geometry and Pinocchio's fingertips.
        contacts = model.contact_geometry(q, p_object_in_palm, R_object_to_palm)
        p_fingertip, R_fingertip, _ = hand.fingertip_placements(q)
        data = self._pin_data
        q_pin = np.empty(self._pin_model.nq)
        q_pin[hand.pinocchio_index] = q
        pin.forwardKinematics(self._pin_model, data, q_pin)
        pin.updateGeometryPlacements(
            self._pin_model, data, self._geometry, self._geometry_data
        )
        links = tuple(
            Shape(
                kind,
                size,
                np.array(self._geometry_data.oMg[index].rotation),
                np.array(self._geometry_data.oMg[index].translation),
                self._geometry.geometryObjects[index].name,
            )
            for index, (kind, size) in self._solids
        )
        parents = self._pin_model.parents
        chain = np.array(
            [
                (data.oMi[parents[j]].translation, data.oMi[j].translation)
                for j in range(1, self._pin_model.njoints)
            ]
        ).reshape(-1, 2, 3)
        joints = {
            name: np.array(data.oMi[j].translation)
            for name, j in zip(model.joint_names, self._joint_ids, strict=True)
        }
        fingertips = tuple(
            Shape('sphere', np.array([tip.radius]), R, p, name)
            for tip, R, p, name in zip(
                hand.fingertips, R_fingertip, p_fingertip, model.contact_names, strict=True
            )
        )
        R_contact = np.array([c.R_contact_to_palm for c in contacts])
        force = None
        if force_in_contact is not None:
            force = np.einsum('nij,nj->ni', R_contact, np.asarray(force_in_contact, dtype=float))
        return GraspScene(
            float(t),
            links,
            chain,
            joints,
            fingertips,
            self._object(p_object_in_palm, R_object_to_palm),
            np.array([c.p_contact_in_palm for c in contacts]),
            R_contact,
            force,
            tuple(model.contact_names),
        )

    def _object(self, p: np.ndarray, R: np.ndarray) -> Shape | None:
        shape = self.model.object_shape
        if shape is None:
            return None
        size = (
            np.array([shape.radius])
            if shape.kind == 'sphere'
            else 0.5 * np.array(shape.edge_lengths, dtype=float)
        )
        kind = 'sphere' if shape.kind == 'sphere' else 'box'
        return Shape(kind, size, np.array(R, dtype=float), np.array(p, dtype=float), 'object')
