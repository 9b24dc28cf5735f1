"""The rclpy nodes' start-up and shutdown, over real rclpy: parameters, refusals, signals.

Parameters are checked on nodes built in-process (each test on its own rclpy context);
refusals and signals on the console scripts run as OS processes, as ``ros2 run`` and
``ros2 launch`` run them.
"""

from __future__ import annotations

import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import time

import pytest
import rclpy
from rclpy.node import Node
from rclpy.parameter import Parameter

from grasp_safety_filter.io.parameters import load_parameter_file, ParameterError
from grasp_safety_filter.io.ros_arguments import (
    parse_ros_arguments,
    remapped_fully_qualified_name,
)
from grasp_safety_filter.nodes.nominal_controller_node import NominalControllerNode
from grasp_safety_filter.nodes.safety_filter_node import SafetyFilterNode
from hand_sim_node.node import HandSimNode

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
NODE_NAMES = ('hand_sim_node', 'nominal_controller_node', 'safety_filter_node')

#: A line rcutils logs to stderr: "[INFO] [1700000000.000000000] [node]: message".
LOG_LINE = re.compile(r'^\[(DEBUG|INFO|WARN|ERROR|FATAL)\] \[\d+\.\d+\] \[')

#: Longest a node process may take to start (imports, DDS, model) or to exit, s.
PROCESS_TIMEOUT = 30.0


@pytest.fixture
def context():
    context = rclpy.Context()
    rclpy.init(context=context)
    nodes: list[Node] = []
    yield context, nodes
    for node in nodes:
        node.destroy_node()
    rclpy.try_shutdown(context=context)


def build(context, node_class, *ros_arguments, **kwargs):
    """Build a node in-process with ``--ros-args <ros_arguments>`` as its own arguments."""
    ros_context, nodes = context
    node = node_class(
        context=ros_context, cli_args=['--ros-args', *map(str, ros_arguments)], **kwargs
    )
    nodes.append(node)
    return node


def write(path: Path, text: str) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(textwrap.dedent(text), encoding='utf-8')
    return path


# --------------------------------------------------------------------------------------------
# Parameter precedence (in-process)


def test_the_config_file_enables_the_filter_in_its_node_section():
    assert load_parameter_file(CONFIG)['/safety_filter_node']['enabled'] is True


def test_command_line_parameter_beats_the_files_node_section(context):
    node = build(context, SafetyFilterNode, '--params-file', CONFIG, '-p', 'enabled:=false')
    assert node.get_parameter('enabled').value is False
    assert node.parameters['enabled'] is False
    assert not node.endpoint.enabled
    assert node.given_parameters['enabled'].source == "ROS argument '-p enabled:=false'"


def test_command_line_duration_beats_the_simulators_section(context):
    node = build(context, HandSimNode, '--params-file', CONFIG, '-p', 'duration:=3.0')
    assert node.get_parameter('duration').value == 3.0
    assert node.endpoint.config.duration == 3.0
    # The rest of the section still applies.
    assert node.get_parameter('time_step').value == 0.001


def test_process_arguments_count_and_a_nodes_own_follow_them(context):
    node = build(
        context,
        SafetyFilterNode,
        '-p',
        'input.max_age:=0.25',
        global_arguments=[
            'prog',
            '--ros-args',
            '--params-file',
            str(CONFIG),
            '-p',
            'enabled:=false',
        ],
    )
    assert node.get_parameter('enabled').value is False
    assert node.get_parameter('input.max_age').value == 0.25


@pytest.mark.parametrize('section', ['safety_filter_node', '/**'])
def test_a_second_parameter_file_beats_the_first_ones_node_section(context, tmp_path, section):
    # '/**' is how launch_ros writes a Node's dict parameters, in a file after the config.
    second = write(
        tmp_path / 'second.yaml', f'{section}:\n  ros__parameters:\n    enabled: false\n'
    )
    node = build(context, SafetyFilterNode, '--params-file', CONFIG, '--params-file', second)
    assert node.get_parameter('enabled').value is False
    assert not node.endpoint.enabled
    first_again = build(
        context, SafetyFilterNode, '--params-file', second, '--params-file', CONFIG
    )
    assert first_again.get_parameter('enabled').value is True


