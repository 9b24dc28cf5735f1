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

The graph run and its monitor are in :mod:`grasp_tools.bench_ros_graph`; its public
names are importable from here as well.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Any

from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.io.topics import JOINT_STATES, topic_spec
from grasp_tools.bench_ros_graph import (
    CPU_SAMPLE_PERIOD,
    GRAPH_NODES,
    graph_run,
    MONITOR_NODE,
    override_arguments,
    percentiles,
    scenario_file,
    stop_process,
)

__all__ = [
    'CPU_SAMPLE_PERIOD',
    'GOAL_FILTER_LATENCY_P99_MS',
    'GOAL_PERIOD_RATIO',
    'GRAPH_NODES',
    'MONITOR_NODE',
    'PING_TOPIC',
    'PONG_TOPIC',
    'bench_ros_main',
    'echo_main',
    'graph_run',
    'override_arguments',
    'percentiles',
    'ping_pong',
    'report',
    'scenario_file',
    'stop_process',
]

PING_TOPIC = '/bench/ping'
PONG_TOPIC = '/bench/pong'

#: Goals of the graph's speed: tick period / baseline round trip, filter latency p99 (ms).
GOAL_PERIOD_RATIO = 3.0
GOAL_FILTER_LATENCY_P99_MS = 1.0


def _joint_state(msg_class: Any, n_joints: int = 9) -> Any:
    msg = msg_class()
    msg.name = [f'joint{i}' for i in range(n_joints)]
    msg.position = [0.1 * i for i in range(n_joints)]
    msg.velocity = [0.0] * n_joints
    msg.effort = [0.0] * n_joints
    return msg


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
        [sys.executable, '-m', 'grasp_tools.bench_ros', '--echo'],
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
        help='give the nodes that declare it this parameter (-p NAME:=VALUE), or with '
        'NODE/NAME=VALUE that node only; repeatable',
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
