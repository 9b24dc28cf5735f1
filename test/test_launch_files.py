"""The launch files, run against stand-ins for ``launch`` and ``launch_ros``.

``launch`` and ``launch_ros`` are not installed here: each launch file is imported with
minimal stand-in modules that record every action's constructor arguments, its
``OpaqueFunction`` is called with the launch arguments, and the nodes it starts are compared
with :mod:`grasp_safety_filter.io.launch_arguments` and with the ``ros2 run`` command lines
the graph tests start (``test/ros_graph.py``).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path
import shutil
import sys
import types
from typing import Any

import pytest
from ros_graph import node_command
import yaml

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.launch_arguments import (
    NodeLaunch,
    paper_demo,
    parameter_argument,
    parse_bool,
    real_hand,
    REAL_HAND_TOPICS,
    recorder_command,
    RECORDER_NODE,
    recorder_problem,
    safety_filter_alone,
    WAIT_FOR_RECORDER,
)
from grasp_safety_filter.io.parameters import load_parameter_file
from grasp_safety_filter.io.paths import config_path

REPO = Path(__file__).resolve().parent.parent
LAUNCH = REPO / 'launch'


class Action:
    """A stand-in launch action: keeps its constructor arguments."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        self.args = args
        self.kwargs = kwargs


class LaunchConfiguration:
    def __init__(self, name: str) -> None:
        self.name = name

    def perform(self, context: dict[str, str]) -> str:
        return context[self.name]


def stand_in_modules() -> dict[str, types.ModuleType]:
    names = ('DeclareLaunchArgument', 'ExecuteProcess', 'LogInfo', 'OpaqueFunction', 'Shutdown')
    actions = types.ModuleType('launch.actions')
    for name in names:
        setattr(actions, name, type(name, (Action,), {}))
    launch = types.ModuleType('launch')
    launch.LaunchDescription = type('LaunchDescription', (Action,), {})
    launch.actions = actions
    substitutions = types.ModuleType('launch.substitutions')
    substitutions.LaunchConfiguration = LaunchConfiguration
    launch_ros = types.ModuleType('launch_ros')
    ros_actions = types.ModuleType('launch_ros.actions')
    ros_actions.Node = type('Node', (Action,), {})
    launch_ros.actions = ros_actions
    return {
        'launch': launch,
        'launch.actions': actions,
        'launch.substitutions': substitutions,
        'launch_ros': launch_ros,
        'launch_ros.actions': ros_actions,
    }


def launch(monkeypatch, file_name: str, **arguments: str) -> list[Action]:
    """Import a launch file with the stand-ins; return the actions it launches."""
    for name, module in stand_in_modules().items():
        monkeypatch.setitem(sys.modules, name, module)
    spec = importlib.util.spec_from_file_location(file_name.replace('.', '_'), LAUNCH / file_name)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    (entities,) = description.args
    declared = {
        a.args[0]: a.kwargs['default_value']
        for a in entities
        if type(a).__name__ == 'DeclareLaunchArgument'
    }
    unknown = set(arguments) - set(declared)
    assert not unknown, f'{file_name} declares no {unknown}'
    for a in entities:
        if type(a).__name__ == 'DeclareLaunchArgument' and 'choices' in a.kwargs:
            value = arguments.get(a.args[0], a.kwargs['default_value'])
            assert value in a.kwargs['choices'], (a.args[0], value)
    (opaque,) = [a for a in entities if type(a).__name__ == 'OpaqueFunction']
    return opaque.kwargs['function']({**declared, **arguments})


def kind(actions: list[Action], name: str) -> list[Action]:
    return [a for a in actions if type(a).__name__ == name]


def parse_ros_arguments(arguments: list[str]) -> tuple[list[str], dict[str, Any], list]:
    """Return the parameter files, ``-p`` values and ``-r`` remaps of a ``--ros-args`` list."""
    assert arguments[0] == '--ros-args'
    files, values, remaps = [], {}, []
    pairs = iter(arguments[1:])
    for flag in pairs:
        value = next(pairs)
        if flag == '--params-file':
            files.append(value)
        elif flag == '-p':
            name, _, text = value.partition(':=')
            values[name] = yaml.safe_load(text)
        elif flag == '-r':
            remaps.append(tuple(value.split(':=')))
        else:
            raise AssertionError(f'unexpected {flag}')
    return files, values, remaps


