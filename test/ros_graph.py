"""The package's nodes as OS processes over DDS: start them, record them, drive them.

Imported by the graph tests. Runs are recorded by the package's ``grasp-record`` (an rclpy
node writing every topic of the table to a rosbag2 bag, as ``ros2 bag record`` would); run
as a script this module is the graph's planner::

    python test/ros_graph.py planner --initial-position 0 0 0.2195 --rise 0.01 --stop-after 0.4

``planner``: on simulation time, publishes ``/object/reference`` every ``--period`` s: a
short trajectory (``--horizon`` s of 1 ms points) of a smooth (quintic) rise by ``--rise``
m and turn by ``--yaw`` rad about palm z over ``--move-time`` s from the initial pose, with
twist and acceleration feed-forward, until ``--stop-after`` s; then it stays silent.

The node commands come from :mod:`grasp_safety_filter.io.launch_arguments`, as the launch
files' nodes do.
"""

from __future__ import annotations

import argparse
from collections.abc import Iterable, Iterator, Mapping, Sequence
from contextlib import contextmanager
import dataclasses
from dataclasses import dataclass
import math
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Any

import numpy as np

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import read_bag
from grasp_safety_filter.io.launch_arguments import NodeLaunch, RECORDER_NODE
from grasp_safety_filter.io.messages import header_stamp_ns
from grasp_tools.bench_ros import stop_process

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
HERE = Path(__file__).resolve()

#: Directory of the package's console scripts (the interpreter's, a venv's ``bin``).
BIN = Path(sys.executable).parent

#: Pass node overrides as a parameter file with the node's own section (as ``launch_ros``
#: writes a ``parameters=[..., dict]`` entry) instead of ``-p name:=value`` (as ``ros2 run``
#: users do). Both beat the parameter file's node section.
OVERRIDES_AS_FILE = False

#: Diagnostic values that time the computation (wall clock): never equal between runs.
TIMING_KEYS = frozenset({'solve_time_us', 'step_time_us', 'tick_time_us'})


# ----------------------------------------------------------------------------------------
# Processes


@dataclass
class Process:
    """A started process and its log file."""

    name: str
    popen: subprocess.Popen
    log: Path

    def text(self) -> str:
        """Return what the process wrote so far (stdout and stderr)."""
        return self.log.read_text(errors='replace') if self.log.exists() else ''


class Processes:
    """Processes of one test, each in its own session, all stopped on exit.

    Args:
        log_dir: Directory of the processes' log files.
        env: Their environment (default: this process's, with its ROS_DOMAIN_ID).

    """

    def __init__(self, log_dir: Path, env: Mapping[str, str] | None = None) -> None:
        self.log_dir = Path(log_dir)
        self.log_dir.mkdir(parents=True, exist_ok=True)
        self.env = dict(os.environ if env is None else env)
        self.env.pop('AMENT_PREFIX_PATH', None)
        self.env['PYTHONUNBUFFERED'] = '1'
        self.started: dict[str, Process] = {}

    def start(self, name: str, command: Sequence[str]) -> Process:
        """Start ``command`` with stdout and stderr to ``<log_dir>/<name>.log``."""
        log = self.log_dir / f'{name}.log'
        with log.open('w') as out:
            out.write(' '.join(map(str, command)) + '\n')
            out.flush()
            popen = subprocess.Popen(
                [str(c) for c in command],
                stdout=out,
                stderr=subprocess.STDOUT,
                env=self.env,
                cwd=self.log_dir,
                start_new_session=True,
            )
        process = Process(name, popen, log)
        self.started[name] = process
        return process

    def wait(self, name: str, timeout: float) -> int:
        """Wait for a process to exit; return its exit code.

        Raises:
            AssertionError: It is still running after ``timeout`` s (with every log).

        """
        try:
            return self.started[name].popen.wait(timeout=timeout)
        except subprocess.TimeoutExpired as error:
            message = f'{name} still running after {timeout} s\n{self.logs()}'
            raise AssertionError(message) from error

    def stop(self, name: str, timeout: float = 10.0) -> int:
        """SIGINT a process (SIGKILL after ``timeout`` s); return its exit code."""
        return stop_process(self.started[name].popen, timeout)

    def logs(self) -> str:
        """Return every process's log, for assertion messages."""
        return '\n'.join(f'--- {name}\n{p.text()[-4000:]}' for name, p in self.started.items())

    def __enter__(self) -> Processes:
        return self

    def __exit__(self, *exc: object) -> None:
        for name in reversed(list(self.started)):
            self.stop(name, timeout=5.0)


