"""``grasp-bench-realtime``'s relay and monitor processes (bare rclpy, no package node).

``python -m grasp_tools.bench.real_time_nodes relay``: subscribes to
``/hand/joint_states`` as the safety filter does with ``input.sync: latest`` (best effort,
the table's depth) and publishes each message unchanged on :data:`RELAY_TOPIC` (the table's
joint-state QoS, as the filter's command): one bare Python hop, the baseline of the filter's
latency. It spins in the executor the package's nodes spin in.

``python -m grasp_tools.bench.real_time_nodes monitor --out OUT``: subscribes to
``/hand/effort_command``, :data:`RELAY_TOPIC` and ``/diagnostics`` (and ``/hand/joint_states``
with ``--states``, when no driver of ours records them) and notes each message's header
stamp and ``time.time_ns()`` at its receipt; of ``/diagnostics`` the ``safety_filter``
statuses (status, watchdog, tick time) and the simulator's last ``hand_sim`` values. With
``--ready PATH`` it writes PATH once every ``--wait-for TOPIC`` has a publisher and every
``--wait-for TOPIC=N`` has N subscribers (its own among them). On SIGINT or SIGTERM it
writes what it noted to OUT (JSON) and exits.
"""

from __future__ import annotations

import argparse
import json
import os
from pathlib import Path
import sys
import time
from typing import Any

from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.sim_diagnostic_keys import SIM_DIAGNOSTIC, SimKey
from grasp_safety_filter.io.topics import DIAGNOSTICS, EFFORT_COMMAND, JOINT_STATES, topic_spec

#: The relay's topic.
RELAY_TOPIC = '/bench/relay'

#: How often the processes look for a termination request, s.
POLL_PERIOD = 0.1


def _start(name: str) -> tuple[Any, Any, Any]:
    """Initialise rclpy without its signal handlers; return the node, executor, termination."""
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    from grasp_safety_filter.io.interrupts import record_termination_requests
    from grasp_safety_filter.nodes.spin_node import make_executor

    termination = record_termination_requests()
    rclpy.init(args=[], signal_handler_options=SignalHandlerOptions.NO)
    node = rclpy.create_node(name)
    executor = make_executor(rclpy.get_default_context())
    executor.add_node(node)
    return node, executor, termination


def _spin(node: Any, executor: Any, termination: Any, each: Any = None) -> None:
    """Spin until SIGINT or SIGTERM; call ``each()`` between spins; shut down."""
    import rclpy

    try:
        while not termination.requested and rclpy.ok():
            executor.spin_once(timeout_sec=POLL_PERIOD)
            if each is not None:
                each()
    finally:
        executor.shutdown()
        node.destroy_node()
        rclpy.try_shutdown()


def _joint_state_qos(best_effort: bool = False) -> Any:
    qos = topic_spec(JOINT_STATES).qos.to_rclpy()
    if best_effort:
        from rclpy.qos import ReliabilityPolicy

        qos.reliability = ReliabilityPolicy.BEST_EFFORT
    return qos


def relay_main() -> int:
    """Republish every joint state unchanged on :data:`RELAY_TOPIC` until SIGINT/SIGTERM."""
    from sensor_msgs.msg import JointState

    node, executor, termination = _start('bench_relay')
    publisher = node.create_publisher(JointState, RELAY_TOPIC, _joint_state_qos())
    node.create_subscription(
        JointState, JOINT_STATES, publisher.publish, _joint_state_qos(best_effort=True)
    )
    _spin(node, executor, termination)
    return 0


