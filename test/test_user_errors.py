"""Every user mistake in a scenario ends an entry point with one line and exit code 2.

Each case is a bad input (a parameter file, a URDF, a ``--set`` value) given to
``grasp-demo`` and ``grasp-model-report`` in-process, a few to the console scripts and the
node processes: the answer is exit code 2 and exactly one line on stderr that names the
problem (the file, parameter, joint, link or contact), never a traceback.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
import os
from pathlib import Path
import re
import subprocess
import sys
from typing import Any

import pytest
import yaml

from grasp_safety_filter.cli import demo_main
from grasp_safety_filter.model_report import main as model_report_main

REPO = Path(__file__).resolve().parent.parent
CONFIG_DIR = REPO / 'config'

#: The height at which the paper's fingertips touch the cube's face centres (the scenario's).
PAPER_HEIGHT = 0.21950666066214627

#: Longest a console script or node process may take to refuse its input, s.
PROCESS_TIMEOUT = 60.0


def model(document: dict[str, Any]) -> dict[str, Any]:
    return document['/**']['ros__parameters']['model']


def simulator(document: dict[str, Any]) -> dict[str, Any]:
    return document['hand_sim_node']['ros__parameters']


@dataclass(frozen=True)
class Case:
    """A bad input: edits of the paper's scenario and URDF, and what the line must name.

    Attributes:
        name: The case's id.
        expected: Words the one line on stderr must hold (a file, parameter, joint...).
        edit: Changes the scenario document in place.
        urdf: Changes the URDF text.
        scenario_bytes: Replaces the scenario file's contents.
        arguments: Extra ``grasp-demo`` arguments (``--set NAME=VALUE``).
    """

    name: str
    expected: tuple[str, ...]
    edit: Callable[[dict[str, Any]], None] | None = None
    urdf: Callable[[str], str] | None = None
    scenario_bytes: bytes | None = None
    arguments: tuple[str, ...] = ()

    def write(self, directory: Path) -> Path:
        """Write the scenario and its URDF into ``directory``; return the scenario."""
        document = yaml.safe_load((CONFIG_DIR / 'paper_scenario.yaml').read_text())
        if self.edit is not None:
            self.edit(document)
        urdf = (CONFIG_DIR / 'hand.urdf').read_text()
        if self.urdf is not None:
            urdf = self.urdf(urdf)
        (directory / 'hand.urdf').write_text(urdf)
        path = directory / 'scenario.yaml'
        if self.scenario_bytes is not None:
            path.write_bytes(self.scenario_bytes)
        else:
            path.write_text(yaml.safe_dump(document, sort_keys=False))
        return path


def setter(section: Callable[[dict[str, Any]], dict[str, Any]], key: str, value: Any):
    def edit(document: dict[str, Any]) -> None:
        section(document)[key] = value

    return edit


def object_at(x: float, y: float, z: float):
    def edit(document: dict[str, Any]) -> None:
        simulator(document)['initial']['object_position'] = [x, y, z]

    return edit


def first_joint_position(value: float, index: int = 1):
    def edit(document: dict[str, Any]) -> None:
        simulator(document)['initial']['joint_positions'][index] = value

    return edit


def drop_section(name: str):
    def edit(document: dict[str, Any]) -> None:
        del document[name]

    return edit


def two_contacts(document: dict[str, Any]) -> None:
    for key in ('contact_names', 'fingertip_frames', 'contact_faces'):
        model(document)[key] = model(document)[key][:2]


def drop_model_key(*keys: str):
    def edit(document: dict[str, Any]) -> None:
        section = model(document)
        for key in keys[:-1]:
            section = section[key]
        del section[keys[-1]]

    return edit


def box_at(edge_lengths: list[float], height: float):
    def edit(document: dict[str, Any]) -> None:
        model(document)['object'] = {'shape': 'box', 'mass': 0.11, 'edge_lengths': edge_lengths}
        simulator(document)['initial']['object_position'] = [0.0, 0.0, height]

    return edit


def without_inertials(text: str) -> str:
    stripped = re.sub(r'<inertial>.*?</inertial>', '', text, flags=re.DOTALL)
    assert '<inertial>' in text and '<inertial>' not in stripped
    return stripped


def replace_once(old: str, new: str):
    def edit(text: str) -> str:
        assert old in text, old
        return text.replace(old, new, 1)

    return edit


FIRST_LIMIT = '<limit lower="0" upper="4.7123889803846897" effort="5.0"'

CASES = [
    Case(
        'missing URDF',
        ('model.urdf_file', 'no_hand.urdf'),
        setter(model, 'urdf_file', 'no_hand.urdf'),
    ),
    Case(
        'malformed URDF',
        ('model.urdf_file', 'hand.urdf', 'XML', 'line'),
        urdf=lambda text: text[: len(text) // 2],
    ),
    Case(
        'URDF without a robot',
        ('model.urdf_file', 'hand.urdf', '<robot>'),
        urdf=lambda text: (
            '<?xml version="1.0"?>\n<model name="hand"><link name="palm"/></model>\n'
        ),
    ),
    Case(
        'q_min > q_max',
        ('finger1_joint1', 'lower', 'upper'),
        urdf=replace_once(
            FIRST_LIMIT, '<limit lower="4.8" upper="4.7123889803846897" effort="5.0"'
        ),
    ),
    Case(
        'zero effort limit',
        ('finger1_joint1', 'effort'),
        urdf=replace_once(FIRST_LIMIT, '<limit lower="0" upper="4.7123889803846897" effort="0"'),
    ),
    Case(
        'unknown joint',
        ('model.joint_names', 'finger2_joint_two'),
        lambda d: model(d)['joint_names'].__setitem__(4, 'finger2_joint_two'),
    ),
    Case(
        'unknown frame',
        ('model.fingertip_frames', 'finger1_tipp'),
        setter(model, 'fingertip_frames', ['finger1_tipp', 'finger2_tip', 'finger3_tip']),
    ),
    Case(
        'binary scenario file',
        ('scenario.yaml',),
        scenario_bytes=b'\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe\x00\x01garbage',
    ),
    Case('object far away', ('finger1', 'face', ' m'), object_at(0.0, 0.0, 5.0)),
    Case(
        'object slightly penetrating',
        ('finger3', 'penetrat', '0.003'),
        object_at(0.0, 0.003, PAPER_HEIGHT),
    ),
    Case('fingertips apart', ('finger1', 'separated', '0.02'), object_at(0.02, 0.0, PAPER_HEIGHT)),
    Case(
        'contact off the face edge',
        ('finger1', 'edge', '0.009'),
        object_at(0.0, 0.0, PAPER_HEIGHT + 0.14),
    ),
    Case(
        'initial joint outside its limits', ('finger1_joint2', 'limits'), first_joint_position(1.2)
    ),
    Case(
        'URDF origin not numbers',
        ('finger1_joint1', 'origin', 'a b c'),
        urdf=replace_once('<origin xyz="-0.694691628007 0 0"', '<origin xyz="a b c"'),
    ),
    Case(
        'negative link mass',
        ('finger1_proximal', 'mass'),
        urdf=replace_once('<mass value="0.1"/>', '<mass value="-0.1"/>'),
    ),
    Case(
        'inertia not positive definite',
        ('finger1_proximal', 'inertia'),
        urdf=replace_once('ixx="7.708333e-04"', 'ixx="-7.708333e-04"'),
    ),
    Case('links without inertia', ('hand.urdf', 'finger', 'inertia'), urdf=without_inertials),
    Case('two opposite contacts', ('rank 5', 'expected 6'), two_contacts),
    Case(
        'pyramid faces huge',
        ('no_slip.pyramid_faces', '100000'),
        arguments=('--set', 'no_slip.pyramid_faces=100000'),
    ),
    Case(
        'missing simulator section',
        ('hand_sim_node', 'initial.joint_positions'),
        drop_section('hand_sim_node'),
    ),
    Case(
        'tip link without a collision sphere',
        ('model.fingertip_frames', "'finger1_tip'", '<collision><sphere>'),
        urdf=replace_once(
            '<collision>\n      <geometry><sphere radius="0.06"/></geometry>\n    </collision>\n',
            '',
        ),
    ),
    Case(
        'fingertip frame on a link with no sphere on its body',
        ('model.fingertip_frames', "'finger2_proximal'", '<collision><sphere>'),
        setter(model, 'fingertip_frames', ['finger1_tip', 'finger2_proximal', 'finger3_tip']),
    ),
    Case(
        'radius not the URDF sphere',
        ('model.fingertip_radius', "'finger1'", "'finger1_tip'", '0.06 m', '0.012 m'),
        setter(model, 'fingertip_radius', 0.012),
    ),
    Case(
        'missing object mass',
        ('model.object.mass', 'no default'),
        drop_model_key('object', 'mass'),
    ),
    Case(
        'missing friction coefficient',
        ('model.friction_coefficient', 'no default'),
        drop_model_key('friction_coefficient'),
    ),
    Case(
        'missing fingertip frames',
        ('model.fingertip_frames', 'no default'),
        drop_model_key('fingertip_frames'),
    ),
    Case(
        'box without edge lengths',
        ('model.object.edge_lengths', 'no default'),
        setter(model, 'object', {'shape': 'box', 'mass': 0.11}),
    ),
    Case(
        'contact off a finite box face',
        ("contact 'finger1'", 'face -x', 'edge', '0.01 m'),
        box_at([0.2604, 0.2604, 0.1], PAPER_HEIGHT + 0.06),
    ),
    Case(
        'declared face not the nearest',
        ("contact 'finger2'", "declares face '+y'", "nearest face '+x'"),
        setter(model, 'contact_faces', ['-x', '+y', '+y']),
    ),
    Case(
        'sphere object apart from the fingertips',
        ("contact 'finger1'", 'separated', '0.0302', 'sphere'),
        setter(model, 'object', {'shape': 'sphere', 'mass': 0.11, 'size': 0.2}),
    ),
]

#: Cases the model report takes (it has no --set).
REPORT_CASES = [case for case in CASES if not case.arguments]


def assert_one_line(code: int, stderr: str, expected: tuple[str, ...]) -> None:
    lines = stderr.splitlines()
    assert code == 2, stderr
    assert 'Traceback' not in stderr
    assert len(lines) == 1, stderr
    for word in expected:
        assert word in lines[0], f'{word!r} not in {lines[0]!r}'


def call(main: Callable[[list[str]], int], arguments: list[str]) -> int:
    try:
        return main(arguments)
    except SystemExit as exit_:  # argparse
        return int(exit_.code)


@pytest.mark.parametrize('case', CASES, ids=[case.name for case in CASES])
def test_grasp_demo_refuses_with_one_line(tmp_path, capsys, case):
    path = case.write(tmp_path)
    arguments = ['--config', str(path), '--mode', 'nominal', '--duration', '0.01']
    code = call(demo_main, [*arguments, '--out', str(tmp_path / 'out'), *case.arguments])
    assert_one_line(code, capsys.readouterr().err, case.expected)


@pytest.mark.parametrize('case', REPORT_CASES, ids=[case.name for case in REPORT_CASES])
def test_grasp_model_report_refuses_with_one_line(tmp_path, capsys, case):
    path = case.write(tmp_path)
    code = call(model_report_main, ['--config', str(path)])
    assert_one_line(code, capsys.readouterr().err, case.expected)


def test_the_paper_scenario_passes_the_start_up_checks(capsys):
    assert model_report_main(['--config', str(CONFIG_DIR / 'paper_scenario.yaml')]) == 0
    assert capsys.readouterr().err == ''


# --------------------------------------------------------------------------------------------
# Processes: the console scripts and the nodes


def by_name(name: str) -> Case:
    (case,) = [case for case in CASES if case.name == name]
    return case


def console_script(name: str) -> str:
    path = Path(sys.executable).with_name(name)
    assert path.is_file(), f'{name} is not installed next to {sys.executable}'
    return str(path)


def run_process(arguments: list[str], cwd: Path) -> tuple[int, str]:
    environment = dict(os.environ, ROS_AUTOMATIC_DISCOVERY_RANGE='LOCALHOST')
    done = subprocess.run(
        arguments,
        cwd=cwd,
        env=environment,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        timeout=PROCESS_TIMEOUT,
    )
    return done.returncode, done.stderr


@pytest.mark.parametrize(
    ('script', 'case_name'),
    [
        ('grasp-demo', 'binary scenario file'),
        ('grasp-demo', 'object far away'),
        ('grasp-model-report', 'malformed URDF'),
    ],
)
def test_console_scripts_refuse_with_one_line(tmp_path, script, case_name):
    case = by_name(case_name)
    path = case.write(tmp_path)
    arguments = ['--config', str(path)]
    if script == 'grasp-demo':
        arguments += ['--mode', 'nominal', '--duration', '0.01', '--out', str(tmp_path / 'o')]
    code, stderr = run_process([console_script(script), *arguments], tmp_path)
    assert_one_line(code, stderr, case.expected)


@pytest.mark.parametrize(
    ('node', 'case_name'),
    [
        ('hand_sim_node', 'object far away'),
        ('safety_filter_node', 'negative link mass'),
        ('nominal_controller_node', 'binary scenario file'),
    ],
)
def test_nodes_refuse_with_one_line(tmp_path, node, case_name):
    case = by_name(case_name)
    path = case.write(tmp_path)
    code, stderr = run_process(
        [console_script(node), '--ros-args', '--params-file', str(path)], tmp_path
    )
    assert_one_line(code, stderr, case.expected)
    assert stderr.startswith(f'{node}: ')