def as_launch_ros_node(command: list[str]) -> dict[str, Any]:
    """Return the Node kwargs that start a process with this command line (as launch_ros)."""
    files, values, remaps = parse_ros_arguments(command[1:])
    return {
        'executable': Path(command[0]).name,
        'parameters': [*files, values],
        'remappings': remaps,
    }


def assert_same_as_the_tested_command_lines(nodes: list[Action], expected: list[NodeLaunch]):
    assert [n.kwargs['name'] for n in nodes] == [e.name for e in expected]
    for node, launch_node in zip(nodes, expected, strict=True):
        kwargs = dict(node.kwargs)
        on_exit = kwargs.pop('on_exit', None)
        assert (type(on_exit).__name__ == 'Shutdown') == launch_node.ends_launch
        assert kwargs == launch_node.node_kwargs()
        # The graph tests' command line, with -p overrides: same files, values and remaps.
        launch_node_command = [launch_node.executable, *launch_node.ros_arguments()]
        parsed = as_launch_ros_node(launch_node_command)
        assert parsed['executable'] == kwargs['executable']
        assert parsed['parameters'] == kwargs['parameters']
        assert parsed['remappings'] == kwargs['remappings']
        # A namespace makes launch_ros write the overrides under the node's name, where
        # they beat the file's node section (under /** they would not).
        assert kwargs['namespace'] == ''


# ----------------------------------------------------------------------------------------
# paper_demo.launch.py


def test_paper_demo_starts_the_three_nodes_on_sim_time_with_the_filter_on(monkeypatch):
    actions = launch(monkeypatch, 'paper_demo.launch.py')
    assert kind(actions, 'ExecuteProcess') == []
    nodes = kind(actions, 'Node')
    assert_same_as_the_tested_command_lines(nodes, paper_demo(str(config_path())))
    parameters = {n.kwargs['name']: n.kwargs['parameters'][-1] for n in nodes}
    assert parameters['safety_filter_node'] == {'use_sim_time': True, 'enabled': True}
    assert WAIT_FOR_RECORDER not in parameters['hand_sim_node']
    (sim,) = [n for n in nodes if n.kwargs['name'] == 'hand_sim_node']
    assert type(sim.kwargs['on_exit']).__name__ == 'Shutdown'


def test_paper_demo_nominal_run_turns_the_filter_off_in_its_own_section(monkeypatch):
    actions = launch(monkeypatch, 'paper_demo.launch.py', filter='false', duration='0.3')
    nodes = kind(actions, 'Node')
    expected = paper_demo(str(config_path()), filter_on=False, duration=0.3)
    assert_same_as_the_tested_command_lines(nodes, expected)
    parameters = {n.kwargs['name']: n.kwargs['parameters'][-1] for n in nodes}
    assert parameters['safety_filter_node']['enabled'] is False
    assert parameters['hand_sim_node']['duration'] == 0.3


def test_paper_demo_records_from_the_first_tick(monkeypatch, tmp_path):
    monkeypatch.setattr(shutil, 'which', lambda name: f'/opt/ros/jazzy/bin/{name}')
    bag = str(tmp_path / 'run')
    actions = launch(monkeypatch, 'paper_demo.launch.py', record='true', bag=bag)
    (recorder,) = kind(actions, 'ExecuteProcess')
    assert actions.index(recorder) == 0
    command = recorder.kwargs['cmd']
    assert command == recorder_command(bag)
    assert command[command.index('--node-name') + 1] == RECORDER_NODE
    assert command[command.index('--topics') + 1 :] == [s.name for s in topics.TOPICS]
    nodes = kind(actions, 'Node')
    assert_same_as_the_tested_command_lines(nodes, paper_demo(str(config_path()), record=True))
    (sim,) = [n for n in nodes if n.kwargs['name'] == 'hand_sim_node']
    assert sim.kwargs['parameters'][-1][WAIT_FOR_RECORDER] == RECORDER_NODE
    # No guessed warm-up: the simulator waits for the recorder itself.
    assert kind(actions, 'TimerAction') == []
    assert 'RECORDER_WARM_UP' not in (LAUNCH / 'paper_demo.launch.py').read_text()


