"""What the launch files start, decided without ``launch``: nodes, parameters, remaps, recorder.

The launch files (``launch/*.launch.py``) only read their launch arguments and turn what
this module returns into ``launch_ros`` actions; everything they decide is here, in plain
Python, so it is tested without ROS, and the same :class:`NodeLaunch` gives the
``ros2 run`` command line of each node (:meth:`NodeLaunch.ros_arguments`), which the graph
tests start as OS processes.

Parameters: each node reads the parameter files, then its ``overrides``. An override beats
the file's ``/**`` section and the node's own section alike: ``launch_ros`` writes a
``parameters=[..., dict]`` entry as a file section under the node's name when the node's
name and namespace are given (:meth:`NodeLaunch.node_kwargs` gives ``namespace=''``), and
the command line passes ``-p name:=value``.

Recording (``paper_demo.launch.py record:=true``): ``ros2 bag record`` on every topic of the
topic table, under the node name :data:`RECORDER_NODE`, and the simulator waits for that
node to subscribe to every published topic before it starts the run
(``start.wait_for_recorder``), so the bag starts at t = 0. Without a ``ros2`` executable
there is no recorder: :func:`recorder_problem` says so and the launch stops.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
import shutil
from typing import Any

import yaml

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.parameters import ROS_PARAMETERS_KEY
from grasp_safety_filter.io.paths import PACKAGE_NAME
from grasp_safety_filter.io.schemas import (
    GRASP_MARKERS_NODE,
    HAND_SIM_NODE,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)

#: Node name of the recorder ``ros2 bag record`` runs (its ``--node-name``, and the default).
RECORDER_NODE = 'rosbag2_recorder'

#: Bag storage of the recorder (the Jazzy default).
RECORDER_STORAGE = 'mcap'

#: The simulator's parameter naming the recorder to wait for.
WAIT_FOR_RECORDER = 'start.wait_for_recorder'

#: ``safety_filter.launch.py`` argument -> the topic it remaps.
REMAPPED_TOPICS: dict[str, str] = {
    'joint_states': topics.JOINT_STATES,
    'object_odom': topics.OBJECT_ODOM,
    'effort_nominal': topics.EFFORT_NOMINAL,
    'effort_command': topics.EFFORT_COMMAND,
    'margins': topics.MARGINS,
    'diagnostics': topics.DIAGNOSTICS,
}


def parse_bool(name: str, text: str | bool) -> bool:
    """Return a ``true``/``false`` launch argument as a bool (ValueError naming it else)."""
    if isinstance(text, bool):
        return text
    value = str(text).strip().lower()
    if value not in ('true', 'false'):
        raise ValueError(f"launch argument '{name}': expected true or false, got {text!r}")
    return value == 'true'


def parameter_argument(name: str, value: Any) -> str:
    """Return ``name:=value`` as ``-p`` takes it (the value in YAML, as ``launch_ros`` does)."""
    text = yaml.safe_dump(value, default_flow_style=True).strip()
    return f'{name}:={text.removesuffix("...").strip()}'


@dataclass(frozen=True)
class NodeLaunch:
    """One node of a launch: its executable, parameter files, overrides and remappings.

    Attributes:
        executable: The package's executable (``ros2 run grasp_safety_filter <executable>``).
        name: Node name (the section of the parameter files it reads).
        params_files: Parameter files, in order.
        overrides: ``{parameter: value}`` beating the files, the node's own section included.
        remappings: ``(from, to)`` topic remappings.
        ends_launch: Whether the launch ends when this node exits (the simulator does).

    """

    executable: str
    name: str
    params_files: tuple[str, ...]
    overrides: Mapping[str, Any] = field(default_factory=dict)
    remappings: tuple[tuple[str, str], ...] = ()
    ends_launch: bool = False

    def ros_arguments(self, overrides_file: str | Path | None = None) -> list[str]:
        """Return the node's ``--ros-args`` (``ros2 run`` takes them after the executable).

        ``overrides_file``: write the overrides there, in the node's own section (as
        ``launch_ros`` does), and pass it after the other files instead of ``-p`` arguments.
        """
        arguments = ['--ros-args']
        for path in self.params_files:
            arguments += ['--params-file', str(path)]
        if overrides_file is not None:
            self.write_overrides(overrides_file)
            arguments += ['--params-file', str(overrides_file)]
        else:
            for name, value in self.overrides.items():
                arguments += ['-p', parameter_argument(name, value)]
        for source, target in self.remappings:
            arguments += ['-r', f'{source}:={target}']
        return arguments

    def command(self, bin_directory: str | Path | None = None) -> list[str]:
        """Return the executable (in ``bin_directory``, else on ``PATH``) and its arguments."""
        executable = self.executable if bin_directory is None else str(
            Path(bin_directory) / self.executable
        )
        return [executable, *self.ros_arguments()]

    def write_overrides(self, path: str | Path) -> Path:
        """Write the overrides as a parameter file with the node's own section; return it."""
        path = Path(path)
        path.write_text(
            yaml.safe_dump({f'/{self.name}': {ROS_PARAMETERS_KEY: dict(self.overrides)}})
        )
        return path

    def node_kwargs(self) -> dict[str, Any]:
        """Return the keyword arguments of the node's ``launch_ros.actions.Node``.

        ``namespace=''`` makes ``launch_ros`` write the overrides under the node's name,
        where they beat the files' node sections (under ``/**`` they would not).
        """
        return {
            'package': PACKAGE_NAME,
            'executable': self.executable,
            'name': self.name,
            'namespace': '',
            'parameters': [*self.params_files, dict(self.overrides)],
            'remappings': [tuple(pair) for pair in self.remappings],
            'output': 'screen',
        }


