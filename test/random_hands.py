"""Seeded random hands: URDF text, model parameters and a touching initial grasp.

:func:`random_hand` draws a fixed-base hand of 3–5 fingers with 3–4 revolute joints each
(abduction about the finger's x axis or a twist about its z axis, then flexions about y; axis
signs random, some axes tilted off the coordinate axes), random link lengths, masses and
inertias (boxes with their inertial frames turned), a fingertip sphere of radius 1–3 cm
declared as the distal link's ``<collision><sphere>`` away from the link's origin (for some
fingers on the tip link instead, off the tip frame's origin), and a tip frame
(``finger<i>_tip``, on a fixed child link, massive or not) with z towards the object. Some
seeds permute the command joint order, write the fingers into the URDF out of contact order,
or tilt gravity up to 0.6 rad off -z.

The grasp is built backwards, so that it touches exactly: the object (a box of three edge
lengths or a sphere) is placed first and a contact point chosen per finger on it (a box's
side faces, inside their edges; a sphere around its equator); each finger's posture is drawn,
its kinematics evaluated here (numpy, not Pinocchio), and the finger's base placed so that its
sphere centre lies one fingertip radius off the contact point along the surface normal. Joint
limits are drawn around that posture, and the tip frame is turned so its z axis points at
the object (tilted by up to 0.8 rad). The hand's link data are kept for the tests'
independent mass matrix (:meth:`RandomHand.mass_matrix`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import math
from pathlib import Path
from typing import Any

import numpy as np
import pinocchio as pin

#: Fingertip chart limits of every random hand: a margin of 0.15 rad from the chart's poles.
WORKSPACE = {
    'model.fingertip_workspace.a_min': -math.pi / 2 + 0.15,
    'model.fingertip_workspace.a_max': math.pi / 2 - 0.15,
    'model.fingertip_workspace.b_min': -math.pi,
    'model.fingertip_workspace.b_max': 0.0,
}
GRAVITY = (0.0, 0.0, -9.81)
#: Side faces of a box, the order a finger's azimuth picks them in (object frame).
SIDE_FACES = {'+x': (0, 1.0), '+y': (1, 1.0), '-x': (0, -1.0), '-y': (1, -1.0)}


def rotation_about(axis: np.ndarray, angle: float) -> np.ndarray:
    """Rodrigues' rotation by ``angle`` (rad) about the unit ``axis``."""
    k = np.asarray(axis, dtype=float)
    K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
    return np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * K @ K


def frame_with_z(z: np.ndarray, spin: float) -> np.ndarray:
    """Return a rotation whose third column is the unit ``z``, turned by ``spin`` about it."""
    helper = np.eye(3)[int(np.argmin(np.abs(z)))]
    x = helper - (helper @ z) * z
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = math.cos(spin), math.sin(spin)
    return np.column_stack((c * x + s * y, -s * x + c * y, z))


def _number(x: float) -> str:
    return repr(float(x))


def _vector(v: np.ndarray) -> str:
    return ' '.join(_number(x) for x in v)


@dataclass(frozen=True)
class Link:
    """A body of the hand: mass (kg), centre of mass and inertia about it in its own frame."""

    name: str
    mass: float
    com: np.ndarray
    inertia: np.ndarray
    inertia_rotation: np.ndarray

    def urdf(self) -> str:
        """Return the ``<inertial>`` element, its inertia in a turned frame."""
        inertia = self.inertia_rotation.T @ self.inertia @ self.inertia_rotation
        rpy = pin.rpy.matrixToRpy(self.inertia_rotation)
        values = ' '.join(
            f'{name}="{_number(inertia[i, j])}"'
            for name, (i, j) in (
                ('ixx', (0, 0)),
                ('ixy', (0, 1)),
                ('ixz', (0, 2)),
                ('iyy', (1, 1)),
                ('iyz', (1, 2)),
                ('izz', (2, 2)),
            )
        )
        return (
            f'    <inertial>\n      <origin xyz="{_vector(self.com)}" rpy="{_vector(rpy)}"/>\n'
            f'      <mass value="{_number(self.mass)}"/>\n'
            f'      <inertia {values}/>\n    </inertial>\n'
        )


