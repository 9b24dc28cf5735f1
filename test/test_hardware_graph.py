"""The simulator's hardware mode as an OS process over DDS, with no controller at all.

``hand_sim_node`` runs as ``ros2 run`` starts it (:mod:`ros_graph`: its own ROS domain,
localhost discovery), ``lockstep: false``, importing this checkout. An rclpy node in the test
counts what it publishes while nothing commands it (joint states at the driver's rate, the
tracker's samples at theirs), then sends ``Float64MultiArray`` commands as ros2_control's
effort controller takes them and reads the simulator's diagnostics and joint states applying
them, then stops sending (the command timeout's ERROR), and stops the node (exit code 0).
"""

from __future__ import annotations

from collections.abc import Callable
import math
import os
from pathlib import Path
import time
from typing import Any

import numpy as np
import pytest
import rclpy
from rclpy.executors import SingleThreadedExecutor
from ros_graph import CONFIG, node_command, Processes, REPO

from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import Pose, ReferenceSample
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.launch_arguments import NodeLaunch
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.io.sim_diagnostic_keys import HardwareKey
from grasp_safety_filter.model.grasp_model import GraspModel
from hand_sim_node.config import SimConfig
from hand_sim_node.plant import RigidPlant

#: The driver's and the tracker's rates for the test, Hz.
RATE = 200.0
TRACKER_RATE = 50.0
#: The tracker's latency, s (not a whole number of driver periods).
LATENCY = 0.012
#: The window the rates are measured over, s.
WINDOW = 2.0
#: Wall-clock limit of the node's start (imports, model, kernels) on a loaded machine, s.
START_TIMEOUT = 30.0

OVERRIDES = {
    'lockstep': False,
    'duration': 60.0,
    'hardware.rate': RATE,
    'hardware.command_message': 'float64_multi_array',
    'hardware.command_timeout': 0.2,
    'tracker.rate': TRACKER_RATE,
    'tracker.latency': LATENCY,
    'tracker.message': 'pose',
}


def checkout_environment() -> dict[str, str]:
    """Return this process's environment, its ROS domain, with this checkout first on the path.

    The console scripts import the package installed in the interpreter's environment (an
    editable install may point at another checkout): the node must run this one's code.
    """
    env = dict(os.environ)
    env['PYTHONPATH'] = os.pathsep.join(p for p in (str(REPO), env.get('PYTHONPATH')) if p)
    return env


def holding_torque() -> np.ndarray:
    """Return the nominal controller's torque at the initial grasp, N·m (it holds it)."""
    values = load_node_parameters(CONFIG, 'hand_sim_node')
    model = GraspModel.from_parameters(values)
    plant = RigidPlant(model, SimConfig.from_parameters(values))
    state = plant.observe()
    reference = ReferenceSample(Pose(state.p_object_in_palm, state.R_object_to_palm).euler)
    nominal = NominalConfig.from_parameters(
        load_node_parameters(CONFIG, 'nominal_controller_node')
    )
    return NominalController(nominal).compute(plant.grasp_state(), reference).u


class Probe:
    """An rclpy node of its own context: subscriptions that log (arrival s, message)."""

    def __init__(self) -> None:
        #: Per topic: the system clock's time of each arrival, ns.
        self.arrivals_ns: dict[str, list[int]] = {}
        self.context = rclpy.Context()
        rclpy.init(args=[], context=self.context)
        self.node = rclpy.create_node('hardware_probe', context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.received: dict[str, list[tuple[float, Any]]] = {}

    def subscribe(self, topic: str) -> None:
        spec = topics.topic_spec(topic)
        log = self.received.setdefault(topic, [])
        arrivals = self.arrivals_ns.setdefault(topic, [])

        def receive(msg: Any) -> None:
            log.append((time.monotonic(), msg))
            arrivals.append(time.time_ns())

        self.node.create_subscription(
            m.rclpy_message_class(spec.msgtype), topic, receive, spec.qos.to_rclpy()
        )

    def spin_until(self, condition: Callable[[], bool], timeout: float) -> bool:
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.01)
            if condition():
                return True
        return False

    def spin_for(self, seconds: float) -> None:
        deadline = time.monotonic() + seconds
        while time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.05)

    def statuses(self, since: float = 0.0) -> list[tuple[int, m.DiagnosticReport]]:
        """Return the ``hand_sim`` statuses that arrived from ``since`` on, with their stamps."""
        return [
            (m.header_stamp_ns(msg), report)
            for arrival, msg in self.received.get(topics.DIAGNOSTICS, [])
            if arrival >= since
            for report in m.diagnostics_from_msg(msg).reports
            if report.name == 'hand_sim'
        ]

    def close(self) -> None:
        self.executor.shutdown()
        self.node.destroy_node()
        rclpy.try_shutdown(context=self.context)