#: Test-only filter override. ``input.hold_timeout`` is also the wall-clock time without a
#: tick after which the safety filter's input watchdog sends its fallback command, which a
#: lockstep simulator waiting for that stamp applies: on this shared machine a scheduling
#: stall of 0.1 s would put a fallback tick into the run. Above the simulator's own
#: ``command_timeout`` (1 s), the simulator recovers a lost command first. Without rejected
#: input the value changes no message of the run.
STALL_TOLERANCE = {'input.hold_timeout': 2.0}


def with_overrides(node: NodeLaunch, **values: Any) -> NodeLaunch:
    """Return ``node`` with further overrides (test-only parameters)."""
    return dataclasses.replace(node, overrides={**node.overrides, **values})


def node_command(
    node: NodeLaunch, work_dir: Path, overrides_as_file: bool = OVERRIDES_AS_FILE
) -> list[str]:
    """Return the ``ros2 run``-equivalent command line of a node (console script + ros args).

    Args:
        node: The node.
        work_dir: Where an overrides file goes.
        overrides_as_file: Overrides as a parameter file (``launch_ros``), not ``-p``.

    """
    overrides = work_dir / f'{node.name}_overrides.yaml' if overrides_as_file else None
    return [str(BIN / node.executable), *node.ros_arguments(overrides_file=overrides)]


def script_command(*arguments: str) -> list[str]:
    """Return the command running this module as a script (``record``, ``planner``)."""
    return [sys.executable, str(HERE), *arguments]


@dataclass(frozen=True)
class GraphRun:
    """What a graph run left: its bag, logs, exit codes and wall time."""

    bag: Path
    logs: str
    returncodes: Mapping[str, int]
    wall_time: float


def run_graph(
    work_dir: Path,
    nodes: Sequence[NodeLaunch],
    timeout: float,
    recorder: str = RECORDER_NODE,
    extra: Mapping[str, Sequence[str]] | None = None,
    recorder_delay: float = 0.0,
    overrides_as_file: bool = OVERRIDES_AS_FILE,
) -> GraphRun:
    """Run a graph to the simulator's exit, recorded from the start; stop every process.

    The recorder starts first (after ``recorder_delay`` s if given: a late recorder), then
    ``extra`` processes (a planner), then the nodes; once the simulator exits, the recorder
    is given a moment for the last answers, then stopped (it closes the bag).

    Args:
        work_dir: Directory of the bag (``work_dir/bag``), logs and override files.
        nodes: The nodes (one of them ``hand_sim_node``).
        timeout: Wall-clock limit for the simulator's run, s.
        recorder: The recorder's node name.
        extra: Further processes, name -> command.
        recorder_delay: Start the recorder this long after the nodes, s (0: before them).
        overrides_as_file: Give the nodes their overrides as ``launch_ros`` does, in a
            parameter file with the node's section, instead of ``-p``.

    """
    work_dir = Path(work_dir)
    bag = work_dir / 'bag'
    start = time.monotonic()
    with Processes(work_dir / 'logs') as processes:
        record = [str(BIN / 'grasp-record'), str(bag), '--node-name', recorder]
        if recorder_delay <= 0.0:
            processes.start('recorder', record)
        for name, command in (extra or {}).items():
            processes.start(name, command)
        for node in nodes:
            processes.start(node.name, node_command(node, work_dir, overrides_as_file))
        if recorder_delay > 0.0:
            time.sleep(recorder_delay)
            processes.start('recorder', record)
        returncodes = {'hand_sim_node': processes.wait('hand_sim_node', timeout)}
        time.sleep(0.5)
        for name in processes.started:
            returncodes[name] = processes.stop(name)
        logs = processes.logs()
    return GraphRun(bag, logs, returncodes, time.monotonic() - start)