def box_link(rng: np.random.Generator, name: str, length: float, width: float) -> Link:
    """Return a box link of section ``width`` along z for ``length`` m (plastic and motors)."""
    length = max(length, width)
    mass = rng.uniform(900.0, 2000.0) * length * width * width
    inertia = mass / 12.0 * np.diag([width**2 + length**2, width**2 + length**2, 2.0 * width**2])
    com = np.array([*rng.uniform(-0.002, 0.002, 2), 0.5 * length])
    turn = rotation_about(np.eye(3)[rng.integers(3)], rng.uniform(-0.5, 0.5))
    # inertia about the com in link axes; the URDF states it in the turned frame.
    return Link(name, float(mass), com, inertia, turn)


@dataclass(frozen=True)
class Finger:
    """One finger: a chain of revolute joints from the palm, a fingertip sphere at its end.

    Attributes:
        name: ``finger<i>``.
        base_position: Joint 1's origin in the palm frame, m.
        base_rotation: Joint 1's origin frame in the palm frame.
        axes: Joint axes, each in its own joint frame (unit).
        offsets: From joint j's frame to joint j+1's origin (along z), m; one fewer than axes.
        links: The body each joint moves, in joint order.
        sphere_centre: Fingertip sphere centre in the distal link's frame, m.
        radius: Fingertip sphere radius, m.
        tip_origin: Tip frame origin in the distal link's frame, m.
        tip_rotation: Tip frame axes in the distal link's frame.
        tip_link: The tip link's own inertial (None: a massless frame).
        sphere_on_tip: Whether the sphere is declared on the tip link (else the distal link).
        lower, upper, effort: Joint limits, rad and N·m.
    """

    name: str
    base_position: np.ndarray
    base_rotation: np.ndarray
    axes: list[np.ndarray]
    offsets: list[float]
    links: list[Link]
    sphere_centre: np.ndarray
    radius: float
    tip_origin: np.ndarray
    tip_rotation: np.ndarray
    tip_link: Link | None
    lower: np.ndarray
    upper: np.ndarray
    effort: np.ndarray
    sphere_on_tip: bool = False

    @property
    def joint_names(self) -> list[str]:
        """``finger<i>_joint<j>``, j from 1."""
        return [f'{self.name}_joint{j + 1}' for j in range(len(self.axes))]

    def link_frames(self, q: np.ndarray) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """``(R_link_to_palm, p_link_in_palm, axis_in_palm)`` of each joint's body at ``q``."""
        R, p = self.base_rotation, self.base_position
        frames = []
        for j, axis in enumerate(self.axes):
            R = R @ rotation_about(axis, q[j])
            frames.append((R, p, R @ axis))
            if j < len(self.offsets):
                p = p + R @ np.array([0.0, 0.0, self.offsets[j]])
        return frames

    def sphere_centre_in_palm(self, q: np.ndarray) -> np.ndarray:
        """Fingertip sphere centre at ``q``, palm frame, m."""
        R, p, _ = self.link_frames(q)[-1]
        return p + R @ self.sphere_centre

    def bodies(self, q: np.ndarray) -> list[tuple[Link, np.ndarray, np.ndarray, int]]:
        """``(link, R_link_to_palm, p_link_in_palm, joints moving it)`` of each massive body."""
        frames = self.link_frames(q)
        found = [
            (link, R, p, j + 1)
            for j, (link, (R, p, _)) in enumerate(zip(self.links, frames, strict=True))
        ]
        if self.tip_link is not None:
            R, p, _ = frames[-1]
            found.append(
                (self.tip_link, R @ self.tip_rotation, p + R @ self.tip_origin, len(self.axes))
            )
        return found

    def urdf(self) -> str:
        """Return the finger's joints and links."""
        parts = []
        parent = 'palm'
        for j, (axis, link) in enumerate(zip(self.axes, self.links, strict=True)):
            if j == 0:
                xyz, rpy = self.base_position, pin.rpy.matrixToRpy(self.base_rotation)
            else:
                xyz, rpy = np.array([0.0, 0.0, self.offsets[j - 1]]), np.zeros(3)
            parts.append(
                f'  <joint name="{self.joint_names[j]}" type="revolute">\n'
                f'    <parent link="{parent}"/>\n    <child link="{link.name}"/>\n'
                f'    <origin xyz="{_vector(xyz)}" rpy="{_vector(rpy)}"/>\n'
                f'    <axis xyz="{_vector(axis)}"/>\n'
                f'    <limit lower="{_number(self.lower[j])}" upper="{_number(self.upper[j])}" '
                f'effort="{_number(self.effort[j])}" velocity="6.0"/>\n  </joint>\n'
            )
            last = j == len(self.axes) - 1
            collision = (
                self._collision(self.sphere_centre) if last and not self.sphere_on_tip else ''
            )
            parts.append(f'  <link name="{link.name}">\n{link.urdf()}{collision}  </link>\n')
            parent = link.name
        tip = f'{self.name}_tip'
        parts.append(
            f'  <joint name="{tip}_joint" type="fixed">\n    <parent link="{parent}"/>\n'
            f'    <child link="{tip}"/>\n    <origin xyz="{_vector(self.tip_origin)}" '
            f'rpy="{_vector(pin.rpy.matrixToRpy(self.tip_rotation))}"/>\n  </joint>\n'
            f'  <link name="{tip}">\n{self.tip_link.urdf() if self.tip_link else ""}'
        )
        if self.sphere_on_tip:
            parts.append(
                self._collision(self.tip_rotation.T @ (self.sphere_centre - self.tip_origin))
            )
        parts.append('  </link>\n')
        return ''.join(parts)

    def _collision(self, centre: np.ndarray) -> str:
        """Return the fingertip's ``<collision><sphere>`` centred at ``centre`` (link frame)."""
        turn = _vector(np.array([0.3, -0.2, 0.1]))
        return (
            f'    <collision>\n      <origin xyz="{_vector(centre)}" rpy="{turn}"/>\n'
            f'      <geometry><sphere radius="{_number(self.radius)}"/></geometry>\n'
            '    </collision>\n'
        )