def test_explicit_overrides_beat_every_argument_and_live_updates_still_apply(context):
    node = build(
        context,
        SafetyFilterNode,
        '--params-file',
        CONFIG,
        '-p',
        'enabled:=false',
        parameter_overrides=[Parameter('enabled', value=True)],
    )
    assert node.get_parameter('enabled').value is True
    assert node.endpoint.enabled
    assert node.set_parameters([Parameter('enabled', value=False)])[0].successful
    assert not node.endpoint.enabled


def test_an_invalid_explicit_override_is_refused(context):
    with pytest.raises(
        ParameterError, match=r"parameter_overrides: parameter 'duration': expected"
    ):
        build(
            context,
            HandSimNode,
            '--params-file',
            CONFIG,
            parameter_overrides=[Parameter('duration', value=-1.0)],
        )


# --------------------------------------------------------------------------------------------
# Relative paths


@pytest.fixture
def robot_directory(tmp_path):
    """Make a directory with a copy of the hand's URDF under another name and a file naming it."""
    directory = tmp_path / 'robot'
    directory.mkdir()
    shutil.copy(REPO / 'config' / 'hand.urdf', directory / 'my_hand.urdf')
    write(
        directory / 'my_hand.yaml',
        '/**:\n  ros__parameters:\n    model:\n      urdf_file: my_hand.urdf\n',
    )
    return directory


def test_relative_urdf_resolves_against_the_file_that_sets_it(context, robot_directory):
    node = build(
        context,
        HandSimNode,
        '--params-file',
        CONFIG,
        '--params-file',
        robot_directory / 'my_hand.yaml',
    )
    assert node.get_parameter('model.urdf_file').value == 'my_hand.urdf'
    assert node.parameters['model.urdf_file'] == str(robot_directory / 'my_hand.urdf')


def test_relative_urdf_from_the_command_line_resolves_against_the_current_directory(
    context, robot_directory, monkeypatch
):
    monkeypatch.chdir(robot_directory)
    node = build(
        context, HandSimNode, '--params-file', CONFIG, '-p', 'model.urdf_file:=my_hand.urdf'
    )
    assert node.parameters['model.urdf_file'] == str(robot_directory / 'my_hand.urdf')


def test_a_node_without_the_hands_parameters_is_refused_naming_them(
    context, tmp_path, monkeypatch
):
    # The schema's model defaults are the paper's hand: never used for another hand.
    monkeypatch.chdir(tmp_path)
    with pytest.raises(ParameterError, match=r"'model\.urdf_file'.*no default") as error:
        build(context, NominalControllerNode)
    for name in ('model.fingertip_frames', 'model.object.mass', 'model.friction_coefficient'):
        assert name in str(error.value)


# --------------------------------------------------------------------------------------------
# The node's name after remapping, as rcl computes it


@pytest.mark.parametrize(
    ('process', 'own', 'namespace'),
    [
        ([], [], None),
        ([], [], 'arm'),
        ([], ['--ros-args', '-r', '__node:=a', '-r', '__node:=b'], None),
        (['--ros-args', '-r', '__node:=g'], ['--ros-args', '-r', '__node:=own'], None),
        (['--ros-args', '-r', '__node:=g', '-r', '__ns:=/g'], [], None),
        ([], ['--ros-args', '-r', 'demo_node:__node:=x'], None),
        ([], ['--ros-args', '-r', 'other_node:__node:=x'], None),
        ([], ['--ros-args', '-r', '__ns:=/left'], '/kw'),
        ([], ['--ros-args', '-r', '__ns:=/a/b', '-r', '__name:=c'], None),
        ([], ['__node:=old'], None),
    ],
)
def test_remapped_name_is_the_name_rcl_gives(process, own, namespace):
    ros_context = rclpy.Context()
    rclpy.init(context=ros_context, args=['prog', *process])
    try:
        node = Node('demo_node', context=ros_context, cli_args=own, namespace=namespace)
        actual = node.get_fully_qualified_name()
        node.destroy_node()
    finally:
        rclpy.try_shutdown(context=ros_context)
    argument_sets = [parse_ros_arguments(process), parse_ros_arguments(own)]
    assert remapped_fully_qualified_name('demo_node', namespace, argument_sets) == actual