# ----------------------------------------------------------------------------------------
# Comparing streams


def _compare(a: Any, b: Any, where: str, atol: float, out: list[str]) -> None:
    if dataclasses.is_dataclass(a) and dataclasses.is_dataclass(b):
        for f in dataclasses.fields(a):
            _compare(getattr(a, f.name), getattr(b, f.name), f'{where}.{f.name}', atol, out)
    elif isinstance(a, np.ndarray) or isinstance(b, np.ndarray):
        a, b = np.asarray(a), np.asarray(b)
        if a.shape != b.shape:
            out.append(f'{where}: shape {a.shape} != {b.shape}')
        elif a.dtype.kind in 'fc' and not np.allclose(a, b, rtol=0.0, atol=atol):
            out.append(f'{where}: max difference {np.max(np.abs(a - b)):.3g}')
        elif a.dtype.kind not in 'fc' and not np.array_equal(a, b):
            out.append(f'{where}: {a.tolist()} != {b.tolist()}')
    elif isinstance(a, list | tuple) and isinstance(b, list | tuple):
        if len(a) != len(b):
            out.append(f'{where}: {len(a)} != {len(b)} entries')
        for k, (x, y) in enumerate(zip(a, b, strict=False)):
            _compare(x, y, f'{where}[{k}]', atol, out)
    elif isinstance(a, float) and isinstance(b, float):
        if not abs(a - b) <= atol:
            out.append(f'{where}: {a!r} != {b!r}')
    elif a != b:
        out.append(f'{where}: {a!r} != {b!r}')


def without_timing(msg: Any) -> Any:
    """Return a DiagnosticArray with the wall-clock timing values blanked (else ``msg``)."""
    if getattr(msg, '__msgtype__', '') != 'diagnostic_msgs/msg/DiagnosticArray':
        return msg
    statuses = [
        dataclasses.replace(
            status,
            values=[
                dataclasses.replace(kv, value='') if kv.key in TIMING_KEYS else kv
                for kv in status.values
            ],
        )
        for status in msg.status
    ]
    return dataclasses.replace(msg, status=statuses)


#: After the controllers' answer to the final state, what arrives within this many ns still
#: belongs to the run (the rest of that answer); later messages (a watchdog's) do not.
RUN_END_SLACK_NS = 50_000_000


def _substreams(topic: str, messages: list[Any]) -> dict[str, list[Any]]:
    """Split ``/diagnostics`` by status name: the order between publishers is not defined."""
    if topic != topics.DIAGNOSTICS:
        return {topic: messages}
    streams: dict[str, list[Any]] = {}
    for msg in messages:
        key = f'{topic}[{",".join(s.name for s in msg.status)}]'
        streams.setdefault(key, []).append(msg)
    return streams


