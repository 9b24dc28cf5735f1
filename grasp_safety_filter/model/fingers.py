"""The hand's joints grouped by finger, from the URDF's kinematic tree.

A finger with a contact is the set of commanded joints on the kinematic chain from the
URDF's root to its fingertip frame (``model.fingertip_frames``), labelled by its contact
name and listed base to tip. A commanded joint on no fingertip's chain (a free finger, or
a finger without a contact in this scenario) belongs to its own branch of the tree: the
subtree hanging off a fingertip chain or off the root, labelled by the branch's first link.
A joint on several fingertip chains (a wrist, a palm joint) is in each of those fingers.

Any number of joints per finger, listed in any order in ``model.joint_names``. Reads the
URDF's ``<joint>`` elements only (parent and child links, type): no Pinocchio, no ROS.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any
from xml.etree import ElementTree

from grasp_safety_filter.model.urdf import check_urdf_file, HandModelError


@dataclass(frozen=True)
class Finger:
    """The commanded joints of one finger.

    Attributes:
        label: The contact's name, or for a free finger its branch's first link.
        joints: Indices into ``model.joint_names`` (command order), base to tip.
        joint_names: The joints' names, in the same order.
        contact: Index of the finger's contact, or None for a free finger.
        free: A finger of the hand that touches nothing (its joints are on no fingertip's
            chain); False for a group of joints whose finger is not known.

    """

    label: str
    joints: tuple[int, ...]
    joint_names: tuple[str, ...]
    contact: int | None = None
    free: bool = False


@dataclass(frozen=True)
class _Joint:
    name: str
    parent: str
    child: str
    movable: bool


def _joints_by_child(robot: ElementTree.Element) -> dict[str, _Joint]:
    """Each link's parent joint, by the link's name (the root link has none)."""
    joints = {}
    for element in robot.findall('joint'):
        parent, child = element.find('parent'), element.find('child')
        if parent is None or child is None:
            raise HandModelError(
                f'model.urdf_file: joint {element.get("name")!r}: expected <parent link> and '
                '<child link>, got '
                + ('neither' if parent is None and child is None else 'only one')
            )
        joint = _Joint(
            str(element.get('name')),
            str(parent.get('link')),
            str(child.get('link')),
            element.get('type') != 'fixed',
        )
        joints[joint.child] = joint
    return joints


def _chain(link: str, by_child: Mapping[str, _Joint]) -> list[_Joint]:
    """Joints from the root to ``link`` (fixed ones included), root first."""
    chain: list[_Joint] = []
    seen = set()
    while link in by_child and link not in seen:
        seen.add(link)
        joint = by_child[link]
        chain.append(joint)
        link = joint.parent
    return chain[::-1]


def group_joints_by_finger(
    robot: ElementTree.Element,
    joint_names: Sequence[str],
    fingertip_frames: Sequence[str],
    contact_names: Sequence[str],
) -> list[Finger]:
    """Group the commanded joints by finger (module docstring).

    Args:
        robot: The URDF's ``<robot>`` element.
        joint_names: ``model.joint_names``: the commanded joints, command order.
        fingertip_frames: ``model.fingertip_frames``: per contact, a link or a joint (the
            frame Pinocchio makes of it) of the URDF.
        contact_names: ``model.contact_names``, one per fingertip frame.

    Returns:
        The fingers with a contact, in contact order, then the free fingers, in the order
        of their first joint in ``joint_names``. Every commanded joint is in at least one.

    Raises:
        HandModelError: A joint or fingertip frame that is not in the URDF, or a number of
            contact names other than the number of fingertip frames.

    """
    if len(contact_names) != len(fingertip_frames):
        raise HandModelError(
            f'model.contact_names: expected one name per fingertip frame '
            f'({len(fingertip_frames)}), got {len(contact_names)}'
        )
    by_child = _joints_by_child(robot)
    by_name = {joint.name: joint for joint in by_child.values()}
    links = {str(link.get('name')) for link in robot.findall('link')}
    for name in joint_names:
        if name not in by_name or not by_name[name].movable:
            raise HandModelError(
                f'model.joint_names: joint {name!r} is not a movable joint of the URDF'
            )
    index = {name: k for k, name in enumerate(joint_names)}
    fingers = []
    on_chains: set[str] = set()
    for contact, (frame, label) in enumerate(zip(fingertip_frames, contact_names, strict=True)):
        if frame in links:
            chain = _chain(frame, by_child)
        elif frame in by_name:
            chain = [*_chain(by_name[frame].parent, by_child), by_name[frame]]
        else:
            raise HandModelError(
                f'model.fingertip_frames: frame {frame!r} is neither a link nor a joint of '
                'the URDF'
            )
        on_chains.update(joint.name for joint in chain)
        commanded = [joint.name for joint in chain if joint.name in index]
        fingers.append(_finger(label, commanded, index, contact))
    branches: dict[str, list[str]] = {}
    for name in joint_names:
        if name in on_chains:
            continue
        chain = _chain(by_name[name].child, by_child)
        # A fingertip chain holds every ancestor of its joints: the joints of ``chain`` on
        # one are its first ones, and the branch starts at the first joint after them.
        top = sum(joint.name in on_chains for joint in chain)
        branches.setdefault(chain[top].child, []).append(name)
    for label, names in branches.items():
        depth = {name: len(_chain(by_name[name].child, by_child)) for name in names}
        ordered = sorted(names, key=lambda name: (depth[name], index[name]))
        fingers.append(_finger(label, ordered, index, None))
    return fingers


def _finger(
    label: str, names: Sequence[str], index: Mapping[str, int], contact: int | None
) -> Finger:
    return Finger(
        label, tuple(index[name] for name in names), tuple(names), contact, free=contact is None
    )


def fingers_from_parameters(params: Mapping[str, Any]) -> list[Finger]:
    """Group the joints of a scenario's hand by finger, from its validated parameters.

    Args:
        params: A node's validated parameters (``model.urdf_file`` resolved, see
            :func:`grasp_safety_filter.io.schemas.load_node_parameters`).

    Raises:
        HandModelError: An unreadable URDF, or names that are not in it.

    """
    robot = check_urdf_file(Path(params['model.urdf_file']))
    return group_joints_by_finger(
        robot,
        list(params['model.joint_names']),
        list(params['model.fingertip_frames']),
        list(params['model.contact_names']),
    )


def all_joints(joint_names: Sequence[str], label: str = 'joints') -> list[Finger]:
    """One group of every joint, command order: for a hand whose tree is not known."""
    return [Finger(label, tuple(range(len(joint_names))), tuple(joint_names), None)]