def paper_demo(
    config: str | Path,
    filter_on: bool = True,
    record: bool = False,
    duration: float | None = None,
    viz: bool = False,
) -> list[NodeLaunch]:
    """Return the paper demo's nodes: simulator, nominal controller, safety filter.

    ``filter_on`` False: the filter passes u_nom through; ``record``: the simulator waits for
    :data:`RECORDER_NODE`; ``duration``: simulated duration, s (None: the file's); ``viz``:
    also ``grasp_markers_node`` (the grasp on ``/grasp/markers``).
    """
    files = (str(config),)
    sim_time = {'use_sim_time': True}
    sim_overrides: dict[str, Any] = dict(sim_time)
    if duration is not None:
        sim_overrides['duration'] = float(duration)
    if record:
        sim_overrides[WAIT_FOR_RECORDER] = RECORDER_NODE
    nodes = [
        NodeLaunch(HAND_SIM_NODE, HAND_SIM_NODE, files, sim_overrides, ends_launch=True),
        NodeLaunch(NOMINAL_CONTROLLER_NODE, NOMINAL_CONTROLLER_NODE, files, dict(sim_time)),
        NodeLaunch(
            SAFETY_FILTER_NODE,
            SAFETY_FILTER_NODE,
            files,
            {**sim_time, 'enabled': bool(filter_on)},
        ),
    ]
    if viz:
        nodes.append(NodeLaunch(GRASP_MARKERS_NODE, GRASP_MARKERS_NODE, files, dict(sim_time)))
    return nodes


def safety_filter_alone(
    config: str | Path,
    use_sim_time: bool = False,
    enabled: bool = True,
    remaps: Mapping[str, str] | None = None,
) -> NodeLaunch:
    """Return the safety filter node of ``safety_filter.launch.py``.

    ``remaps``: launch argument (a key of :data:`REMAPPED_TOPICS`) -> the topic to use; an
    unknown argument raises ValueError.
    """
    remappings = _remappings(remaps, REMAPPED_TOPICS)
    return NodeLaunch(
        SAFETY_FILTER_NODE,
        SAFETY_FILTER_NODE,
        (str(config),),
        {'use_sim_time': bool(use_sim_time), 'enabled': bool(enabled)},
        remappings,
    )


#: ``real_hand.launch.py`` argument -> the topic it remaps, in every node it starts.
REAL_HAND_TOPICS: dict[str, str] = {
    'joint_states': topics.JOINT_STATES,
    'object_odom': topics.OBJECT_ODOM,
    'object_pose': topics.OBJECT_POSE,
    'effort_nominal': topics.EFFORT_NOMINAL,
    'effort_command': topics.EFFORT_COMMAND,
    'effort_controller': topics.EFFORT_CONTROLLER_COMMANDS,
}

#: ``real_hand.launch.py``: the filter's ``margins.period`` on a hand's stream, s. The margins
#: message of every tick (some 60 rows) cost the node more than its QP: at 1 kHz it answered
#: 52 % of the periods with it and 92 % at 100 Hz of margins (grasp-bench-realtime).
REAL_HAND_MARGINS_PERIOD = 0.01