def run_stream(
    bag: Path, topic_names: Iterable[str] | None = None
) -> tuple[dict[str, list[Any]], dict[str, list[Any]]]:
    """Return a graph bag's messages per topic during the run, and those after it.

    The run ends with the safety filter's answer to the final state: the first
    ``/hand/effort_command`` stamped like the last ``/hand/joint_states``, and what arrives
    within :data:`RUN_END_SLACK_NS` of it.
    """
    names = [s.name for s in topics.TOPICS] if topic_names is None else list(topic_names)
    recorded = read_bag(bag, set(names) | {topics.JOINT_STATES, topics.EFFORT_COMMAND})
    last_state = header_stamp_ns(recorded[topics.JOINT_STATES][-1][1])
    answers = [
        arrival
        for arrival, msg in recorded[topics.EFFORT_COMMAND]
        if header_stamp_ns(msg) == last_state
    ]
    end = (answers[0] if answers else recorded[topics.JOINT_STATES][-1][0]) + RUN_END_SLACK_NS
    during = {t: [m for a, m in recorded.get(t, []) if a <= end] for t in names}
    after = {t: [m for a, m in recorded.get(t, []) if a > end] for t in names}
    return during, after


#: The simulator's lockstep watchdog statuses: a command it waited for in vain (it then
#: published its state again), and a command that came after it had stepped on (an answer
#: to a state it published again, when the first answer came after all).
RESENT_TEXT = 'no command stamped'
LATE_TEXT = 'is late'
WATCHDOG_TEXTS = (RESENT_TEXT, LATE_TEXT)


def _waiting_for_a_first_tick(status: Any) -> bool:
    """Tell a controller's status from before its first tick, saying what it waits for.

    It answers no tick (no status value) and comes every second of wall time while the
    graph connects; the runner, which has no wall clock, has none.
    """
    keys = {pair.key for pair in status.values}
    if status.name == 'nominal_controller':
        return 'input.waiting' in keys
    return status.name == 'safety_filter' and 'input.watchdog' in keys and 'status' not in keys


def _same(a: Any, b: Any) -> bool:
    found: list[str] = []
    _compare(a, b, '', 0.0, found)
    return not found


def without_watchdog_repeats(key: str, messages: list[Any]) -> tuple[list[Any], int]:
    """Drop what the lockstep watchdog adds to a stream; return the rest and the count dropped.

    A command lost while DDS still connects two nodes (discovery can take a few seconds)
    makes the simulator report it and publish the same state again, and the controllers
    answer it again: the simulator's watchdog statuses, the filter's while it waits for a
    first tick, and each message equal to the one before it on its (sub)stream go; the run's
    stream is what remains.
    """
    kept: list[Any] = []
    for msg in messages:
        statuses = getattr(msg, 'status', None)
        if statuses and all(
            (st.name == 'hand_sim' and any(text in st.message for text in WATCHDOG_TEXTS))
            or _waiting_for_a_first_tick(st)
            for st in statuses
        ):
            continue
        if kept and _same(kept[-1], msg):
            continue
        kept.append(msg)
    return kept, len(messages) - len(kept)


def stream_differences(
    graph_bag: Path,
    runner_bag: Path,
    atol: float = 1e-12,
    topic_names: Iterable[str] | None = None,
    repeats: dict[str, int] | None = None,
) -> list[str]:
    """Return how a graph run's message stream differs from the runner's, per topic.

    The graph's stream is :func:`run_stream`'s, during the run, without the lockstep
    watchdog's repeats (:func:`without_watchdog_repeats`; their count per stream goes to
    ``repeats`` if given). Messages are compared decoded, field by field, in arrival order
    per topic (``/diagnostics`` per status name): stamps, names and strings exactly, floats
    to ``atol``; diagnostics without their timing values (:data:`TIMING_KEYS`). Bag
    timestamps are not compared (arrival time against stamp). Empty: the same stream.
    """
    names = [s.name for s in topics.TOPICS] if topic_names is None else list(topic_names)
    graph, _ = run_stream(graph_bag, names)
    runner = read_bag(runner_bag, names)
    differences: list[str] = []
    for topic in names:
        ours = _substreams(topic, [without_timing(m) for m in graph.get(topic, [])])
        for key in list(ours):
            ours[key], dropped = without_watchdog_repeats(key, ours[key])
            if repeats is not None and dropped:
                repeats[key] = dropped
        theirs = _substreams(topic, [without_timing(m) for _, m in runner.get(topic, [])])
        for key in sorted(set(ours) | set(theirs)):
            a_list, b_list = ours.get(key, []), theirs.get(key, [])
            found: list[str] = []
            if len(a_list) != len(b_list):
                found.append(f'{key}: {len(a_list)} messages, the runner {len(b_list)}')
            for k, (a, b) in enumerate(zip(a_list, b_list, strict=False)):
                _compare(a, b, f'{key}[{k}]', atol, found)
                if len(found) > 5:
                    break
            differences += found[:6]
    return differences


