"""``grasp-bench-ros``: how fast the three nodes run as a ROS 2 graph over DDS.

Measured in one run, on the same machine, so that the figures can be compared:

1. **Baseline.** A bare rclpy ping-pong: this process publishes a 9-joint
   ``sensor_msgs/JointState`` on ``/bench/ping``, a second process (this module with
   ``--echo``) publishes it back on ``/bench/pong``, and the next ping goes out when the
   pong is in. Its round trip is the least a lockstep tick can cost: two DDS hops and two
   Python callbacks.
2. **Graph.** ``hand_sim_node``, ``nominal_controller_node`` and ``safety_filter_node`` run
   as three OS processes (their console scripts, as ``ros2 run`` starts them) on the paper's
   scenario for ``--duration`` simulated seconds, in lockstep with ``use_sim_time``. A
   monitor node in this process subscribes to the state, the nominal command, the command and
   ``/diagnostics`` and notes when each message of each stamp arrives (steady clock):

   - tick period: between the arrivals of consecutive states (``/hand/joint_states``);
   - state → command: from a state's arrival to the arrival of the command of its stamp
     (one tick of the whole graph: nominal controller, filter, three DDS hops);
   - filter latency: from a nominal command's arrival to the arrival of the filter's command
     of the same stamp (the filter's callback, solve and publish, plus one DDS hop, since both
     messages reach the monitor alike);
   - the filter's own tick (``tick_time_us`` on ``/diagnostics``: model terms, filter step,
     message conversion);
   - CPU time of each node process over the run (``/proc/<pid>/stat``), per tick.

Goals (issue: the real ROS 2 graph): tick period <= 3 x the baseline round trip; filter
latency <= 1 ms at p99 on an idle machine. The figures are printed (and written as JSON with
``--json``); nothing here asserts a time.
"""

from __future__ import annotations

import argparse
from collections.abc import Sequence
from functools import partial
import json
import os
from pathlib import Path
import signal
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np
import yaml

