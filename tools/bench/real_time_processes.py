"""``grasp-bench-realtime``'s runs: one case's processes, started, sampled, stopped, read.

Both modes start the same monitor and relay (:mod:`.real_time_nodes`) and read their records
into the same :class:`~.real_time_figures.RunRecords`:

- :func:`run_filter_case`: ``safety_filter_node`` alone, fed by the lean driver
  (:mod:`.real_time_driver`), which records the states it published;
- :func:`run_graph_case`: ``hand_sim_node`` in its hardware mode, the nominal controller and
  the filter as ``real_hand.launch.py sim:=true`` starts them; the monitor notes the states.

Every process is an OS process of its own (the nodes' console scripts, as ``ros2 run``
starts them; the helpers with ``python -m``), on a ROS domain of the run's own with
discovery on this machine only. While the driver (or the simulator) runs, each process's
CPU time is read from ``/proc`` every :data:`CPU_SAMPLE_PERIOD` s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
import dataclasses
from dataclasses import dataclass
import json
import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Any

import grasp_safety_filter
from grasp_safety_filter.io.launch_arguments import NodeLaunch, real_hand
from grasp_safety_filter.io.schemas import HAND_SIM_NODE, SAFETY_FILTER_NODE
from grasp_safety_filter.io.topics import (
    EFFORT_COMMAND,
    EFFORT_NOMINAL,
    JOINT_STATES,
    OBJECT_ODOM,
)
from grasp_tools.bench.real_time_driver import (
    driver_plan,
    ORIENTATION_NOISE,
    write_driver_input,
)
from grasp_tools.bench.real_time_figures import FilterStatusRecord, RunRecords
from grasp_tools.bench.real_time_nodes import RELAY_TOPIC
from grasp_tools.bench.real_time_recording import Recording
from grasp_tools.bench_ros_graph import cpu_seconds, stop_process

#: Wall-clock period of the CPU readings, s.
CPU_SAMPLE_PERIOD = 0.1

#: After the driver's (or simulator's) last state, how long the others get to answer it, s.
DRAIN_TIME = 0.3

#: Longest wait for the nodes to start and connect, s (a cold start compiles kernels).
CONNECT_TIMEOUT = 180.0

#: The simulator's hardware-mode options of ``--plant mujoco``.
MUJOCO_OVERRIDES = {'plant': 'mujoco', 'mujoco.cone': 'elliptic', 'mujoco.noslip_iterations': 10}


@dataclass(frozen=True)
class Case:
    """A hand's streams: the driver's rate, the tracker's rate, latency and noise.

    Attributes:
        name: Its label.
        period: The driver's period, s (a whole number of the recording's 1 ms steps).
        tracker_rate: Hz.
        latency: Capture to publication, s.
        noise: Position noise per axis, m.
        orientation_noise: Orientation noise per axis, rad.
        correction_time: The controllers' ``object_state.correction_time``, s (None: the
            parameter file's).
    """

    name: str
    period: float
    tracker_rate: float
    latency: float
    noise: float
    orientation_noise: float = ORIENTATION_NOISE
    correction_time: float | None = None

    @property
    def rate(self) -> float:
        """Return the driver's rate, Hz."""
        return 1.0 / self.period

    @property
    def period_ns(self) -> int:
        """Return the driver's period, ns."""
        return round(self.period * 1e9)

    def controller_overrides(self) -> dict[str, Any]:
        """Return the controllers' parameters this case sets."""
        if self.correction_time is None:
            return {}
        return {'object_state.correction_time': float(self.correction_time)}

    def describe(self) -> str:
        """Return the case in words."""
        tau = 'file' if self.correction_time is None else f'{self.correction_time:g} s'
        return (
            f'{self.name}: driver {self.rate:.0f} Hz (period {self.period * 1e3:g} ms), tracker '
            f'{self.tracker_rate:g} Hz, {self.latency * 1e3:g} ms late, '
            f'{self.noise * 1e3:g} mm noise, correction_time {tau}'
        )