def test_paper_demo_without_ros2_stops_instead_of_running_without_a_bag(monkeypatch):
    monkeypatch.setattr(shutil, 'which', lambda name: None)
    actions = launch(monkeypatch, 'paper_demo.launch.py', record='true')
    assert [type(a).__name__ for a in actions] == ['LogInfo', 'Shutdown']
    message = actions[0].kwargs['msg']
    assert 'ros2' in message and 'PATH' in message and 'record:=true' in message
    assert actions[1].kwargs['reason'] == message
    assert launch(monkeypatch, 'paper_demo.launch.py', record='false')  # no bag asked: runs


# ----------------------------------------------------------------------------------------
# safety_filter.launch.py


def test_safety_filter_launch_defaults_remap_nothing(monkeypatch):
    nodes = kind(launch(monkeypatch, 'safety_filter.launch.py'), 'Node')
    assert_same_as_the_tested_command_lines(nodes, [safety_filter_alone(str(config_path()))])
    assert nodes[0].kwargs['remappings'] == []
    assert nodes[0].kwargs['parameters'][-1] == {'use_sim_time': False, 'enabled': True}


def test_safety_filter_launch_remaps_to_the_users_topics(monkeypatch, tmp_path):
    config = str(tmp_path / 'my_hand.yaml')
    remaps = {
        'joint_states': '/my_hand/joint_states',
        'object_odom': '/tracker/object_odom',
        'effort_nominal': '/my_planner/effort',
        'effort_command': '/my_hand/effort_command',
    }
    actions = launch(
        monkeypatch,
        'safety_filter.launch.py',
        config=config,
        use_sim_time='true',
        enabled='false',
        **remaps,
    )
    nodes = kind(actions, 'Node')
    expected = safety_filter_alone(config, use_sim_time=True, enabled=False, remaps=remaps)
    assert_same_as_the_tested_command_lines(nodes, [expected])
    assert nodes[0].kwargs['remappings'] == [
        (topics.JOINT_STATES, '/my_hand/joint_states'),
        (topics.OBJECT_ODOM, '/tracker/object_odom'),
        (topics.EFFORT_NOMINAL, '/my_planner/effort'),
        (topics.EFFORT_COMMAND, '/my_hand/effort_command'),
    ]
    assert '-r' in expected.ros_arguments()


# ----------------------------------------------------------------------------------------
# The pure decisions


def test_recording_needs_a_ros2_executable():
    assert recorder_problem(False, which=lambda name: None) is None
    assert recorder_problem(True, which=lambda name: '/usr/bin/ros2') is None
    problem = recorder_problem(True, which=lambda name: None)
    assert problem is not None and 'no ros2 executable on PATH' in problem


def test_launch_arguments_are_strict_booleans():
    assert parse_bool('record', 'True') is True
    assert parse_bool('record', 'false') is False
    with pytest.raises(ValueError, match="'record'"):
        parse_bool('record', 'yes')
    with pytest.raises(ValueError, match='unknown arguments'):
        safety_filter_alone('x.yaml', remaps={'joint_state': '/x'})


@pytest.mark.parametrize(
    ('value', 'text'),
    [(True, 'true'), (False, 'false'), (0.3, '0.3'), ('rosbag2_recorder', 'rosbag2_recorder'),
     ('', "''"), ([1.0, 2.0], '[1.0, 2.0]')],
)  # fmt: skip
def test_parameter_arguments_are_yaml_as_rcl_reads_them(value, text):
    assert parameter_argument('name', value) == f'name:={text}'
    assert yaml.safe_load(parameter_argument('name', value).split(':=', 1)[1]) == value