from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.messages import header_stamp_ns, rclpy_message_class
from grasp_safety_filter.io.parameters import (
    load_parameter_file,
    ParameterError,
    ROS_PARAMETERS_KEY,
)
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import (
    HAND_SIM_NODE,
    load_node_parameters,
    NODE_SCHEMAS,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.io.topics import (
    DIAGNOSTICS,
    EFFORT_COMMAND,
    EFFORT_NOMINAL,
    JOINT_STATES,
    topic_spec,
    TOPICS,
)

PING_TOPIC = '/bench/ping'
PONG_TOPIC = '/bench/pong'

#: Node processes of the graph, in start order (the simulator last: it waits for the others).
GRAPH_NODES = (SAFETY_FILTER_NODE, NOMINAL_CONTROLLER_NODE, HAND_SIM_NODE)

#: Node name of the monitor, which the simulator waits for as for a recorder.
MONITOR_NODE = 'grasp_bench_monitor'

#: Wall-clock period of the CPU time readings of the node processes, s.
CPU_SAMPLE_PERIOD = 0.2

#: Goals of the graph's speed: tick period / baseline round trip, filter latency p99 (ms).
GOAL_PERIOD_RATIO = 3.0
GOAL_FILTER_LATENCY_P99_MS = 1.0


def percentiles(values: Sequence[float]) -> dict[str, float | None]:
    """Median, p99, max and count of ``values`` (None when empty)."""
    if not len(values):
        return {'median': None, 'p99': None, 'max': None, 'count': 0}
    array = np.asarray(values, dtype=float)
    return {
        'median': float(np.median(array)),
        'p99': float(np.percentile(array, 99)),
        'max': float(array.max()),
        'count': int(array.size),
    }


def _joint_state(msg_class: Any, n_joints: int = 9) -> Any:
    msg = msg_class()
    msg.name = [f'joint{i}' for i in range(n_joints)]
    msg.position = [0.1 * i for i in range(n_joints)]
    msg.velocity = [0.0] * n_joints
    msg.effort = [0.0] * n_joints
    return msg


def _ignore(_: Any) -> None:
    """Take a message and drop it."""


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process so far, s."""
    fields = Path(f'/proc/{pid}/stat').read_text(encoding='ascii').rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


def stop_process(process: subprocess.Popen[Any], timeout: float = 10.0) -> int:
    """End a node process: SIGINT (a clean shutdown), SIGKILL if it does not exit in time.

    Returns:
        Its exit code.
    """
    if process.poll() is None:
        process.send_signal(signal.SIGINT)
    try:
        process.wait(timeout=timeout)
    except subprocess.TimeoutExpired:
        process.kill()
        process.wait()
    return process.returncode


# --------------------------------------------------------------------------------- baseline
def echo_main() -> None:
    """Run the ping-pong echo node until SIGINT/SIGTERM (the ``--echo`` process)."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from sensor_msgs.msg import JointState

    rclpy.init()
    node = rclpy.create_node('bench_echo')
    qos = topic_spec(JOINT_STATES).qos.to_rclpy()
    pong = node.create_publisher(JointState, PONG_TOPIC, qos)
    node.create_subscription(JointState, PING_TOPIC, pong.publish, qos)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


def ping_pong(pings: int, warm_up: int = 100, timeout: float = 60.0) -> dict[str, Any]:
    """Round trips of a 9-joint JointState to the echo process and back, ms."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from sensor_msgs.msg import JointState

    echo = subprocess.Popen(
        [sys.executable, '-m', 'grasp_safety_filter.bench_ros', '--echo'],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('bench_ping', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    qos = topic_spec(JOINT_STATES).qos.to_rclpy()
    ping = node.create_publisher(JointState, PING_TOPIC, qos)
    received: list[int] = []
    node.create_subscription(
        JointState, PONG_TOPIC, lambda _: received.append(time.perf_counter_ns()), qos
    )
    msg = _joint_state(JointState)
    round_trips: list[float] = []
    try:
        deadline = time.monotonic() + timeout
        while ping.get_subscription_count() == 0 or node.count_publishers(PONG_TOPIC) == 0:
            executor.spin_once(timeout_sec=0.05)
            if time.monotonic() > deadline:
                raise RuntimeError('ping-pong: the echo process did not connect')
        time.sleep(0.5)  # let discovery settle in both directions
        while len(round_trips) < pings + warm_up and time.monotonic() < deadline:
            before = len(received)
            sent = time.perf_counter_ns()
            ping.publish(msg)
            while len(received) == before and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=1.0)
            if len(received) > before:
                round_trips.append((received[-1] - sent) / 1e6)
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown(context=context)
        stop_process(echo)
    return {'round_trip_ms': percentiles(round_trips[warm_up:])}


# ------------------------------------------------------------------------------------ graph
def scenario_file(config: Path, duration: float, directory: Path, enabled: bool) -> Path:
    """Write ``config`` with the run's duration, filter switch and monitor; paths absolute."""
    load_parameter_file(config)  # the same checks as the nodes' loader, with its messages
    document = yaml.safe_load(config.read_text(encoding='utf-8'))
    for section in document.values():
        model = section.get(ROS_PARAMETERS_KEY, {}).get('model', {})
        if 'urdf_file' in model:
            model['urdf_file'] = str((config.parent / model['urdf_file']).resolve())
    simulator = document[HAND_SIM_NODE][ROS_PARAMETERS_KEY]
    simulator['duration'] = float(duration)
    simulator.setdefault('start', {})['wait_for_recorder'] = MONITOR_NODE
    document[SAFETY_FILTER_NODE][ROS_PARAMETERS_KEY]['enabled'] = bool(enabled)
    path = directory / 'scenario.yaml'
    path.write_text(yaml.safe_dump(document), encoding='utf-8')
    return path


class _Monitor:
    """Arrival times (steady clock, ns) of each stamp's state, nominal and filtered command.

    Subscribed to every topic of the topic table, as a recorder is (the simulator waits for
    it with ``start.wait_for_recorder``), so the graph does the work a recorded run does.
    """

    def __init__(self, node: Any) -> None:
        self.arrivals: dict[str, dict[int, int]] = {
            JOINT_STATES: {},
            EFFORT_NOMINAL: {},
            EFFORT_COMMAND: {},
        }
        self.filter_tick_us: list[float] = []
        for spec in TOPICS:
            if spec.name in self.arrivals:
                callback = partial(self._note, spec.name)
            elif spec.name == DIAGNOSTICS:
                callback = self._on_diagnostics
            else:
                callback = _ignore
            node.create_subscription(
                rclpy_message_class(spec.msgtype), spec.name, callback, spec.qos.to_rclpy()
            )

    def _note(self, topic: str, msg: Any) -> None:
        self.arrivals[topic].setdefault(header_stamp_ns(msg), time.perf_counter_ns())

    def _on_diagnostics(self, msg: Any) -> None:
        for status in msg.status:
            if status.name != FILTER_DIAGNOSTIC:
                continue
            for pair in status.values:
                if pair.key == Key.TICK_TIME_US:
                    try:
                        self.filter_tick_us.append(float(pair.value))
                    except ValueError:
                        pass

    def figures(self) -> dict[str, Any]:
        states = self.arrivals[JOINT_STATES]
        nominal = self.arrivals[EFFORT_NOMINAL]
        commands = self.arrivals[EFFORT_COMMAND]
        ordered = [states[stamp] for stamp in sorted(states)]
        periods = np.diff(np.asarray(ordered, dtype=float)) / 1e6 if len(ordered) > 1 else []
        to_command = [(commands[s] - states[s]) / 1e6 for s in states if s in commands]
        filter_latency = [(commands[s] - nominal[s]) / 1e6 for s in nominal if s in commands]
        wall = (ordered[-1] - ordered[0]) / 1e9 if len(ordered) > 1 else float('nan')
        return {
            'ticks': len(states),
            'ticks_per_wall_second': (len(ordered) - 1) / wall if wall > 0 else None,
            'tick_period_ms': percentiles(periods),
            'state_to_command_ms': percentiles(to_command),
            'filter_latency_ms': percentiles(filter_latency),
            'filter_tick_ms': percentiles([us / 1e3 for us in self.filter_tick_us]),
        }


def override_arguments(overrides: Sequence[str]) -> dict[str, list[str]]:
    """Per node, the ``-p NAME:=VALUE`` arguments of the overrides it declares.

    Raises:
        ParameterError: An override is not ``NAME=VALUE`` or no node declares ``NAME``.
    """
    arguments: dict[str, list[str]] = {name: [] for name in GRAPH_NODES}
    for override in overrides:
        name, equals, value = override.partition('=')
        owners = [node for node in GRAPH_NODES if NODE_SCHEMAS[node].get(name) is not None]
        if not equals or not owners:
            raise ParameterError(
                f'--set {override!r}: expected NAME=VALUE with a parameter of one of the nodes'
            )
        for node in owners:
            arguments[node] += ['-p', f'{name}:={value}']
    return arguments


def graph_run(
    config: Path,
    duration: float,
    enabled: bool = True,
    overrides: Sequence[str] = (),
    timeout: float = 600.0,
) -> dict[str, Any]:
    """Run the three nodes as processes over DDS and time the run from a monitor node."""
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    bin_dir = Path(sys.executable).parent
    extra_arguments = override_arguments(overrides)
    with tempfile.TemporaryDirectory(prefix='grasp-bench-ros-') as tmp:
        params = scenario_file(config, duration, Path(tmp), enabled)
        context = rclpy.Context()
        rclpy.init(context=context)
        node = rclpy.create_node(MONITOR_NODE, context=context)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        monitor = _Monitor(node)
        processes: dict[str, subprocess.Popen[bytes]] = {}
        cpu: dict[str, float] = {}
        cpu_start: dict[str, float] = {}
        logs = {name: Path(tmp) / f'{name}.log' for name in GRAPH_NODES}
        try:
            for name in GRAPH_NODES:
                with logs[name].open('wb') as log:
                    processes[name] = subprocess.Popen(
                        [
                            str(bin_dir / name),
                            '--ros-args',
                            '--params-file',
                            str(params),
                            '-p',
                            'use_sim_time:=true',
                            *extra_arguments[name],
                        ],
                        stdout=log,
                        stderr=subprocess.STDOUT,
                    )
            simulator = processes[HAND_SIM_NODE]
            started = sampled = time.monotonic()
            while simulator.poll() is None and time.monotonic() - started < timeout:
                executor.spin_once(timeout_sec=0.05)
                # CPU from the first state on (not the start-up), read 5 times a second.
                running = bool(monitor.arrivals[JOINT_STATES])
                due = not cpu_start or time.monotonic() - sampled > CPU_SAMPLE_PERIOD
                if running and due:
                    sampled = time.monotonic()
                    for name, process in processes.items():
                        if process.poll() is None:
                            cpu[name] = _cpu_seconds(process.pid)
                            cpu_start.setdefault(name, cpu[name])
            if simulator.poll() is None:
                raise RuntimeError(f'the graph did not finish {duration} s within {timeout} s')
            if simulator.returncode != 0:
                raise RuntimeError(
                    f'hand_sim_node exited {simulator.returncode}:\n'
                    + logs[HAND_SIM_NODE].read_text(encoding='utf-8', errors='replace')[-2000:]
                )
        finally:
            for process in processes.values():
                stop_process(process)
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)
    figures = monitor.figures()
    ticks = max(figures['ticks'], 1)
    figures['cpu_ms_per_tick'] = {
        name: 1e3 * (seconds - cpu_start[name]) / ticks for name, seconds in cpu.items()
    }
    figures['duration'] = duration
    figures['enabled'] = enabled
    figures['overrides'] = list(overrides)
    return figures