def lockstep_watchdog_counts(bag: Path) -> dict[str, int]:
    """Count the simulator's lockstep watchdog statuses during a graph run, by text.

    Returns:
        ``{RESENT_TEXT: states published again, LATE_TEXT: commands that came late}``.

    """
    during, _ = run_stream(bag, [topics.DIAGNOSTICS])
    counts = dict.fromkeys(WATCHDOG_TEXTS, 0)
    for msg in during[topics.DIAGNOSTICS]:
        for status in msg.status:
            for text in WATCHDOG_TEXTS:
                if status.name == 'hand_sim' and text in status.message:
                    counts[text] += 1
    return counts


def unexplained_repeats(repeats: Mapping[str, int], resent: int, late: int) -> list[str]:
    """Return which dropped repeats the lockstep watchdog does not explain (empty: all).

    Each state the simulator published again (``resent``, one status each) repeats one
    ``/hand/joint_states`` and one ``/object/odom``; the controllers answer it again, so a
    repeated command and, if the first answer came after all, one command the simulator
    reports as late (``late``) belong to it. The simulator steps once per stamp: no
    ``/hand/contacts`` repeats.

    Args:
        repeats: Messages dropped per (sub)stream (:func:`stream_differences`).
        resent: The simulator's statuses saying it published its state again.
        late: Its statuses saying a command came late.

    """
    found = [
        f'{topic}: {repeats.get(topic, 0)} repeated, {resent} states published again'
        for topic in (topics.JOINT_STATES, topics.OBJECT_ODOM)
        if repeats.get(topic, 0) != resent
    ]
    if late > resent:
        found.append(f'{late} late commands, {resent} states published again')
    if repeats.get(topics.EFFORT_COMMAND, 0) > resent:
        found.append(
            f'{topics.EFFORT_COMMAND}: {repeats[topics.EFFORT_COMMAND]} repeated, '
            f'{resent} states published again'
        )
    if repeats.get(topics.CONTACTS, 0):
        found.append(f'{topics.CONTACTS}: {repeats[topics.CONTACTS]} repeated')
    return found


# ----------------------------------------------------------------------------------------
# The recorder process


# ----------------------------------------------------------------------------------------
# The planner process


def smooth_step(u: float) -> tuple[float, float, float]:
    """Return the quintic s(u) = 10u³ - 15u⁴ + 6u⁵ on [0, 1] and its first two derivatives."""
    u = min(max(u, 0.0), 1.0)
    s = u**3 * (10.0 - 15.0 * u + 6.0 * u * u)
    ds = 30.0 * u * u * (1.0 - u) ** 2
    dds = 60.0 * u * (1.0 - u) * (1.0 - 2.0 * u)
    return s, ds, dds


