"""A random finger per contact, placed on the palm to reach it, and the hand's URDF text.

Each finger is a chain of 3 or 4 revolute joints from a base frame on the palm plane
``z = 0`` whose x axis points at the object (turned by up to 0.3 rad about z and tilted by
up to 0.15 rad) and z axis up:

- ``<finger>_joint1``: abduction about the base's x axis, or (a third of the thumbs, a
  tenth of the others) a rotation about its z axis; a knuckle 0–15 mm long;
- 2 or 3 flexions about y (positive curls the finger towards the object), each joint's
  origin tilted by up to 0.1 rad in roll and yaw, links 20–60 mm long along z;
- the fingertip: a ``<collision><sphere>`` at the end of the distal link, and a fixed
  ``<finger>_tip`` frame at its centre whose orientation is set once the grasp is solved
  (:mod:`.grasp`).

The base's distance from the fingertip's centre is 55–90 % of the finger's reach (the sum
of its flexion links), so the posture that reaches it is neither stretched nor folded.
Links are boxes of 15–22 mm section and 0.6–0.9 kg/m (a 40 mm link weighs 24–36 g), the
knuckle 12 g, the fingertip 5–10 g; effort limits 0.5–1.5 N·m per finger, velocity limits
6 rad/s, no damping (as config/four_finger_hand.urdf).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
import xml.etree.ElementTree as ET

import numpy as np
from scipy.spatial.transform import Rotation

from grasp_tools.hands.objects import DrawRejectedError

#: Flexion link length, m.
LINK_LENGTH_RANGE = (0.02, 0.06)
#: The base's distance from the fingertip centre, as a share of the finger's reach.
REACH_SHARE_RANGE = (0.55, 0.9)
#: Least horizontal distance from the fingertip centre back to the base, m.
MIN_BASE_SETBACK = 0.015
VELOCITY_LIMIT = 6.0
KNUCKLE_MASS = 0.012


@dataclass(frozen=True)
class FingerDesign:
    """One finger's kinematics, inertia and limits.

    Attributes:
        name: ``"thumb"``, ``"finger1"``...
        first_axis: Axis of joint 1 in the base frame: ``(1, 0, 0)`` or ``(0, 0, 1)``.
        p_base_in_palm: Base frame origin, (3,), m.
        rpy_base_to_palm: Base frame orientation as URDF roll, pitch, yaw, rad.
        knuckle_length: Joint 1 to the first flexion joint, along z, m.
        link_lengths: Flexion links, proximal first, m.
        joint_rpy: Each flexion joint's origin rotation (roll, pitch, yaw), (k, 3), rad.
        link_masses: kg, one per flexion link.
        link_widths: Square section edge of each flexion link, m.
        tip_radius: Fingertip sphere radius, m.
        tip_mass: kg.
        effort_limit: N·m, every joint of the finger.
        rpy_tip_to_distal: The fixed tip frame's orientation on the distal link, rad.
        lower: Joint lower limits, (joints,), rad.
        upper: Joint upper limits, (joints,), rad.
    """

    name: str
    first_axis: tuple[float, float, float]
    p_base_in_palm: np.ndarray
    rpy_base_to_palm: np.ndarray
    knuckle_length: float
    link_lengths: np.ndarray
    joint_rpy: np.ndarray
    link_masses: np.ndarray
    link_widths: np.ndarray
    tip_radius: float
    tip_mass: float
    effort_limit: float
    rpy_tip_to_distal: np.ndarray = field(default_factory=lambda: np.zeros(3))
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    @property
    def n_joints(self) -> int:
        """Joints of the finger: joint 1 and the flexions."""
        return 1 + self.link_lengths.size

    @property
    def joint_names(self) -> list[str]:
        """``<name>_joint1``... in chain order."""
        return [f'{self.name}_joint{k + 1}' for k in range(self.n_joints)]

    @property
    def tip_frame(self) -> str:
        """The fingertip frame's (and link's) name."""
        return f'{self.name}_tip'

    @property
    def distal_link(self) -> str:
        """The link that carries the fingertip sphere."""
        return f'{self.name}_link{self.link_lengths.size}'

    def with_tip_and_limits(
        self, rpy_tip_to_distal: np.ndarray, lower: np.ndarray, upper: np.ndarray
    ) -> FingerDesign:
        """Return the finger with its tip frame turned and its joint limits set."""
        return replace(self, rpy_tip_to_distal=rpy_tip_to_distal, lower=lower, upper=upper)


def draw_finger(
    rng: np.random.Generator,
    name: str,
    p_tip_centre_in_palm: np.ndarray,
    n_outward_in_palm: np.ndarray,
    tip_radius: float,
    effort_limit: float,
    attempts: int = 30,
) -> FingerDesign:
    """Draw a finger whose base on the palm lets it reach ``p_tip_centre_in_palm``.

    The base lies behind the fingertip centre along the horizontal part of the object's
    outward normal there (so the finger comes from outside), up to 1 cm aside.

    Raises:
        DrawRejectedError: No drawn finger reaches the point from the palm in ``attempts`` draws.
    """
    thumb = name == 'thumb'
    rotation_first = rng.random() < (1.0 / 3.0 if thumb else 0.1)
    first_axis = (0.0, 0.0, 1.0) if rotation_first else (1.0, 0.0, 0.0)
    outward = np.array([n_outward_in_palm[0], n_outward_in_palm[1], 0.0])
    if np.linalg.norm(outward) < 1e-6:
        raise DrawRejectedError('contact normal vertical')
    outward /= np.linalg.norm(outward)
    aside = np.array([-outward[1], outward[0], 0.0])
    for _ in range(attempts):
        flexions = 2 if rng.random() < 0.4 else 3
        lengths = rng.uniform(*LINK_LENGTH_RANGE, size=flexions)
        knuckle = float(rng.uniform(0.0, 0.015))
        height = float(p_tip_centre_in_palm[2]) - knuckle
        distance = float(rng.uniform(*REACH_SHARE_RANGE)) * float(lengths.sum())
        if distance <= abs(height):
            continue
        setback = math.sqrt(distance**2 - height**2)
        if setback < MIN_BASE_SETBACK:
            continue
        p_base = p_tip_centre_in_palm + setback * outward + rng.uniform(-0.01, 0.01) * aside
        p_base[2] = 0.0
        inward = p_tip_centre_in_palm - p_base
        yaw = math.atan2(inward[1], inward[0]) + rng.uniform(-0.3, 0.3)
        widths = rng.uniform(0.015, 0.022, size=flexions)
        return FingerDesign(
            name=name,
            first_axis=first_axis,
            p_base_in_palm=p_base,
            rpy_base_to_palm=np.array([*rng.uniform(-0.15, 0.15, size=2), yaw]),
            knuckle_length=knuckle,
            link_lengths=lengths,
            joint_rpy=np.column_stack(
                (
                    rng.uniform(-0.1, 0.1, flexions),
                    np.zeros(flexions),
                    rng.uniform(-0.1, 0.1, flexions),
                )
            ),
            link_masses=rng.uniform(0.6, 0.9, size=flexions) * lengths,
            link_widths=widths,
            tip_radius=float(tip_radius),
            tip_mass=float(rng.uniform(0.005, 0.01)),
            effort_limit=float(effort_limit),
        )
    raise DrawRejectedError('out of reach')


def draw_joint_limits(rng: np.random.Generator, q0: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Limits around ``q0``: a range of 1–2.5 rad with q0 at 3–97 % of it (rad)."""
    width = rng.uniform(1.0, 2.5, size=q0.size)
    share = rng.uniform(0.03, 0.97, size=q0.size)
    return q0 - share * width, q0 + (1.0 - share) * width


