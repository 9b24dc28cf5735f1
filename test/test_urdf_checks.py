"""A URDF the hand model cannot use is refused before Pinocchio, naming the file and element."""

from __future__ import annotations

from pathlib import Path

import pytest

from grasp_safety_filter.model.urdf import check_urdf_file, HandModelError

PAPER_URDF = Path(__file__).resolve().parent.parent / 'config' / 'hand.urdf'
FIRST_LIMIT = '<limit lower="0" upper="4.7123889803846897" effort="5.0" velocity="10"/>'

CASES = {
    'not XML': (lambda text: '\x00\x01binary', 'well-formed XML'),
    'cut short': (lambda text: text[: len(text) // 3], 'well-formed XML'),
    'no robot': (
        lambda text: '<model><link name="a"/></model>',
        '<robot> root element, got <model>',
    ),
    'no link': (lambda text: '<robot name="r"/>', 'at least one <link>'),
    'joint without limit': (
        lambda text: text.replace(FIRST_LIMIT, '', 1),
        "joint 'finger1_joint1': expected a <limit>",
    ),
    'effort not a number': (
        lambda text: text.replace('effort="5.0"', 'effort="strong"', 1),
        "joint 'finger1_joint1': expected a number in <limit effort>, got 'strong'",
    ),
    'mass not a number': (
        lambda text: text.replace('<mass value="0.1"/>', '<mass value="abc"/>', 1),
        "link 'finger1_proximal': expected a number in <mass value>, got 'abc'",
    ),
    'zero mass': (
        lambda text: text.replace('<mass value="0.1"/>', '<mass value="0"/>', 1),
        "link 'finger1_proximal': expected a mass > 0 kg, got 0",
    ),
    'inertia missing an attribute': (
        lambda text: text.replace(' izz="4.166667e-05"', '', 1),
        "link 'finger1_proximal': expected a izz=",
    ),
    'inertia indefinite': (
        lambda text: text.replace('ixy="0"', 'ixy="0.01"', 3),
        'expected a positive definite inertia',
    ),
    'axis not three numbers': (
        lambda text: text.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 1"/>', 1),
        "joint 'finger1_joint1': expected three numbers in <axis xyz>, got '0 1'",
    ),
}


@pytest.mark.parametrize('name', list(CASES))
def test_a_bad_urdf_is_refused_naming_the_element(tmp_path, name):
    edit, message = CASES[name]
    path = tmp_path / 'hand.urdf'
    path.write_text(edit(PAPER_URDF.read_text()))
    with pytest.raises(HandModelError) as caught:
        check_urdf_file(path)
    assert message in str(caught.value)
    assert str(path) in str(caught.value)


def test_the_papers_urdf_passes():
    assert check_urdf_file(PAPER_URDF).get('name') == 'three_finger_hand'


def test_a_missing_or_unreadable_urdf_names_the_parameter(tmp_path):
    with pytest.raises(HandModelError, match=r'model\.urdf_file: no such file'):
        check_urdf_file(tmp_path / 'none.urdf')
    with pytest.raises(HandModelError, match=r'model\.urdf_file: no such file'):
        check_urdf_file(tmp_path)