def bench_environment(domain_id: int) -> dict[str, str]:
    """Return the processes' environment: their own ROS domain, discovery on this machine.

    ``PYTHONPATH`` starts with the directory of the runtime packages this process imported,
    so the helpers and the node processes run the same code as this process.
    """
    env = dict(os.environ)
    env['ROS_DOMAIN_ID'] = str(domain_id)
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    for name in ('ROS_LOCALHOST_ONLY', 'ROS_STATIC_PEERS', 'AMENT_PREFIX_PATH'):
        env.pop(name, None)
    env['PYTHONUNBUFFERED'] = '1'
    root = str(Path(grasp_safety_filter.__file__).resolve().parents[1])
    env['PYTHONPATH'] = os.pathsep.join(p for p in (root, env.get('PYTHONPATH')) if p)
    return env


def module_command(module: str, *arguments: Any) -> list[str]:
    """Return the command running ``grasp_tools.bench.<module>`` with ``arguments``."""
    return [sys.executable, '-m', f'grasp_tools.bench.{module}', *map(str, arguments)]


class ProcessGroup:
    """Processes of one run, logs in a directory; stopped in reverse start order on exit."""

    def __init__(self, directory: Path, env: Mapping[str, str]) -> None:
        self.directory = directory
        self.env = dict(env)
        self.started: dict[str, subprocess.Popen[bytes]] = {}

    def start(self, name: str, command: Sequence[str]) -> subprocess.Popen[bytes]:
        """Start ``command`` with stdout and stderr to ``<directory>/<name>.log``."""
        with (self.directory / f'{name}.log').open('wb') as log:
            log.write((' '.join(command) + '\n').encode())
            log.flush()
            process = subprocess.Popen(
                list(command),
                stdout=log,
                stderr=subprocess.STDOUT,
                env=self.env,
                cwd=self.directory,
                start_new_session=True,
            )
        self.started[name] = process
        return process

    def log_tail(self, name: str, characters: int = 3000) -> str:
        """Return the end of a process's log."""
        path = self.directory / f'{name}.log'
        return path.read_text(errors='replace')[-characters:] if path.exists() else ''

    def check_running(self) -> None:
        """Raise RuntimeError, with its log, if a process has exited."""
        for name, process in self.started.items():
            if process.poll() is not None:
                raise RuntimeError(
                    f'{name} exited ({process.returncode}) early:\n{self.log_tail(name)}'
                )

    def cpu_sample(self) -> tuple[int, dict[str, float]]:
        """Return ``(time.time_ns(), {process: CPU s so far})`` of the running processes."""
        cpu = {}
        for name, process in self.started.items():
            try:
                cpu[name] = cpu_seconds(process.pid)
            except (OSError, IndexError, ValueError):
                pass  # it has exited
        return time.time_ns(), cpu

    def sample_until_exit(
        self, name: str, timeout: float
    ) -> tuple[int, list[tuple[int, dict[str, float]]]]:
        """Read every process's CPU time until ``name`` exits; return its code, the readings.

        Raises:
            RuntimeError: It did not exit within ``timeout`` s, or another process exited.
        """
        process = self.started[name]
        samples = []
        deadline = time.monotonic() + timeout
        while process.poll() is None:
            if time.monotonic() > deadline:
                raise RuntimeError(f'{name} still running after {timeout} s')
            samples.append(self.cpu_sample())
            others = [n for n, p in self.started.items() if n != name and p.poll() is not None]
            if others:
                self.check_running()
            time.sleep(CPU_SAMPLE_PERIOD)
        return process.returncode, samples

    def wait_for_file(self, path: Path, timeout: float) -> None:
        """Wait for ``path`` to exist while every process runs.

        Raises:
            RuntimeError: A process exited, or ``timeout`` s passed.
        """
        deadline = time.monotonic() + timeout
        while not path.exists():
            self.check_running()
            if time.monotonic() > deadline:
                logs = '\n'.join(f'--- {n}\n{self.log_tail(n, 800)}' for n in self.started)
                raise RuntimeError(f'the processes did not connect within {timeout} s\n{logs}')
            time.sleep(0.05)

    def __enter__(self) -> ProcessGroup:
        return self

    def __exit__(self, *exc: object) -> None:
        for process in reversed(list(self.started.values())):
            stop_process(process, timeout=10.0)