#: ``real_hand.launch.py``: the simulator's hardware mode (a driver and a tracker on the
#: wall clock, no /clock) when ``sim:=true``.
HARDWARE_MODE = {'lockstep': False, 'publish_clock': False, 'use_sim_time': False}


def real_hand(
    config: str | Path,
    *,
    simulate: bool = False,
    nominal: bool = True,
    enabled: bool = True,
    object_message: str = 'odometry',
    command_message: str = 'joint_state',
    remaps: Mapping[str, str] | None = None,
    viz: bool = False,
) -> list[NodeLaunch]:
    """Return the nodes of ``real_hand.launch.py``: the controllers on a hand's streams.

    Both controllers tick on each joint state (``input.sync: latest``) on the wall clock
    (no ``use_sim_time``), the object's state estimated from the tracker's samples; the
    filter publishes its margins at 100 Hz (:data:`REAL_HAND_MARGINS_PERIOD`).

    ``simulate``: also start ``hand_sim_node`` in its hardware mode in place of the hand;
    ``nominal`` False: a controller of one's own publishes u_nom; ``object_message`` and
    ``command_message``: ``input.object_message`` and ``command.message``; ``remaps``:
    launch argument (a key of :data:`REAL_HAND_TOPICS`) -> the topic, in every node (an
    unknown one raises ValueError); ``viz``: also ``grasp_markers_node`` (it draws the
    tracker's pose: with ``object_message`` ``pose``, none).
    """
    remappings = _remappings(remaps, REAL_HAND_TOPICS)
    files = (str(config),)
    streams = {
        'use_sim_time': False,
        'input.sync': 'latest',
        'input.object_message': object_message,
    }
    nodes = []
    if simulate:
        sim = {
            **HARDWARE_MODE,
            'tracker.message': object_message,
            'hardware.command_message': command_message,
        }
        nodes.append(
            NodeLaunch(HAND_SIM_NODE, HAND_SIM_NODE, files, sim, remappings, ends_launch=True)
        )
    if nominal:
        nodes.append(
            NodeLaunch(
                NOMINAL_CONTROLLER_NODE, NOMINAL_CONTROLLER_NODE, files, streams, remappings
            )
        )
    filter_overrides = {
        **streams,
        'enabled': bool(enabled),
        'command.message': command_message,
        'margins.period': REAL_HAND_MARGINS_PERIOD,
    }
    nodes.append(
        NodeLaunch(SAFETY_FILTER_NODE, SAFETY_FILTER_NODE, files, filter_overrides, remappings)
    )
    if viz:
        wall = {'use_sim_time': False}
        nodes.append(NodeLaunch(GRASP_MARKERS_NODE, GRASP_MARKERS_NODE, files, wall, remappings))
    return nodes


def _remappings(
    remaps: Mapping[str, str] | None, table: Mapping[str, str]
) -> tuple[tuple[str, str], ...]:
    """Return ``(topic, target)`` for each launch argument of ``table`` remapped elsewhere."""
    remaps = dict(remaps or {})
    unknown = sorted(set(remaps) - set(table))
    if unknown:
        raise ValueError(f'remappings: unknown arguments {unknown}; known: {sorted(table)}')
    return tuple(
        (topic, remaps[name]) for name, topic in table.items() if remaps.get(name, topic) != topic
    )


def recorder_command(
    bag: str | Path,
    node_name: str = RECORDER_NODE,
    storage: str = RECORDER_STORAGE,
    topic_names: Sequence[str] | None = None,
) -> list[str]:
    """Return the ``ros2 bag record`` command recording ``topic_names`` (None: the table)."""
    names = [spec.name for spec in topics.TOPICS] if topic_names is None else list(topic_names)
    return [
        'ros2', 'bag', 'record', '-s', storage, '-o', str(bag), '--node-name', node_name,
        '--topics', *names,
    ]  # fmt: skip


def recorder_problem(
    record: bool, which: Callable[[str], str | None] | None = None
) -> str | None:
    """Return why recording cannot run (None: it can, or is not asked for)."""
    which = shutil.which if which is None else which
    if record and which('ros2') is None:
        return (
            'record:=true needs ros2 bag record, but there is no ros2 executable on PATH '
            '(source a ROS 2 Jazzy setup with rosbag2 and its mcap storage plugin): not '
            'starting the demo without its bag'
        )
    return None