def rpy_of(R: np.ndarray) -> np.ndarray:
    """URDF roll, pitch, yaw (fixed axes x, y, z) of a rotation matrix, rad."""
    return Rotation.from_matrix(R).as_euler('xyz')


def urdf_text(name: str, fingers: list[FingerDesign], comment: str = '') -> str:
    """Return the hand's URDF: a palm link and each finger's chain (module docstring).

    Fingers without limits yet get ±π (for solving the grasp before the limits are drawn).
    """
    robot = ET.Element('robot', name=name)
    if comment:
        robot.append(ET.Comment(f' {comment} '))
    palm = ET.SubElement(robot, 'link', name='palm')
    _inertial(palm, 0.35, (0.0, 0.0, -0.01), _box_inertia(0.35, 0.2, 0.2, 0.02))
    _visual_box(palm, (0.2, 0.2, 0.02), (0.0, 0.0, -0.01))
    for finger in fingers:
        _finger(robot, finger)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding='unicode') + '\n'


def _finger(robot: ET.Element, finger: FingerDesign) -> None:
    lower = finger.lower if finger.lower is not None else np.full(finger.n_joints, -math.pi)
    upper = finger.upper if finger.upper is not None else np.full(finger.n_joints, math.pi)
    names = finger.joint_names
    knuckle = f'{finger.name}_knuckle'
    _joint(
        robot, names[0], 'palm', knuckle, finger.p_base_in_palm, finger.rpy_base_to_palm,
        finger.first_axis, (lower[0], upper[0], finger.effort_limit),
    )  # fmt: skip
    link = ET.SubElement(robot, 'link', name=knuckle)
    _inertial(link, KNUCKLE_MASS, (0.0, 0.0, 0.0), np.full(3, 4.8e-7))
    parent, offset = knuckle, finger.knuckle_length
    for k, length in enumerate(finger.link_lengths):
        child = f'{finger.name}_link{k + 1}'
        _joint(
            robot, names[k + 1], parent, child, (0.0, 0.0, offset), finger.joint_rpy[k],
            (0.0, 1.0, 0.0), (lower[k + 1], upper[k + 1], finger.effort_limit),
        )  # fmt: skip
        link = ET.SubElement(robot, 'link', name=child)
        width, mass = finger.link_widths[k], finger.link_masses[k]
        centre = (0.0, 0.0, 0.5 * length)
        _inertial(link, mass, centre, _box_inertia(mass, width, width, length))
        _visual_box(link, (width, width, length), centre)
        parent, offset = child, length
    collision = ET.SubElement(link, 'collision')
    ET.SubElement(collision, 'origin', xyz=_numbers((0.0, 0.0, offset)), rpy='0 0 0')
    ET.SubElement(ET.SubElement(collision, 'geometry'), 'sphere', radius=repr(finger.tip_radius))
    tip_joint = ET.SubElement(robot, 'joint', name=f'{finger.tip_frame}_joint', type='fixed')
    ET.SubElement(tip_joint, 'parent', link=parent)
    ET.SubElement(tip_joint, 'child', link=finger.tip_frame)
    ET.SubElement(
        tip_joint, 'origin', xyz=_numbers((0.0, 0.0, offset)),
        rpy=_numbers(finger.rpy_tip_to_distal),
    )  # fmt: skip
    tip = ET.SubElement(robot, 'link', name=finger.tip_frame)
    sphere_inertia = np.full(3, 0.4 * finger.tip_mass * finger.tip_radius**2)
    _inertial(tip, finger.tip_mass, (0.0, 0.0, 0.0), sphere_inertia)
    visual = ET.SubElement(tip, 'visual')
    ET.SubElement(ET.SubElement(visual, 'geometry'), 'sphere', radius=repr(finger.tip_radius))