def test_overrides_file_holds_the_node_section(tmp_path):
    (sim, _, safety_filter) = paper_demo('config.yaml', filter_on=False, record=True)
    path = safety_filter.write_overrides(tmp_path / 'filter.yaml')
    sections = load_parameter_file(path)
    assert sections == {'/safety_filter_node': {'use_sim_time': True, 'enabled': False}}
    expected = {'use_sim_time': True, WAIT_FOR_RECORDER: RECORDER_NODE}
    command = node_command(sim, tmp_path, overrides_as_file=True)
    files, values, _ = parse_ros_arguments(command[1:])
    assert files[0] == 'config.yaml' and len(files) == 2 and values == {}
    assert load_parameter_file(files[1]) == {'/hand_sim_node': expected}
    command = node_command(sim, tmp_path, overrides_as_file=False)
    files, values, _ = parse_ros_arguments(command[1:])
    assert files == ['config.yaml'] and values == expected
    assert sim.node_kwargs()['package'] == 'grasp_safety_filter'


@pytest.mark.parametrize(
    ('launch_file', 'sim_time'), [('paper_demo.launch.py', True), ('real_hand.launch.py', False)]
)
def test_viz_adds_the_grasp_markers_node_on_the_graphs_clock(monkeypatch, launch_file, sim_time):
    plain = {n.kwargs['name'] for n in kind(launch(monkeypatch, launch_file), 'Node')}
    nodes = kind(launch(monkeypatch, launch_file, viz='true'), 'Node')
    names = {n.kwargs['name'] for n in nodes}
    assert names - plain == {'grasp_markers_node'}
    (markers,) = [n for n in nodes if n.kwargs['name'] == 'grasp_markers_node']
    assert markers.kwargs['executable'] == 'grasp_markers_node'
    assert markers.kwargs['parameters'] == [str(config_path()), {'use_sim_time': sim_time}]


# ----------------------------------------------------------------------------------------
# real_hand.launch.py


def test_real_hand_starts_both_controllers_on_the_hands_streams_and_wall_clock(monkeypatch):
    actions = launch(monkeypatch, 'real_hand.launch.py')
    nodes = kind(actions, 'Node')
    assert_same_as_the_tested_command_lines(nodes, real_hand(str(config_path())))
    parameters = {n.kwargs['name']: n.kwargs['parameters'][-1] for n in nodes}
    assert sorted(parameters) == ['nominal_controller_node', 'safety_filter_node']
    for values in parameters.values():
        assert values['input.sync'] == 'latest'
        assert values['use_sim_time'] is False
    assert all(n.kwargs['remappings'] == [] for n in nodes)


def test_real_hand_wires_ros2_control_a_tracker_and_the_simulators_hardware_mode(monkeypatch):
    arguments = {
        'sim': 'true',
        'object_message': 'pose',
        'command_message': 'float64_multi_array',
        'joint_states': '/joint_states',
        'object_pose': '/tracker/object_pose',
        'effort_controller': '/hand_effort_controller/commands',
    }
    nodes = kind(launch(monkeypatch, 'real_hand.launch.py', **arguments), 'Node')
    expected = real_hand(
        str(config_path()),
        simulate=True,
        object_message='pose',
        command_message='float64_multi_array',
        remaps={k: v for k, v in arguments.items() if k in REAL_HAND_TOPICS},
    )
    assert_same_as_the_tested_command_lines(nodes, expected)
    parameters = {n.kwargs['name']: n.kwargs['parameters'][-1] for n in nodes}
    assert parameters['hand_sim_node']['lockstep'] is False
    assert parameters['hand_sim_node']['tracker.message'] == 'pose'
    assert parameters['safety_filter_node']['command.message'] == 'float64_multi_array'
    assert parameters['nominal_controller_node']['input.object_message'] == 'pose'
    remaps = {n.kwargs['name']: dict(n.kwargs['remappings']) for n in nodes}
    for node_remaps in remaps.values():
        assert node_remaps == {
            topics.JOINT_STATES: '/joint_states',
            topics.OBJECT_POSE: '/tracker/object_pose',
            topics.EFFORT_CONTROLLER_COMMANDS: '/hand_effort_controller/commands',
        }


def test_real_hand_with_a_controller_of_ones_own_starts_the_filter_alone(monkeypatch):
    nodes = kind(launch(monkeypatch, 'real_hand.launch.py', nominal='false'), 'Node')
    assert [n.kwargs['name'] for n in nodes] == ['safety_filter_node']