class Monitor:
    """What the monitor notes: ``(stamp ns, receipt ns)`` per topic, statuses, the simulator's.

    Attributes:
        received: Per topic, ``[stamp, receipt]`` of each message, ns.
        statuses: ``[stamp, status, watchdog, tick_time_us or None]`` of each
            ``safety_filter`` status.
        sim_values: The values of the last ``hand_sim`` status.
        sim_final: The values of the last ``hand_sim`` status with ``run.stop_reason``.
    """

    def __init__(self, topics: list[str]) -> None:
        self.received: dict[str, list[list[int]]] = {topic: [] for topic in topics}
        self.statuses: list[list[Any]] = []
        self.sim_values: dict[str, str] = {}
        self.sim_final: dict[str, str] = {}

    def note(self, topic: str) -> Any:
        """Return the callback noting ``topic``'s messages."""
        clock = time.time_ns
        append = self.received[topic].append

        def callback(msg: Any) -> None:
            receipt = clock()
            stamp = msg.header.stamp
            append([stamp.sec * 1_000_000_000 + stamp.nanosec, receipt])

        return callback

    def on_diagnostics(self, msg: Any) -> None:
        """Note the filter's statuses and the simulator's values."""
        stamp = msg.header.stamp.sec * 1_000_000_000 + msg.header.stamp.nanosec
        for status in msg.status:
            if status.name == FILTER_DIAGNOSTIC:
                values = {pair.key: pair.value for pair in status.values}
                tick = values.get(Key.TICK_TIME_US)
                try:
                    tick_us = None if tick is None else float(tick)
                except ValueError:
                    tick_us = None
                watchdog = values.get(Key.INPUT_WATCHDOG, 'false') == 'true'
                self.statuses.append([stamp, values.get(Key.STATUS, ''), watchdog, tick_us])
            elif status.name == SIM_DIAGNOSTIC:
                self.sim_values = {pair.key: pair.value for pair in status.values}
                if SimKey.RUN_STOP_REASON in self.sim_values:
                    self.sim_final = self.sim_values

    def to_json(self) -> dict[str, Any]:
        """Return the notes as a JSON object."""
        return {
            'received': self.received,
            'statuses': self.statuses,
            'sim_values': self.sim_values,
            'sim_final': self.sim_final,
        }


def monitor_main(out: Path, states: bool, ready: Path | None, wait_for: list[str]) -> int:
    """Note what arrives (module docstring) until SIGINT/SIGTERM; write it to ``out``."""
    from diagnostic_msgs.msg import DiagnosticArray
    from sensor_msgs.msg import JointState

    node, executor, termination = _start('bench_monitor')
    topics = [EFFORT_COMMAND, RELAY_TOPIC] + ([JOINT_STATES] if states else [])
    monitor = Monitor(topics)
    for topic in topics:
        node.create_subscription(JointState, topic, monitor.note(topic), _joint_state_qos())
    diagnostics = topic_spec(DIAGNOSTICS)
    node.create_subscription(
        DiagnosticArray, DIAGNOSTICS, monitor.on_diagnostics, diagnostics.qos.to_rclpy()
    )
    signalled = {'ready': ready is None}

    def connected(condition: str) -> bool:
        topic, _, subscribers = condition.partition('=')
        if subscribers:
            return node.count_subscribers(topic) >= int(subscribers)
        return node.count_publishers(topic) >= 1

    def signal_ready() -> None:
        if signalled['ready'] or not all(connected(c) for c in wait_for):
            return
        assert ready is not None
        partial = ready.with_suffix('.part')
        partial.write_text(str(os.getpid()), encoding='utf-8')
        partial.replace(ready)
        signalled['ready'] = True

    try:
        _spin(node, executor, termination, signal_ready)
    finally:
        out.write_text(json.dumps(monitor.to_json()), encoding='utf-8')
    return 0


def main(argv: list[str] | None = None) -> int:
    """Run the relay or the monitor (module docstring)."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    commands = parser.add_subparsers(dest='command', required=True)
    commands.add_parser('relay', help=f'republish {JOINT_STATES} on {RELAY_TOPIC}')
    monitor = commands.add_parser('monitor', help='note stamps and receipts')
    monitor.add_argument('--out', type=Path, required=True, help='notes (JSON)')
    monitor.add_argument('--states', action='store_true', help=f'note {JOINT_STATES} too')
    monitor.add_argument('--ready', type=Path, help='written once every --wait-for is up')
    monitor.add_argument('--wait-for', action='append', default=[], metavar='TOPIC[=SUBSCRIBERS]')
    args = parser.parse_args(argv)
    if args.command == 'relay':
        return relay_main()
    return monitor_main(args.out, args.states, args.ready, args.wait_for)


if __name__ == '__main__':
    sys.exit(main())
