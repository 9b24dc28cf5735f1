"""The hand's joints grouped by finger: from the URDF tree, any order, any count per finger."""

from __future__ import annotations

from pathlib import Path
from xml.etree import ElementTree

import pinocchio as pin
import pytest

from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters
from grasp_safety_filter.model.fingers import (
    all_joints,
    fingers_from_parameters,
    group_joints_by_finger,
)
from grasp_safety_filter.model.urdf import HandModelError

CONFIG = Path(__file__).resolve().parent.parent / 'config'
SCENARIOS = ('paper_scenario.yaml', 'four_finger_box.yaml')


@pytest.mark.parametrize('scenario', SCENARIOS)
def test_each_finger_is_the_joints_pinocchio_puts_on_its_fingertip_chain(scenario):
    params = load_node_parameters(CONFIG / scenario, HAND_SIM_NODE)
    fingers = fingers_from_parameters(params)
    model = pin.buildModelFromUrdf(params['model.urdf_file'])
    joint_names = params['model.joint_names']
    assert [f.label for f in fingers] == params['model.contact_names']
    for contact, (finger, frame) in enumerate(
        zip(fingers, params['model.fingertip_frames'], strict=True)
    ):
        parent = model.frames[model.getFrameId(frame)].parentJoint
        # supports: the joints from the root to this one, root first (0 is the universe).
        chain = [model.names[j] for j in model.supports[parent] if j > 0]
        assert finger.joint_names == tuple(chain)
        assert [joint_names[j] for j in finger.joints] == chain
        assert finger.contact == contact
    grouped = sorted(j for finger in fingers for j in finger.joints)
    assert grouped == list(range(len(joint_names)))


def test_joints_listed_out_of_finger_order_keep_their_fingers():
    params = load_node_parameters(CONFIG / 'four_finger_box.yaml', HAND_SIM_NODE)
    in_order = fingers_from_parameters(params)
    shuffled = list(reversed(params['model.joint_names']))
    shuffled[0], shuffled[5] = shuffled[5], shuffled[0]
    fingers = fingers_from_parameters({**params, 'model.joint_names': shuffled})
    assert [f.joint_names for f in fingers] == [f.joint_names for f in in_order]
    for finger in fingers:
        assert tuple(shuffled[j] for j in finger.joints) == finger.joint_names


def joint(name: str, parent: str, child: str, kind: str = 'revolute') -> str:
    limit = '<limit lower="-1" upper="1" effort="1" velocity="1"/>' if kind != 'fixed' else ''
    return (
        f'<joint name="{name}" type="{kind}"><parent link="{parent}"/>'
        f'<child link="{child}"/>{limit}</joint>'
    )


def robot(*joints: tuple[str, ...]) -> ElementTree.Element:
    """Make a URDF tree of the given joints (name, parent, child[, type]), links from them."""
    links = {'palm'} | {j[1] for j in joints} | {j[2] for j in joints}
    text = '<robot name="hand">' + ''.join(f'<link name="{link}"/>' for link in sorted(links))
    return ElementTree.fromstring(text + ''.join(joint(*j) for j in joints) + '</robot>')


#: A wrist, a two-joint finger with its tip on a fixed joint, a three-joint finger with a
#: free side joint, and a thumb with no contact behind a fixed base link.
HAND = robot(
    ('wrist', 'palm', 'hand_base'),
    ('a1', 'hand_base', 'a_link1'),
    ('a2', 'a_link1', 'a_link2'),
    ('a_tip_joint', 'a_link2', 'a_tip', 'fixed'),
    ('b1', 'hand_base', 'b_link1'),
    ('b2', 'b_link1', 'b_link2'),
    ('b3', 'b_link2', 'b_tip'),
    ('b_side', 'b_link1', 'b_side_link'),
    ('thumb_mount', 'palm', 'thumb_base', 'fixed'),
    ('t1', 'thumb_base', 't_link1'),
    ('t2', 't_link1', 't_link2'),
)

GROUPING_CASES = {
    'unequal fingers, a wrist, free branches': (
        ['t2', 'b3', 'a1', 'wrist', 'b_side', 'b1', 't1', 'a2', 'b2'],
        ['a_tip', 'b_tip'],
        [
            ('a', ['wrist', 'a1', 'a2']),
            ('b', ['wrist', 'b1', 'b2', 'b3']),
            ('thumb_base', ['t1', 't2']),
            ('b_side_link', ['b_side']),
        ],
    ),
    'a fingertip frame named by its fixed joint': (
        ['wrist', 'a1', 'a2', 'b1', 'b2', 'b3', 'b_side', 't1', 't2'],
        ['a_tip_joint', 'b_tip'],
        [
            ('a', ['wrist', 'a1', 'a2']),
            ('b', ['wrist', 'b1', 'b2', 'b3']),
            ('b_side_link', ['b_side']),
            ('thumb_base', ['t1', 't2']),
        ],
    ),
}


@pytest.mark.parametrize('case', GROUPING_CASES)
def test_fingers_follow_the_tree_whatever_the_order_and_counts(case):
    joint_names, frames, expected = GROUPING_CASES[case]
    fingers = group_joints_by_finger(HAND, joint_names, frames, ['a', 'b'])
    assert [(f.label, list(f.joint_names)) for f in fingers] == expected
    for finger in fingers:
        assert tuple(joint_names[j] for j in finger.joints) == finger.joint_names
    assert [f.contact for f in fingers] == [0, 1] + [None] * (len(expected) - 2)
    assert [f.free for f in fingers] == [False, False] + [True] * (len(expected) - 2)


ERROR_CASES = {
    'unknown joint': (['wrist', 'z9'], ['a_tip'], ['a'], "joint 'z9'"),
    'a fixed joint commanded': (['a_tip_joint'], ['a_tip'], ['a'], "joint 'a_tip_joint'"),
    'unknown frame': (['wrist'], ['nowhere'], ['a'], "frame 'nowhere'"),
    'names and frames differ in number': (['wrist'], ['a_tip'], ['a', 'b'], 'one name per'),
}


@pytest.mark.parametrize('case', ERROR_CASES)
def test_a_name_not_in_the_urdf_is_refused_by_name(case):
    joint_names, frames, contacts, expected = ERROR_CASES[case]
    with pytest.raises(HandModelError, match=expected):
        group_joints_by_finger(HAND, joint_names, frames, contacts)


def test_without_a_tree_every_joint_is_one_group_in_command_order():
    (group,) = all_joints(['j2', 'j0', 'j1'])
    assert group.joints == (0, 1, 2) and group.joint_names == ('j2', 'j0', 'j1')
    assert not group.free  # not known to touch nothing: its figure row is not called free