# ------------------------------------------------------------------------------------ report
def _row(label: str, stats: dict[str, Any], unit: str = 'ms') -> str:
    if stats['median'] is None:
        return f'  {label:<44} (none)'
    return (
        f"  {label:<44} {stats['median']:8.3f} {stats['p99']:8.3f} {unit}"
        f"   ({stats['count']} samples)"
    )


def report(results: dict[str, Any]) -> str:
    """Format the figures as text, with the goals."""
    baseline = results['baseline']['round_trip_ms']
    graph = results['graph']
    lines = [
        'grasp-bench-ros: median, p99',
        _row('baseline ping-pong round trip (2 processes)', baseline),
        f"graph: {graph['ticks']} ticks, "
        f"{graph['ticks_per_wall_second'] or float('nan'):.0f} ticks per wall second "
        f"(filter {'on' if graph['enabled'] else 'off'}"
        + ''.join(f', {o}' for o in graph.get('overrides', []))
        + ')',
        _row('tick period (state to state)', graph['tick_period_ms']),
        _row('state -> command (whole graph)', graph['state_to_command_ms']),
        _row('filter latency (u_nom in -> u* out)', graph['filter_latency_ms']),
        _row("filter node's own tick (tick_time_us)", graph['filter_tick_ms']),
        '  CPU per tick: '
        + ', '.join(f'{name} {ms:.3f} ms' for name, ms in graph['cpu_ms_per_tick'].items()),
    ]
    if baseline['median'] and graph['tick_period_ms']['median']:
        ratio = graph['tick_period_ms']['median'] / baseline['median']
        results['period_over_round_trip'] = ratio
        lines.append(
            f'goal: tick period <= {GOAL_PERIOD_RATIO:g} x round trip: {ratio:.2f} x '
            f"({'met' if ratio <= GOAL_PERIOD_RATIO else 'not met'})"
        )
    latency_p99 = graph['filter_latency_ms']['p99']
    if latency_p99 is not None:
        met = latency_p99 <= GOAL_FILTER_LATENCY_P99_MS
        lines.append(
            f'goal: filter latency p99 <= {GOAL_FILTER_LATENCY_P99_MS:g} ms: '
            f"{latency_p99:.3f} ms ({'met' if met else 'not met'})"
        )
    return '\n'.join(lines)


