"""One generated hand and grasp: object, contacts, fingers, IK, limits, files, start-up check.

Hand ``i`` of seed ``s`` draws everything from ``numpy.random.default_rng([s, i])``:

1. the object (:func:`~.objects.draw_object`), 3–5 fingers and their contacts, the thumb's
   opposing the others (:func:`~.objects.draw_contacts`);
2. a finger per contact, its base placed on the palm to reach the fingertip sphere's centre
   one radius out of the surface along the normal (:func:`~.kinematics.draw_finger`);
3. the joint angles that put every sphere centre there, solved on the package's own hand
   model (:func:`~.ik.solve_fingertip_centres`);
4. each fingertip frame turned so that its contact lies at random fingertip coordinates
   ``|a| <= 1``, ``|b + π/2| <= 1`` rad (the workspace's centre is ``(0, -π/2)``);
5. joint limits around the solved angles, some near a limit
   (:func:`~.kinematics.draw_joint_limits`);
6. the URDF and the scenario file written, the contacts closed exactly by the model's
   ``project_to_contact``, and the scenario put through the nodes' parameter schemas and
   the start-up check every node makes (``load_initial_grasp``: joints inside their limits,
   fingertips on their faces and in their workspace, ranks, force closure).

A draw refused at any step (:class:`~.objects.DrawRejectedError`, or a finding of the start-up
check) is drawn again from the same generator; how many were and why is kept. Grasps that
pass are kept whether or not a controller can hold them.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters, NODE_SCHEMAS
from grasp_safety_filter.model.grasp_check import load_initial_grasp
from grasp_safety_filter.model.grasp_configuration import project_to_contact
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.hand import HandModel
from grasp_tools.hands.ik import solve_fingertip_centres, tip_rotation
from grasp_tools.hands.kinematics import (
    draw_finger,
    draw_joint_limits,
    FingerDesign,
    rpy_of,
    urdf_text,
)
from grasp_tools.hands.objects import (
    Contacts,
    draw_contacts,
    draw_object,
    DrawRejectedError,
    ObjectDesign,
)
from grasp_tools.hands.scenario import (
    scenario_document,
    SCENARIO_NAME,
    URDF_NAME,
    WORKSPACE,
    write_scenario,
)

#: Draws of one hand before giving up.
MAX_ATTEMPTS = 200
#: Fingertip coordinates' largest offset from the workspace's centre (0, -π/2), rad: the
#: contacts start anywhere from the fingertip's tip to 0.42 rad from its workspace's edge.
CONTACT_TILT = 1.0
#: Words of a start-up check's finding -> the rejection reason counted.
CHECK_REASONS = (
    ('no force closure', 'no force closure'),
    ('rank', 'singular grasp'),
    ('fingertip workspace', 'fingertip workspace'),
    ('beyond the edge', 'off its face'),
    ('not inside its limits', 'joint limits'),
    ('nearest face', 'wrong face'),
)


@dataclass(frozen=True)
class GeneratedHand:
    """A hand that passed, what it is, and the draws refused before it.

    Attributes:
        index: i of ``default_rng([seed, i])``.
        directory: Holds ``hand.urdf`` and ``scenario.yaml``.
        fingers: The fingers, thumb first.
        obj: The object.
        q0: The initial joint angles, rad.
        min_joint_margin: Smallest distance of a joint from a limit at the start, rad.
        min_workspace_margin: Smallest distance of a contact's fingertip coordinates from
            its workspace's bounds, rad.
        rejections: Why each refused draw was refused, and how many.
    """

    index: int
    directory: Path
    fingers: tuple[FingerDesign, ...]
    obj: ObjectDesign
    q0: np.ndarray
    min_joint_margin: float
    min_workspace_margin: float
    rejections: Counter[str]

    @property
    def scenario(self) -> Path:
        """The scenario parameter file."""
        return self.directory / SCENARIO_NAME

    def row(self) -> dict[str, Any]:
        """Return the hand's line of ``hands.csv``."""
        radii = [finger.tip_radius for finger in self.fingers]
        x, y, z = self.obj.edge_lengths
        return {
            'hand': self.index,
            'scenario': f'{self.directory.name}/{SCENARIO_NAME}',
            'fingers': len(self.fingers),
            'joints': self.q0.size,
            'object': self.obj.shape,
            'size_x': x,
            'size_y': y,
            'size_z': z,
            'mass': self.obj.mass,
            'mu': self.obj.friction_coefficient,
            'tip_radius_min': min(radii),
            'tip_radius_max': max(radii),
            'min_joint_margin': self.min_joint_margin,
            'min_workspace_margin': self.min_workspace_margin,
            'rejected': sum(self.rejections.values()),
            'rejections': '; '.join(f'{k} {v}' for k, v in sorted(self.rejections.items())),
        }


def generate_hand(seed: int, index: int, directory: Path) -> GeneratedHand:
    """Draw hand ``index`` of ``seed`` into ``directory`` (module docstring).

    Raises:
        RuntimeError: No draw passed in :data:`MAX_ATTEMPTS`.
    """
    rng = np.random.default_rng([seed, index])
    directory.mkdir(parents=True, exist_ok=True)
    rejections: Counter[str] = Counter()
    for _ in range(MAX_ATTEMPTS):
        try:
            return _attempt(rng, seed, index, directory, rejections)
        except DrawRejectedError as rejected:
            rejections[str(rejected)] += 1
    raise RuntimeError(
        f'hand {index} of seed {seed}: no draw passed in {MAX_ATTEMPTS} ({dict(rejections)})'
    )