@dataclass(frozen=True)
class RandomHand:
    """A random hand, its object and the initial grasp (see the module docstring).

    Attributes:
        seed: The generator's seed.
        fingers: The fingers, in contact order.
        palm: The palm's inertial.
        shape: ``"box"`` or ``"sphere"``.
        edge_lengths: A box's ``(l_x, l_y, l_z)``, m (None for a sphere).
        object_radius: A sphere's radius, m (None for a box).
        object_mass: kg.
        faces: Per contact, the box face it touches (None for a sphere).
        friction_coefficient: mu.
        joint_names: The command order (a permutation of the fingers' joints for some seeds).
        q0: Initial joint angles in ``joint_names`` order, rad.
        p_object: Initial object position, palm frame, m.
        R_object: Initial object orientation.
        declare_faces: Whether ``model.contact_faces`` lists the faces (else ``nearest``).
        gravity: Gravity in the palm frame, m/s² (tilted off -z for some seeds).
        urdf_order: The order the fingers are written in the URDF (contact order for most).
    """

    seed: int
    fingers: list[Finger]
    palm: Link
    shape: str
    edge_lengths: tuple[float, float, float] | None
    object_radius: float | None
    object_mass: float
    faces: list[str | None]
    friction_coefficient: float
    joint_names: list[str]
    q0: np.ndarray
    p_object: np.ndarray
    R_object: np.ndarray
    declare_faces: bool
    gravity: tuple[float, float, float] = GRAVITY
    urdf_order: tuple[int, ...] | None = None

    @property
    def n_fingers(self) -> int:
        """Number of fingers (contacts) n."""
        return len(self.fingers)

    @property
    def contact_names(self) -> list[str]:
        """``finger<i>``."""
        return [finger.name for finger in self.fingers]

    def finger_q(self, q: np.ndarray) -> list[np.ndarray]:
        """Split ``q`` (``joint_names`` order) into each finger's joint angles."""
        index = {name: k for k, name in enumerate(self.joint_names)}
        return [np.array([q[index[name]] for name in f.joint_names]) for f in self.fingers]

    def sphere_centres(self, q: np.ndarray) -> np.ndarray:
        """Fingertip sphere centres at ``q`` (this module's kinematics), (n, 3), m."""
        return np.array(
            [
                f.sphere_centre_in_palm(qf)
                for f, qf in zip(self.fingers, self.finger_q(q), strict=True)
            ]
        )

    def urdf(self) -> str:
        """Return the URDF text."""
        order = self.urdf_order or range(self.n_fingers)
        body = ''.join(self.fingers[k].urdf() for k in order)
        return (
            f'<?xml version="1.0"?>\n<robot name="random_hand_{self.seed}">\n'
            f'  <link name="palm">\n{self.palm.urdf()}  </link>\n{body}</robot>\n'
        )

    def write(self, directory: Path, text: str | None = None) -> Path:
        """Write the URDF (or ``text``) as ``random_hand_<seed>.urdf`` in ``directory``."""
        path = Path(directory) / f'random_hand_{self.seed}.urdf'
        path.write_text(self.urdf() if text is None else text)
        return path

    def model_parameters(self, urdf_path: Path) -> dict[str, Any]:
        """Return the ``model.*`` parameters of this hand and object (dotted names)."""
        params: dict[str, Any] = {
            'model.urdf_file': str(urdf_path),
            'model.joint_names': list(self.joint_names),
            'model.fingertip_frames': [f'{name}_tip' for name in self.contact_names],
            'model.contact_names': self.contact_names,
            'model.object.shape': self.shape,
            'model.object.mass': self.object_mass,
            'model.friction_coefficient': self.friction_coefficient,
            'model.gravity': [float(x) for x in self.gravity],
            'model.palm_frame': '',
            'model.object_frame': 'object',
            **WORKSPACE,
        }
        if self.shape == 'box':
            params['model.object.edge_lengths'] = list(self.edge_lengths)
            params['model.contact_faces'] = list(self.faces) if self.declare_faces else ['nearest']
        else:
            params['model.object.size'] = 2.0 * self.object_radius
        return params

    def initial_parameters(self) -> dict[str, Any]:
        """Return the ``initial.*`` parameters of the grasp (quaternion x, y, z, w)."""
        x, y, z, w = pin.Quaternion(self.R_object).coeffs()
        return {
            'initial.joint_positions': [float(x) for x in self.q0],
            'initial.object_position': [float(x) for x in self.p_object],
            'initial.object_orientation': [float(x), float(y), float(z), float(w)],
        }

    def mass_matrix(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(M_h, g)`` at ``q`` from this module's kinematics and link data (not Pinocchio).

        ``M_h = sum_k m_k J_v,k^T J_v,k + J_w,k^T I_k J_w,k`` over the bodies (J at their
        centres of mass, ``I_k`` in palm axes) and ``g = -sum_k m_k J_v,k^T gravity``, in
        ``joint_names`` order.
        """
        index = {name: k for k, name in enumerate(self.joint_names)}
        m = len(self.joint_names)
        M, g = np.zeros((m, m)), np.zeros(m)
        gravity = np.array(self.gravity)
        for finger, qf in zip(self.fingers, self.finger_q(q), strict=True):
            frames = finger.link_frames(qf)
            columns = [index[name] for name in finger.joint_names]
            for link, R, p, moved_by in finger.bodies(qf):
                com = p + R @ link.com
                J_v, J_w = np.zeros((3, m)), np.zeros((3, m))
                for j in range(moved_by):
                    _, p_joint, axis = frames[j]
                    J_w[:, columns[j]] = axis
                    J_v[:, columns[j]] = np.cross(axis, com - p_joint)
                M += link.mass * J_v.T @ J_v + J_w.T @ (R @ link.inertia @ R.T) @ J_w
                g -= link.mass * J_v.T @ gravity
        return M, g


def _axes(rng: np.random.Generator, n_joints: int, tilted: bool) -> tuple[list, np.ndarray]:
    """Joint axes of a finger and the sign each flexion takes to bend towards the palm axis."""
    first = np.array([1.0, 0.0, 0.0]) if rng.random() < 0.7 else np.array([0.0, 0.0, 1.0])
    axes = [first * rng.choice([-1.0, 1.0])]
    signs = [1.0]
    for _ in range(n_joints - 1):
        sign = rng.choice([-1.0, 1.0])
        axes.append(np.array([0.0, sign, 0.0]))
        signs.append(sign)
    if tilted:
        axes = [a + rng.normal(0.0, 0.08, 3) for a in axes]
        axes = [a / np.linalg.norm(a) for a in axes]
    return axes, np.array(signs)


def _contacts(rng, shape, n, sizes, R_object):
    """Per finger: contact point (object frame), outward normal (object frame), face label."""
    azimuths = 2.0 * math.pi * np.arange(n) / n + rng.uniform(0, 2 * math.pi)
    azimuths += rng.uniform(-0.25, 0.25, n) * 2.0 * math.pi / n
    found = []
    for azimuth in azimuths:
        direction = np.array([math.cos(azimuth), math.sin(azimuth), 0.0])
        if shape == 'sphere':
            elevation = rng.uniform(-0.35, 0.35)
            normal = np.array(
                [
                    math.cos(elevation) * direction[0],
                    math.cos(elevation) * direction[1],
                    math.sin(elevation),
                ]
            )
            found.append((sizes * normal, normal, None))
            continue
        # The side face whose outward normal (palm frame) is nearest the finger's azimuth.
        in_object = R_object.T @ direction
        label = max(SIDE_FACES, key=lambda f: SIDE_FACES[f][1] * in_object[SIDE_FACES[f][0]])
        axis, sign = SIDE_FACES[label]
        other = 1 - axis
        half = 0.5 * np.asarray(sizes)
        point = np.zeros(3)
        point[axis] = sign * half[axis]
        lateral = in_object[other] / max(abs(in_object[axis]), 1e-9) * half[axis]
        point[other] = np.clip(lateral, -0.6 * half[other], 0.6 * half[other])
        point[other] += rng.uniform(-0.1, 0.1) * half[other]
        point[2] = rng.uniform(-0.4, 0.4) * half[2]
        normal = np.zeros(3)
        normal[axis] = sign
        found.append((point, normal, label))
    return found


def random_hand(seed: int) -> RandomHand:
    """Draw the hand, object and touching grasp of ``seed`` (module docstring)."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(3, 6))
    shape = 'box' if seed % 2 == 0 else 'sphere'
    p_object = np.array([*rng.uniform(-0.01, 0.01, 2), rng.uniform(0.08, 0.14)])
    if shape == 'box':
        edges = tuple(float(x) for x in rng.uniform(0.04, 0.09, 3))
        sizes = np.array(edges)
        R_object = rotation_about(np.array([0, 0, 1.0]), rng.uniform(-math.pi, math.pi))
        tilt_axis = np.array([*rng.normal(size=2), 0.0])
        tilt = rotation_about(tilt_axis / np.linalg.norm(tilt_axis), rng.uniform(0, 0.4))
        R_object = tilt @ R_object
        radius_object = None
    else:
        radius_object = float(rng.uniform(0.025, 0.05))
        sizes = radius_object
        edges = None
        R_object = pin.exp3(rng.uniform(-math.pi, math.pi, 3))
    contacts = _contacts(rng, shape, n, sizes, R_object)
    tilted = bool(rng.random() < 0.5)
    fingers, q_fingers = [], []
    for i, (point, normal, _) in enumerate(contacts):
        name = f'finger{i + 1}'
        k = int(rng.integers(3, 5))
        axes, signs = _axes(rng, k, tilted)
        width = rng.uniform(0.012, 0.02)
        lengths = [rng.uniform(0.0, 0.01)] + [rng.uniform(0.025, 0.055) for _ in range(k - 1)]
        names = ['knuckle'] + [f'phalanx{j}' for j in range(1, k - 1)] + ['distal']
        links = [
            box_link(rng, f'{name}_{part}', L, width)
            for part, L in zip(names, lengths, strict=True)
        ]
        q = np.empty(k)
        q[0] = rng.uniform(-0.25, 0.25)
        bends = rng.uniform(0.25, 0.6, k - 1) if k == 4 else rng.uniform(0.3, 0.9, k - 1)
        q[1:] = signs[1:] * bends
        radius = float(rng.uniform(0.01, 0.03))
        sphere = np.array(
            [*rng.uniform(-0.004, 0.004, 2), lengths[-1] + rng.uniform(-0.004, 0.006)]
        )
        n_palm = R_object @ normal
        target = p_object + R_object @ point + radius * n_palm
        inward = -np.array([n_palm[0], n_palm[1], 0.0])
        base_rotation = rotation_about(np.array([0, 0, 1.0]), math.atan2(inward[1], inward[0]))
        # The finger with its base at the palm origin: where its sphere centre is at q.
        probe = Finger(
            name=name,
            base_position=np.zeros(3),
            base_rotation=base_rotation,
            axes=axes,
            offsets=lengths[:-1],
            links=links,
            sphere_centre=sphere,
            radius=radius,
            tip_origin=sphere,
            tip_rotation=np.eye(3),
            tip_link=None,
            lower=q - 1.0,
            upper=q + 1.0,
            effort=np.ones(k),
        )
        base = target - probe.sphere_centre_in_palm(q)
        R_distal = probe.link_frames(q)[-1][0]
        z_tip = rotation_about(
            frame_with_z(-n_palm, 0.0)[:, int(rng.integers(2))], rng.uniform(-0.8, 0.8)
        ) @ (-n_palm)
        tip_rotation = R_distal.T @ frame_with_z(z_tip, rng.uniform(-math.pi, math.pi))
        tip_link = box_link(rng, f'{name}_tip', radius, radius) if rng.random() < 0.5 else None
        sphere_on_tip = bool(rng.random() < 0.3)
        # On the tip link, the sphere is off the tip frame's origin by up to 3 mm.
        tip_origin = sphere + rng.uniform(-0.003, 0.003, 3) if sphere_on_tip else sphere
        fingers.append(
            replace(
                probe,
                base_position=base,
                tip_rotation=tip_rotation,
                tip_link=tip_link,
                tip_origin=tip_origin,
                sphere_on_tip=sphere_on_tip,
                lower=q - rng.uniform(0.4, 0.9, k),
                upper=q + rng.uniform(0.4, 0.9, k),
                effort=rng.uniform(0.6, 1.5, k),
            )
        )
        q_fingers.append(q)
    palm = Link('palm', 0.4, np.array([0, 0, -0.01]), np.diag([1.2e-3, 1.2e-3, 2.3e-3]), np.eye(3))
    joint_names = [name for finger in fingers for name in finger.joint_names]
    q0 = np.concatenate(q_fingers)
    if rng.random() < 0.4:
        order = rng.permutation(len(joint_names))
        joint_names = [joint_names[k] for k in order]
        q0 = q0[order]
    gravity = np.array(GRAVITY)
    if rng.random() < 0.3:
        gravity = rotation_about(np.array([1.0, 0.0, 0.0]), rng.uniform(-0.6, 0.6)) @ gravity
    urdf_order = tuple(int(k) for k in rng.permutation(n)) if rng.random() < 0.3 else None
    return RandomHand(
        seed=seed,
        fingers=fingers,
        palm=palm,
        shape=shape,
        edge_lengths=edges,
        object_radius=radius_object,
        object_mass=float(rng.uniform(0.04, 0.15)),
        faces=[face for _, _, face in contacts],
        friction_coefficient=float(rng.uniform(0.7, 1.0)),
        joint_names=joint_names,
        q0=q0,
        p_object=p_object,
        R_object=R_object,
        declare_faces=shape == 'box' and bool(rng.random() < 0.5),
        gravity=tuple(float(x) for x in gravity),
        urdf_order=urdf_order,
    )


#: The scenario file the random scenarios take every non-model value from.
TEMPLATE = Path(__file__).resolve().parent.parent / 'config' / 'four_finger_box.yaml'


def _nested(dotted: dict[str, Any]) -> dict[str, Any]:
    """``{'a.b': 1}`` as ``{'a': {'b': 1}}``."""
    tree: dict[str, Any] = {}
    for name, value in dotted.items():
        *path, last = name.split('.')
        node = tree
        for key in path:
            node = node.setdefault(key, {})
        node[last] = value
    return tree


def scenario_document(hand: RandomHand, urdf_path: Path, duration: float = 0.3) -> dict[str, Any]:
    """Return the nodes' parameter file of ``hand`` (the example box scenario's other values).

    The reference moves the object by 2 mm and 0.02 rad (the fingers are small).
    """
    import yaml

    document = yaml.safe_load(TEMPLATE.read_text())
    document['/**']['ros__parameters'] = _nested(hand.model_parameters(urdf_path))
    sim = document['hand_sim_node']['ros__parameters']
    sim.update(_nested(hand.initial_parameters()))
    sim['duration'] = float(duration)
    nominal = document['nominal_controller_node']['ros__parameters']
    nominal['reference']['amplitude'] = [0.0, 0.0, 0.002, 0.0, 0.0, 0.02]
    return document


def write_scenario(
    hand: RandomHand, directory: Path, duration: float = 0.3, urdf_text: str | None = None
) -> Path:
    """Write the URDF and the scenario file of ``hand`` into ``directory``; return the latter."""
    import yaml

    urdf = hand.write(directory, urdf_text)
    path = Path(directory) / f'random_hand_{hand.seed}.yaml'
    path.write_text(yaml.safe_dump(scenario_document(hand, urdf, duration), sort_keys=False))
    return path