def _joint(
    robot: ET.Element,
    name: str,
    parent: str,
    child: str,
    xyz: tuple[float, ...] | np.ndarray,
    rpy: tuple[float, ...] | np.ndarray,
    axis: tuple[float, float, float],
    limits: tuple[float, float, float],
) -> None:
    joint = ET.SubElement(robot, 'joint', name=name, type='revolute')
    ET.SubElement(joint, 'parent', link=parent)
    ET.SubElement(joint, 'child', link=child)
    ET.SubElement(joint, 'origin', xyz=_numbers(xyz), rpy=_numbers(rpy))
    ET.SubElement(joint, 'axis', xyz=_numbers(axis))
    lower, upper, effort = limits
    ET.SubElement(
        joint, 'limit', lower=repr(float(lower)), upper=repr(float(upper)),
        effort=repr(float(effort)), velocity=repr(VELOCITY_LIMIT),
    )  # fmt: skip


def _inertial(
    link: ET.Element, mass: float, centre: tuple[float, ...], diagonal: np.ndarray
) -> None:
    inertial = ET.SubElement(link, 'inertial')
    ET.SubElement(inertial, 'origin', xyz=_numbers(centre), rpy='0 0 0')
    ET.SubElement(inertial, 'mass', value=repr(float(mass)))
    ixx, iyy, izz = (f'{float(x):.6e}' for x in diagonal)
    ET.SubElement(inertial, 'inertia', ixx=ixx, ixy='0', ixz='0', iyy=iyy, iyz='0', izz=izz)


def _visual_box(link: ET.Element, size: tuple[float, ...], centre: tuple[float, ...]) -> None:
    visual = ET.SubElement(link, 'visual')
    ET.SubElement(visual, 'origin', xyz=_numbers(centre), rpy='0 0 0')
    ET.SubElement(ET.SubElement(visual, 'geometry'), 'box', size=_numbers(size))


def _box_inertia(mass: float, x: float, y: float, z: float) -> np.ndarray:
    """Principal moments of a solid box of edges x, y, z (m) about its centre, kg·m²."""
    return mass / 12.0 * np.array([y * y + z * z, x * x + z * z, x * x + y * y])


def _numbers(values: tuple[float, ...] | np.ndarray) -> str:
    return ' '.join(repr(float(v)) for v in values)