@dataclass(frozen=True)
class PlannerMotion:
    """A rise along palm z and a turn about it, quintic in time, from an initial pose.

    Attributes:
        initial_position: Object centre at t0, palm frame, m.
        initial_yaw: Object yaw at t0 (roll = pitch = 0), rad.
        rise: Total rise, m.
        yaw: Total turn, rad.
        move_time: Duration of the motion, s.
        t0: Start, s.

    """

    initial_position: tuple[float, float, float]
    initial_yaw: float = 0.0
    rise: float = 0.01
    yaw: float = 0.0
    move_time: float = 0.3
    t0: float = 0.0

    def at(self, t: float) -> Any:
        """Return the :class:`~grasp_safety_filter.io.messages.ObjectReference` at ``t``, s."""
        from grasp_safety_filter.io.messages import ObjectReference

        s, ds, dds = smooth_step((t - self.t0) / self.move_time)
        T = self.move_time
        z = self.initial_position[2] + self.rise * s
        psi = self.initial_yaw + self.yaw * s
        c, n = math.cos(psi), math.sin(psi)
        R = np.array([[c, -n, 0.0], [n, c, 0.0], [0.0, 0.0, 1.0]])
        velocity = np.array([0.0, 0.0, self.rise * ds / T, 0.0, 0.0, self.yaw * ds / T])
        acceleration = np.array(
            [0.0, 0.0, self.rise * dds / T**2, 0.0, 0.0, self.yaw * dds / T**2]
        )
        position = np.array([self.initial_position[0], self.initial_position[1], z])
        return ObjectReference(position, R, velocity, acceleration)


def _plan(args: argparse.Namespace) -> int:
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.parameter import Parameter

    from grasp_safety_filter.io.messages import (
        clock_from_msg,
        MessageNamespace,
        reference_to_msg,
        seconds_to_nanoseconds,
    )
    from grasp_safety_filter.io.topics import CLOCK, OBJECT_REFERENCE, topic_spec

    motion = PlannerMotion(
        tuple(args.initial_position),
        args.initial_yaw,
        args.rise,
        args.yaw,
        args.move_time,
    )
    msgs = MessageNamespace.from_rclpy()
    rclpy.init(args=[])
    node = rclpy.create_node(
        'planner', parameter_overrides=[Parameter('use_sim_time', value=True)]
    )
    spec = topic_spec(OBJECT_REFERENCE)
    publisher = node.create_publisher(msgs.MultiDOFJointTrajectory, spec.name, spec.qos.to_rclpy())
    period_ns = seconds_to_nanoseconds(args.period)
    step = 0.001
    taus = [k * step for k in range(round(args.horizon / step) + 1)]
    state = {'next_ns': 0, 'published': 0}

    def on_clock(msg: Any) -> None:
        t = clock_from_msg(msg)
        t_ns = seconds_to_nanoseconds(t)
        if t > args.stop_after or t_ns < state['next_ns']:
            return
        state['next_ns'] = t_ns + period_ns
        points = [motion.at(t + tau) for tau in taus]
        publisher.publish(reference_to_msg(msgs, t, taus, points))
        state['published'] += 1

    clock_spec = topic_spec(CLOCK)
    node.create_subscription(msgs.Clock, clock_spec.name, on_clock, clock_spec.qos.to_rclpy())
    print(f'planner: {motion}, until t = {args.stop_after} s', flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        print(f'planner: published {state["published"]} references', flush=True)
        node.destroy_node()
        rclpy.try_shutdown()
    return 0


@contextmanager
def _quiet_broken_pipe() -> Iterator[None]:
    try:
        yield
    except BrokenPipeError:
        pass


def main(argv: list[str] | None = None) -> int:
    """Run the planner (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)
    plan = commands.add_parser('planner', help='publish /object/reference')
    plan.add_argument('--initial-position', type=float, nargs=3, required=True)
    plan.add_argument('--initial-yaw', type=float, default=0.0)
    plan.add_argument('--rise', type=float, default=0.01)
    plan.add_argument('--yaw', type=float, default=0.0)
    plan.add_argument('--move-time', type=float, default=0.3)
    plan.add_argument('--stop-after', type=float, default=math.inf)
    plan.add_argument('--period', type=float, default=0.01)
    plan.add_argument('--horizon', type=float, default=0.05)
    args = parser.parse_args(argv)
    with _quiet_broken_pipe():
        return _plan(args)


if __name__ == '__main__':
    sys.exit(main())