def _monitor_command(directory: Path, states: bool, wait_for: Sequence[str]) -> list[str]:
    arguments: list[Any] = ['monitor', '--out', directory / 'monitor.json']
    arguments += ['--ready', directory / 'ready']
    for condition in wait_for:
        arguments += ['--wait-for', condition]
    return module_command('real_time_nodes', *arguments, *(['--states'] if states else []))


def _read_monitor(directory: Path) -> dict[str, Any]:
    return json.loads((directory / 'monitor.json').read_text(encoding='utf-8'))


def _statuses(monitor: dict[str, Any]) -> list[FilterStatusRecord]:
    return [FilterStatusRecord(int(s), str(v), bool(w), t) for s, v, w, t in monitor['statuses']]


def _pairs(monitor: dict[str, Any], topic: str) -> list[tuple[int, int]]:
    return [(int(stamp), int(receipt)) for stamp, receipt in monitor['received'][topic]]


def with_overrides(node: NodeLaunch, values: Mapping[str, Any]) -> NodeLaunch:
    """Return ``node`` with further parameter overrides."""
    return dataclasses.replace(node, overrides={**node.overrides, **values})


def filter_launch(config: Path, case: Case, object_message: str = 'odometry') -> NodeLaunch:
    """Return the safety filter as ``real_hand.launch.py`` starts it without a nominal node."""
    (node,) = real_hand(config, nominal=False, object_message=object_message)
    return with_overrides(node, case.controller_overrides())


def run_filter_case(
    case: Case,
    config: Path,
    recording: Recording,
    duration: float,
    warm_up: float,
    directory: Path,
    env: Mapping[str, str],
    object_message: str = 'odometry',
) -> RunRecords:
    """Run the filter node on the lean driver's streams for ``warm_up + duration`` s."""
    plan = driver_plan(
        recording,
        case.rate,
        warm_up + duration,
        case.tracker_rate,
        case.latency,
        case.noise,
        case.orientation_noise,
    )
    driver_input = write_driver_input(directory / 'driver.npz', recording, plan, object_message)
    bin_dir = Path(sys.executable).parent
    with ProcessGroup(directory, env) as group:
        # The filter subscribes once its kernels are loaded (a first start compiles them):
        # its publishers alone would start the driver before it can answer.
        ready = [EFFORT_COMMAND, RELAY_TOPIC, f'{EFFORT_NOMINAL}=1', f'{JOINT_STATES}=2']
        group.start('monitor', _monitor_command(directory, False, ready))
        group.start('relay', module_command('real_time_nodes', 'relay'))
        node = filter_launch(config, case, object_message)
        group.start(SAFETY_FILTER_NODE, node.command(bin_dir))
        group.wait_for_file(directory / 'ready', CONNECT_TIMEOUT)
        driver_out = directory / 'driver.json'
        driver = module_command('real_time_driver', driver_input, '--out', driver_out)
        group.start('driver', driver)
        code, samples = group.sample_until_exit('driver', CONNECT_TIMEOUT + warm_up + duration)
        if code != 0:
            raise RuntimeError(f'the driver exited {code}:\n{group.log_tail("driver")}')
        time.sleep(DRAIN_TIME)
    published = json.loads(driver_out.read_text(encoding='utf-8'))
    monitor = _read_monitor(directory)
    return RunRecords(
        period_ns=int(published['period_ns']),
        warm_up_ns=round(warm_up * 1e9),
        states=published['stamps'],
        commands=_pairs(monitor, EFFORT_COMMAND),
        relay=_pairs(monitor, RELAY_TOPIC),
        statuses=_statuses(monitor),
        driver_lateness=published['lateness_ns'],
        cpu_samples=samples,
    )