def stamps_in(received: list[tuple[float, Any]], start_ns: int, seconds: float) -> list[int]:
    """Header stamps, ns, of the messages published in ``[start_ns, start_ns + seconds)``."""
    end_ns = start_ns + round(seconds * 1e9)
    return [s for _, msg in received if start_ns <= (s := m.header_stamp_ns(msg)) < end_ns]


def test_hardware_mode_runs_without_a_controller_and_applies_commands(tmp_path: Path) -> None:
    hold = holding_torque()
    env = checkout_environment()
    node = NodeLaunch('hand_sim_node', 'hand_sim_node', (str(CONFIG),), OVERRIDES)
    probe = Probe()
    try:
        for topic in (topics.JOINT_STATES, topics.OBJECT_POSE, topics.DIAGNOSTICS):
            probe.subscribe(topic)
        msgs = m.MessageNamespace.from_rclpy()
        spec = topics.topic_spec(topics.EFFORT_CONTROLLER_COMMANDS)
        publisher = probe.node.create_publisher(
            msgs.Float64MultiArray, spec.name, spec.qos.to_rclpy()
        )
        with Processes(tmp_path / 'logs', env) as processes:
            processes.start('hand_sim_node', node_command(node, tmp_path))
            states = probe.received[topics.JOINT_STATES]
            started = probe.spin_until(lambda: len(states) >= 20, START_TIMEOUT)
            assert started, processes.logs()

            # No controller: joint states at the driver's rate, poses at the tracker's.
            probe.spin_for(WINDOW + 0.5)
            first = m.header_stamp_ns(states[0][1])
            counted = stamps_in(states, first, WINDOW)
            poses = stamps_in(probe.received[topics.OBJECT_POSE], first, WINDOW)
            assert np.all(np.diff([m.header_stamp_ns(msg) for _, msg in states]) > 0)
            # A period whose timer call came a period late or more (this machine is shared)
            # is caught up in the next call, counted late, its state not published: between
            # two regular statuses (after the probe's subscription matched), the driver's
            # accounting holds every period of its clock and every state it published.
            regulars = [
                (stamp, report)
                for stamp, report in probe.statuses()
                if HardwareKey.PERIODS in report.values and stamp > first
            ]
            assert len(regulars) >= 2, regulars
            (stamp_a, a), (stamp_b, b) = regulars[0], regulars[-1]

            def between(key: str) -> int:
                return int(b.values[key]) - int(a.values[key])

            published = [m.header_stamp_ns(msg) for _, msg in states]
            assert sum(stamp_a < s <= stamp_b for s in published) == between(HardwareKey.PERIODS)
            periods = sum(
                between(key)
                for key in (
                    HardwareKey.PERIODS,
                    HardwareKey.PERIODS_LATE,
                    HardwareKey.PERIODS_SKIPPED,
                )
            )
            assert abs(periods - (stamp_b - stamp_a) * RATE / 1e9) <= 1.0, periods
            regular = b
            late = int(regular.values[HardwareKey.PERIODS_LATE])
            # Counts at the configured rates: all of them but the late ones, if any.
            expected = RATE * WINDOW
            assert 0.75 * expected <= len(counted) <= expected + 2, (len(counted), late)
            assert abs(len(poses) - TRACKER_RATE * WINDOW) <= 0.1 * TRACKER_RATE * WINDOW
            # The state's period: 5 ms between the stamps of consecutive periods.
            spacing = np.median(np.diff(counted)) / 1e9
            assert spacing == pytest.approx(1.0 / RATE, abs=0.1 / RATE), spacing
            # Each pose published tracker.latency after its capture (its stamp), at the first
            # driver period at or after it; the median arrival adds DDS and scheduling.
            pose_msgs = probe.received[topics.OBJECT_POSE]
            delays_ns = np.array(probe.arrivals_ns[topics.OBJECT_POSE]) - [
                m.header_stamp_ns(msg) for _, msg in pose_msgs
            ]
            delay = float(np.median(delays_ns)) / 1e9
            released = math.ceil(LATENCY * RATE) / RATE  # 15 ms: the third period after
            assert LATENCY <= delay < released + 0.005, delay
            # Stamped with the system clock (ROS time without use_sim_time), integer ns.
            assert abs(m.header_stamp_ns(states[-1][1]) - time.time_ns()) < 0.5e9
            frozen = [m.joint_state_from_msg(msg, list(states[0][1].name)) for _, msg in states]
            assert all(np.array_equal(s.position, frozen[0].position) for s in frozen)
            assert all(np.all(s.effort == 0.0) for s in frozen)

            # A controller's commands at the driver's rate: applied from the next period on.
            command = m.effort_array_to_msg(msgs, np.arange(len(hold)), hold)
            sent_at = time.monotonic()
            sender = probe.node.create_timer(1.0 / RATE, lambda: publisher.publish(command))
            probe.spin_for(1.5)
            names = list(states[0][1].name)
            applied = [
                m.joint_state_from_msg(msg, names).effort
                for arrival, msg in states
                if arrival > sent_at + 0.2
            ]
            assert applied and all(np.array_equal(effort, hold) for effort in applied)
            statuses = [report for _, report in probe.statuses(since=sent_at)]
            assert any('released' in s.message for s in statuses), statuses
            running = [s for s in statuses if HardwareKey.COMMAND_AGE in s.values]
            # OK, or WARN if the shared machine made periods late: not timed out.
            assert running and running[-1].level != m.DiagnosticLevel.ERROR
            assert running[-1].values[HardwareKey.COMMAND_TIMED_OUT] == 'false'
            assert int(running[-1].values[HardwareKey.COMMANDS_RECEIVED]) > 0.2 * RATE
            assert running[-1].values[HardwareKey.RELEASED] == 'true'

            # The commands stop: the driver's timeout is an ERROR on /diagnostics.
            sender.cancel()
            stopped_at = time.monotonic()
            timed_out = probe.spin_until(
                lambda: any(
                    s.level == m.DiagnosticLevel.ERROR and 'no valid command' in s.message
                    for _, s in probe.statuses(since=stopped_at)
                ),
                3.0,
            )
            assert timed_out, processes.logs()
            assert processes.stop('hand_sim_node') == 0, processes.logs()
            print(
                f'joint states {len(counted)} in {WINDOW} s ({len(counted) / WINDOW:.1f} Hz), '
                f'tracker {len(poses)} ({len(poses) / WINDOW:.1f} Hz, median delay '
                f'{delay * 1e3:.2f} ms, median state period {spacing * 1e3:.3f} ms); driver '
                f'periods {periods}, late {late}'
            )
    finally:
        probe.close()


def test_hardware_mode_refuses_simulation_time(tmp_path: Path) -> None:
    env = checkout_environment()
    overrides = {**OVERRIDES, 'use_sim_time': True}
    node = NodeLaunch('hand_sim_node', 'hand_sim_node', (str(CONFIG),), overrides)
    with Processes(tmp_path / 'logs', env) as processes:
        processes.start('hand_sim_node', node_command(node, tmp_path))
        assert processes.wait('hand_sim_node', START_TIMEOUT) == 2
        lines = processes.started['hand_sim_node'].text().strip().splitlines()
    assert lines[-1].startswith("hand_sim_node: parameter 'use_sim_time': the hardware mode")
    assert not any('Traceback' in line for line in lines)
