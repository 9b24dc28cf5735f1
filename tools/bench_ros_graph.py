"""``grasp-bench-ros``'s graph run: the three nodes as processes over DDS, timed by a monitor.

The measurement of item 2 of :mod:`grasp_tools.bench_ros` (which runs it and prints
its figures): the scenario file the nodes are started with, the node processes, the
monitor node that notes each stamp's arrivals, and the figures drawn from them
(:func:`percentiles`, shared with the baseline's round trips).
"""

from __future__ import annotations

from collections.abc import Sequence
from functools import partial
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

from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.messages import header_stamp_ns, rclpy_message_class
from grasp_safety_filter.io.parameters import (
    load_parameter_file,
    ParameterError,
    ROS_PARAMETERS_KEY,
)
from grasp_safety_filter.io.schemas import (
    HAND_SIM_NODE,
    node_overrides,
    NOMINAL_CONTROLLER_NODE,
    override_errors,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.io.topics import (
    DIAGNOSTICS,
    EFFORT_COMMAND,
    EFFORT_NOMINAL,
    JOINT_STATES,
    TOPICS,
)

#: Node processes of the graph, in start order (the simulator last: it waits for the others).
GRAPH_NODES = (SAFETY_FILTER_NODE, NOMINAL_CONTROLLER_NODE, HAND_SIM_NODE)

#: Node name of the monitor, which the simulator waits for as for a recorder.
MONITOR_NODE = 'grasp_bench_monitor'

#: Wall-clock period of the CPU time readings of the node processes, s.
CPU_SAMPLE_PERIOD = 0.2


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


def _ignore(_: Any) -> None:
    """Take a message and drop it."""


def cpu_seconds(pid: int) -> float:
    """Return the user + system CPU time of a process so far (``/proc/<pid>/stat``), s."""
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
    """Per node, the ``-p NAME:=VALUE`` arguments of the overrides that apply to it.

    ``NAME=VALUE`` goes to every node that declares ``NAME``, ``NODE/NAME=VALUE`` to ``NODE``
    only (and beats ``NAME`` there): :func:`~grasp_safety_filter.io.schemas.node_overrides`.

    Raises:
        ParameterError: An override is not ``NAME=VALUE`` or no node of the graph takes it.
    """
    given: dict[str, str] = {}
    for override in overrides:
        name, equals, value = override.partition('=')
        errors = override_errors([name]) if equals else ['expected NAME=VALUE or NODE/NAME=VALUE']
        if not errors and not any(node_overrides({name: value}, node) for node in GRAPH_NODES):
            errors = [f'no node of the graph ({", ".join(GRAPH_NODES)}) declares it']
        if errors:
            raise ParameterError(f'--set {override!r}: {"; ".join(errors)}')
        given[name] = value
    return {
        node: [
            argument
            for name, value in node_overrides(given, node).items()
            for argument in ('-p', f'{name}:={value}')
        ]
        for node in GRAPH_NODES
    }


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
                            cpu[name] = cpu_seconds(process.pid)
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