def test_a_renamed_node_reads_the_section_of_its_new_name(context, tmp_path):
    left = write(tmp_path / 'left.yaml', 'left_filter:\n  ros__parameters:\n    enabled: false\n')
    node = build(
        context,
        SafetyFilterNode,
        '--params-file',
        CONFIG,
        '--params-file',
        left,
        '-r',
        '__node:=left_filter',
    )
    assert node.get_fully_qualified_name() == '/left_filter'
    assert node.get_parameter('enabled').value is False


# --------------------------------------------------------------------------------------------
# Node processes


def console_script(name: str) -> str:
    path = Path(sys.executable).with_name(name)
    assert path.is_file(), f'{name} is not installed next to {sys.executable}'
    return str(path)


class NodeProcess:
    """A console script run as an OS process, its stderr read line by line as it comes."""

    def __init__(self, name: str, *ros_arguments: str | Path, cwd: Path = REPO) -> None:
        self.name = name
        self.lines: list[str] = []
        self._changed = threading.Condition()
        self.process = subprocess.Popen(
            [console_script(name), '--ros-args', *map(str, ros_arguments)],
            cwd=cwd,
            env=dict(os.environ),
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=subprocess.PIPE,
            text=True,
        )
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.process.stderr:
            with self._changed:
                self.lines.append(line.rstrip('\n'))
                self._changed.notify_all()

    def wait_for_line(self, pattern: str, timeout: float = PROCESS_TIMEOUT) -> None:
        """Wait until a stderr line matches ``pattern`` (a regex)."""
        regex = re.compile(pattern)
        with self._changed:
            found = self._changed.wait_for(
                lambda: (
                    any(regex.search(line) for line in self.lines)
                    or self.process.poll() is not None
                ),
                timeout=timeout,
            )
        assert found and any(regex.search(line) for line in self.lines), self.report()

    def wait_until_spinning(self) -> None:
        """Wait for the node's first INFO line, which it logs when it is built."""
        self.wait_for_line(rf'^\[INFO\] \[[\d.]+\] \[{self.name}\]: ')

    def finish(self, timeout: float = PROCESS_TIMEOUT) -> int:
        """Wait for the exit; kill the process if it does not come. Returns the exit code."""
        try:
            return self.process.wait(timeout=timeout)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
            message = f'{self.name} did not exit within {timeout} s\n{self.report()}'
            raise AssertionError(message) from None
        finally:
            self._reader.join(timeout=5.0)

    def kill(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait()

    def report(self) -> str:
        return f'{self.name} (exit {self.process.poll()}), stderr:\n' + '\n'.join(self.lines)

    def other_than_log_lines(self) -> list[str]:
        return [line for line in self.lines if line.strip() and not LOG_LINE.match(line)]


# --------------------------------------------------------------------------------------------
# Refusals (processes)


@pytest.mark.parametrize(
    ('node_name', 'text', 'arguments', 'message'),
    [
        (
            'safety_filter_node',
            'safety_filter_node:\n  ros__parameters:\n    barier: {alpha1: {gain: 2.0}}\n',
            (),
            "safety_filter_node: parameter file 'bad.yaml' (node 'safety_filter_node'): unknown "
            "parameter 'barier.alpha1.gain': node 'safety_filter_node' does not declare it (did "
            "you mean 'barrier.alpha1.gain'?)",
        ),
        (
            'safety_filter_node',
            'safety_filter_node:\n  ros__parameters:\n    input:\n      max_agee: 0.1\n',
            (),
            "safety_filter_node: parameter file 'bad.yaml' (node 'safety_filter_node'): unknown "
            "parameter 'input.max_agee': node 'safety_filter_node' does not declare it (did you "
            "mean 'input.max_age'?)",
        ),
        (
            'safety_filter_node',
            'safety_filtr_node:\n  ros__parameters:\n    enabled: false\n',
            (),
            "safety_filter_node: parameter file 'bad.yaml': section '/safety_filtr_node' "
            "addresses no node of this package (did you mean 'safety_filter_node'?)",
        ),
        (
            'hand_sim_node',
            'safety_filtr_node:\n  ros__parameters:\n    enabled: false\n',
            (),
            "hand_sim_node: parameter file 'bad.yaml': section '/safety_filtr_node' addresses "
            "no node of this package (did you mean 'safety_filter_node'?)",
        ),
        (
            'hand_sim_node',
            'robot_state_publisher:\n  ros__parameters:\n    publish_frequency: 20.0\n',
            ('-p', 'duration:=3'),
            "hand_sim_node: ROS argument '-p duration:=3' (node 'hand_sim_node'): parameter "
            "'duration': expected a double (ROS reads 3 as an integer; write 3.0), got 3",
        ),
        (
            'nominal_controller_node',
            '/**:\n  ros__parameters:\n    enabled: false\n',
            (),
            "nominal_controller_node: parameter file 'bad.yaml' (node 'nominal_controller_node'): "
            "unknown parameter 'enabled': node 'nominal_controller_node' does not declare it (it "
            'is a parameter of safety_filter_node)',
        ),
    ],
)
def test_bad_parameters_end_the_process_with_one_line_and_exit_code_2(
    tmp_path, node_name, text, arguments, message
):
    write(tmp_path / 'bad.yaml', text)
    shutil.copy(CONFIG, tmp_path / 'config.yaml')
    shutil.copy(REPO / 'config' / 'hand.urdf', tmp_path / 'hand.urdf')
    node = NodeProcess(
        node_name,
        '--params-file',
        'config.yaml',
        '--params-file',
        'bad.yaml',
        *arguments,
        cwd=tmp_path,
    )
    try:
        assert node.finish() == 2, node.report()
    finally:
        node.kill()
    assert node.other_than_log_lines() == [message], node.report()
    assert not any('Traceback' in line for line in node.lines)


# --------------------------------------------------------------------------------------------
# Signals (processes): all three nodes at once, the loop running between them


def start_graph(*extra_arguments: str) -> list[NodeProcess]:
    return [
        NodeProcess(name, '--params-file', CONFIG, '-p', 'use_sim_time:=true', *extra_arguments)
        for name in NODE_NAMES
    ]


def assert_quiet_exits(nodes: list[NodeProcess]) -> None:
    for node in nodes:
        assert node.finish() == 0, node.report()
        assert node.other_than_log_lines() == [], node.report()


#: (first signal, wait before the first, second signal or None, wait between them) [s].
SIGNAL_TRIALS = [
    (signal.SIGINT, 0.0, signal.SIGINT, 0.0),
    (signal.SIGINT, 0.05, signal.SIGINT, 0.005),
    (signal.SIGINT, 0.15, signal.SIGINT, 0.02),
    (signal.SIGINT, 0.3, signal.SIGINT, 0.05),
    (signal.SIGTERM, 0.1, None, 0.0),
    (signal.SIGTERM, 0.0, signal.SIGINT, 0.03),
]


@pytest.mark.parametrize(
    ('first', 'wait', 'second', 'gap'),
    SIGNAL_TRIALS,
    ids=[f'{a.name}-{b.name if b else "once"}-{w}-{g}' for a, w, b, g in SIGNAL_TRIALS],
)
def test_nodes_exit_quietly_on_one_or_two_signals_while_spinning(first, wait, second, gap):
    nodes = start_graph()
    try:
        for node in nodes:
            node.wait_until_spinning()
        time.sleep(wait)
        for node in nodes:
            node.process.send_signal(first)
        if second is not None:
            time.sleep(gap)
            for node in nodes:
                node.process.send_signal(second)
        assert_quiet_exits(nodes)
    finally:
        for node in nodes:
            node.kill()


def test_nodes_exit_quietly_on_two_sigints_while_they_are_built():
    # rcl logs this at debug level once rclpy is initialised, before the model is built.
    nodes = start_graph('--log-level', 'debug')
    try:
        for node in nodes:
            node.wait_for_line(rf"Initializing node '{node.name}'")
            node.process.send_signal(signal.SIGINT)
            time.sleep(0.01)
            node.process.send_signal(signal.SIGINT)
        assert_quiet_exits(nodes)
    finally:
        for node in nodes:
            node.kill()


def test_the_filter_node_logs_its_start_up_advice_once_at_its_first_tick():
    """The paper's cubic class-K functions freeze its joint limits: a warning, with gains."""
    nodes = start_graph()
    try:
        node = nodes[NODE_NAMES.index('safety_filter_node')]
        node.wait_for_line(r'^\[WARN\] .*start-up advice \(frozen\): joint_limits: .* frozen')
        node.wait_for_line(r'start-up advice \(frozen\): QP at rest: feasible')
        node.wait_for_line(r'start-up advice \(frozen\): to let .* barrier\.alpha1\.kind=linear')
        time.sleep(0.5)  # more ticks: no second advice
        advice = [line for line in node.lines if 'start-up advice' in line]
        # joint limits, fingertip workspace, QP, held still, gains
        assert len(advice) == 5, node.report()
        for process in nodes:
            process.process.send_signal(signal.SIGINT)
        assert_quiet_exits(nodes)
    finally:
        for node in nodes:
            node.kill()


def wait_until_importing(
    node: NodeProcess, library: str, timeout: float = PROCESS_TIMEOUT
) -> None:
    """Wait until the process has mapped a shared library that only the node's imports load."""
    maps = Path(f'/proc/{node.process.pid}/maps')
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            if library in maps.read_text(encoding='utf-8', errors='replace'):
                return
        except OSError:
            break  # the process is gone: finish() reports it
        time.sleep(0.001)
    raise AssertionError(f'{library} never loaded\n{node.report()}')


@pytest.mark.parametrize('library', ['_multiarray_umath', '_rclpy_pybind11', 'libpinocchio'])
def test_nodes_exit_quietly_on_a_signal_while_they_import(library):
    """Before spin_node runs, the console script's entry point already makes SIGINT quiet.

    The entry point imports the node's module only after taking the signals over; numpy,
    rclpy and Pinocchio are loaded by that import, so a signal sent once one of them is
    mapped arrives in the middle of it.
    """
    nodes = start_graph()
    try:
        for node in nodes:
            wait_until_importing(node, library)
            node.process.send_signal(signal.SIGINT)
        assert_quiet_exits(nodes)
    finally:
        for node in nodes:
            node.kill()


def test_a_signal_swallowed_in_a_weakref_callback_still_ends_the_node_quietly(tmp_path):
    """The import system runs weakref callbacks, where Python can only report an exception.

    A node module whose import is interrupted inside one must neither print "Exception
    ignored" nor go on to run the node: the signal is recorded, and honoured once the import
    is done.
    """
    (tmp_path / 'interrupted_in_callback.py').write_text(
        textwrap.dedent(
            """
            import os, signal, time, weakref

            class Target:
                pass

            def callback(reference):
                os.kill(os.getpid(), signal.SIGINT)
                time.sleep(0.5)  # the handler runs here, inside the callback

            target = Target()
            reference = weakref.ref(target, callback)
            del target
            print('import continued', flush=True)

            def main(args):
                print('node ran', flush=True)
            """
        ),
        encoding='utf-8',
    )
    script = textwrap.dedent(
        """
        from grasp_safety_filter.nodes import entry_points
        entry_points.NODE_MODULES['interrupted'] = 'interrupted_in_callback'
        entry_points.run_node('interrupted')
        """
    )
    environment = {**os.environ, 'PYTHONPATH': f'{tmp_path}{os.pathsep}{os.getcwd()}'}
    result = subprocess.run(
        [sys.executable, '-c', script],
        capture_output=True, text=True, timeout=60, env=environment, check=False,
    )
    assert (result.returncode, result.stderr) == (0, '')
    assert 'node ran' not in result.stdout