def _attempt(
    rng: np.random.Generator,
    seed: int,
    index: int,
    directory: Path,
    rejections: Counter[str],
) -> GeneratedHand:
    obj = draw_object(rng)
    n_fingers = int(rng.integers(3, 6))
    contacts = draw_contacts(rng, obj, n_fingers)
    names = ['thumb', *(f'finger{k}' for k in range(1, n_fingers))]
    p_centres = contacts.p_tip_centre_in_palm
    fingers = [
        draw_finger(
            rng,
            name,
            p_centres[i],
            contacts.n_outward_in_palm[i],
            contacts.tip_radius[i],
            float(rng.uniform(0.5, 1.5)),
        )
        for i, name in enumerate(names)
    ]
    urdf_path = directory / URDF_NAME
    hand = _hand_model(urdf_path, fingers)
    q = solve_fingertip_centres(rng, hand, fingers, p_centres, obj)
    fingers = _tips_and_limits(rng, hand, fingers, contacts, q)
    header = _header(seed, index, fingers, obj)
    urdf_path.write_text(urdf_text(f'generated_hand_{index:03d}', fingers, header))
    scenario = directory / SCENARIO_NAME
    document = scenario_document(fingers, obj, contacts.faces, q)
    write_scenario(scenario, document, header)
    model = GraspModel.from_parameters(load_node_parameters(scenario, HAND_SIM_NODE))
    try:
        q = project_to_contact(model, q, obj.p_object_in_palm, obj.R_object_to_palm)
    except ConfigError:
        raise DrawRejectedError('contact projection') from None
    write_scenario(scenario, scenario_document(fingers, obj, contacts.faces, q), header)
    for node in NODE_SCHEMAS:  # a parameter file every node takes
        load_node_parameters(scenario, node)
    try:
        model, _ = load_initial_grasp(scenario)
    except ConfigError as error:
        raise DrawRejectedError(_check_reason(str(error))) from None
    lower = np.concatenate([finger.lower for finger in fingers])
    upper = np.concatenate([finger.upper for finger in fingers])
    return GeneratedHand(
        index=index,
        directory=directory,
        fingers=tuple(fingers),
        obj=obj,
        q0=q,
        min_joint_margin=float(np.minimum(q - lower, upper - q).min()),
        min_workspace_margin=_workspace_margin(model, q, obj),
        rejections=rejections,
    )


def _hand_model(urdf_path: Path, fingers: list[FingerDesign]) -> HandModel:
    """Write the fingers' URDF (tip frames unturned, limits ±π); return its hand model."""
    urdf_path.write_text(urdf_text('generated_hand', fingers))
    try:
        return HandModel(
            urdf_path,
            [name for finger in fingers for name in finger.joint_names],
            [finger.tip_frame for finger in fingers],
            np.array([0.0, 0.0, -9.81]),
        )
    except ConfigError as error:
        raise DrawRejectedError(f'hand model: {error}') from None


def _tips_and_limits(
    rng: np.random.Generator,
    hand: HandModel,
    fingers: list[FingerDesign],
    contacts: Contacts,
    q: np.ndarray,
) -> list[FingerDesign]:
    """Turn each tip frame to a random contact point on its fingertip; draw joint limits."""
    _, R_distal_to_palm, _ = hand.fingertip_placements(q)
    turned, start = [], 0
    for i, finger in enumerate(fingers):
        a = float(rng.uniform(-CONTACT_TILT, CONTACT_TILT))
        b = float(-0.5 * math.pi + rng.uniform(-CONTACT_TILT, CONTACT_TILT))
        R_tip_to_palm = tip_rotation(R_distal_to_palm[i], contacts.n_outward_in_palm[i], a, b)
        rpy = rpy_of(R_distal_to_palm[i].T @ R_tip_to_palm)
        lower, upper = draw_joint_limits(rng, q[start : start + finger.n_joints])
        turned.append(finger.with_tip_and_limits(rpy, lower, upper))
        start += finger.n_joints
    return turned


def _workspace_margin(model: GraspModel, q: np.ndarray, obj: ObjectDesign) -> float:
    """Smallest distance of a contact's (a, b) from its workspace bounds, rad."""
    margins = []
    for geometry in model.contact_geometry(q, obj.p_object_in_palm, obj.R_object_to_palm):
        a, b = geometry.xi_cf
        margins += [
            a - WORKSPACE['a_min'],
            WORKSPACE['a_max'] - a,
            b - WORKSPACE['b_min'],
            WORKSPACE['b_max'] - b,
        ]
    return float(min(margins))


def _check_reason(message: str) -> str:
    """Return the counted reason of a start-up check's message."""
    for words, reason in CHECK_REASONS:
        if words in message:
            return reason
    return 'start-up check'


def _header(seed: int, index: int, fingers: list[FingerDesign], obj: ObjectDesign) -> str:
    joints = sum(finger.n_joints for finger in fingers)
    size = ' x '.join(f'{1000 * x:.1f}' for x in obj.edge_lengths)
    what = f'a {size} mm box' if obj.shape == 'box' else f'a {size.split()[0]} mm sphere'
    return (
        f'Generated by python -m grasp_tools.hands (seed {seed}, hand {index}: drawn from\n'
        f'numpy.random.default_rng([{seed}, {index}])): a random hand, not designed with the\n'
        f'filter, of {len(fingers)} fingers ({joints} joints, the thumb first) holding\n'
        f'{what} of {obj.mass:.3f} kg, mu {obj.friction_coefficient:.2f}.'
    )