def graph_nodes(config: Path, case: Case, duration: float, plant: str) -> list[NodeLaunch]:
    """Return ``real_hand(config, simulate=True)``'s nodes with the case's overrides.

    The simulator's hardware mode gets the driver's rate, the tracker's rate, latency and
    noise, the run's ``duration`` (s) and, for ``plant == 'mujoco'``,
    :data:`MUJOCO_OVERRIDES`; the controllers get the case's own parameters.
    """
    simulator = {
        'hardware.rate': float(case.rate),
        'tracker.rate': float(case.tracker_rate),
        'tracker.latency': float(case.latency),
        'tracker.position_noise': float(case.noise),
        'tracker.orientation_noise': float(case.orientation_noise),
        'duration': float(duration),
        **(MUJOCO_OVERRIDES if plant == 'mujoco' else {}),
    }
    controllers = case.controller_overrides()
    return [
        with_overrides(node, simulator if node.name == HAND_SIM_NODE else controllers)
        for node in real_hand(config, simulate=True)
    ]


def run_graph_case(
    case: Case,
    config: Path,
    duration: float,
    warm_up: float,
    directory: Path,
    env: Mapping[str, str],
    plant: str = 'rigid',
) -> tuple[RunRecords, dict[str, Any]]:
    """Run the hardware-mode graph for ``warm_up + duration`` s.

    Returns:
        The records (the states as the monitor received them) and the simulator's outcome:
        its exit code, its last status's values and its end-of-run values.
    """
    nodes = graph_nodes(config, case, warm_up + duration, plant)
    bin_dir = Path(sys.executable).parent
    ready = [EFFORT_COMMAND, EFFORT_NOMINAL, RELAY_TOPIC, f'{JOINT_STATES}=4', f'{OBJECT_ODOM}=2']
    with ProcessGroup(directory, env) as group:
        group.start('monitor', _monitor_command(directory, True, ready))
        group.start('relay', module_command('real_time_nodes', 'relay'))
        for node in nodes:
            if node.name != HAND_SIM_NODE:
                group.start(node.name, node.command(bin_dir))
        group.wait_for_file(directory / 'ready', CONNECT_TIMEOUT)
        (simulator,) = (node for node in nodes if node.name == HAND_SIM_NODE)
        group.start(HAND_SIM_NODE, simulator.command(bin_dir))
        code, samples = group.sample_until_exit(
            HAND_SIM_NODE, CONNECT_TIMEOUT + warm_up + duration
        )
        time.sleep(DRAIN_TIME)
        log = group.log_tail(HAND_SIM_NODE) if code != 0 else ''
    monitor = _read_monitor(directory)
    states = sorted({stamp for stamp, _ in _pairs(monitor, JOINT_STATES)})
    if not states:
        raise RuntimeError(f'hand_sim_node published no state (exit code {code}):\n{log}')
    commands = _pairs(monitor, EFFORT_COMMAND)
    # The plant stands still until its first command (the release): the run starts there.
    answered = set(states).intersection(stamp for stamp, _ in commands)
    records = RunRecords(
        period_ns=case.period_ns,
        warm_up_ns=round(warm_up * 1e9),
        states=states,
        commands=commands,
        relay=_pairs(monitor, RELAY_TOPIC),
        statuses=_statuses(monitor),
        cpu_samples=samples,
        start_ns=min(answered) if answered else None,
    )
    outcome = {
        'exit_code': code,
        'final': monitor['sim_final'],
        'last_status': monitor['sim_values'],
        'log_tail': log,
    }
    return records, outcome