def bench_ros_main(argv: list[str] | None = None) -> int:
    """Entry point of ``grasp-bench-ros``."""
    parser = argparse.ArgumentParser(prog='grasp-bench-ros', description=__doc__.split('\n')[0])
    parser.add_argument('--config', type=Path, default=config_path(), help='scenario file')
    parser.add_argument(
        '--duration', type=float, default=2.0, help='simulated seconds of the graph run'
    )
    parser.add_argument('--pings', type=int, default=2000, help='ping-pong round trips')
    parser.add_argument(
        '--no-filter', action='store_true', help='the graph with the filter off (enabled false)'
    )
    parser.add_argument(
        '--set',
        dest='overrides',
        action='append',
        default=[],
        metavar='NAME=VALUE',
        help='give the nodes that declare it this parameter (-p NAME:=VALUE), repeatable',
    )
    parser.add_argument('--json', type=Path, help='also write the figures to this file')
    parser.add_argument('--echo', action='store_true', help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.echo:
        echo_main()
        return 0
    from grasp_safety_filter.model.grasp_check import load_initial_grasp

    try:
        # The nodes' start-up checks, before the ping-pong: the nodes would refuse later.
        load_initial_grasp(args.config)
        for node in GRAPH_NODES:
            load_node_parameters(args.config, node)
        override_arguments(args.overrides)
    except ConfigError as error:
        print(config_error_line('grasp-bench-ros', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    os.environ.setdefault('ROS_AUTOMATIC_DISCOVERY_RANGE', 'LOCALHOST')
    results = {
        'baseline': ping_pong(args.pings),
        'graph': graph_run(
            args.config, args.duration, enabled=not args.no_filter, overrides=args.overrides
        ),
        'ros_domain_id': os.environ.get('ROS_DOMAIN_ID', '0'),
    }
    print(report(results))
    if args.json is not None:
        args.json.write_text(json.dumps(results, indent=2), encoding='utf-8')
    return 0


if __name__ == '__main__':
    sys.exit(bench_ros_main())
