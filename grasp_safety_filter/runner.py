"""The ROS-free lockstep runner: the three nodes' endpoints wired in-process, recorded to a bag.

Every message the endpoints exchange goes through CDR exactly as through the middleware,
is written to a rosbag2 bag with the topic names, types and QoS the ROS graph records, and
is delivered, deserialised, to its subscribers in publication order. The simulator's
lockstep makes this the same stream a ``ros2 launch`` run of the paper demo records.

Results (figures and ``summary.json``) are then produced from the bag alone, by the same
analysis ``grasp-analyze`` runs on any recording.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping
import dataclasses
from dataclasses import dataclass, field
import json
from pathlib import Path
import shutil
import time
from typing import Any

from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.analysis.figures import plot_run
from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.analysis.summary import summarize
from grasp_safety_filter.control.hold_policy import InputPolicyConfig
from grasp_safety_filter.control.nominal import NominalConfig
from grasp_safety_filter.control.safety_filter import SafetyFilterConfig
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import BagRecorder, interrupt_on_signals, signal_name
from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.parameters import ParameterError, suggestion
from grasp_safety_filter.io.schemas import (
    HAND_SIM_NODE,
    load_node_parameters,
    NODE_SCHEMAS,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.nominal_controller import NominalControllerEndpoint
from grasp_safety_filter.nodes.publication_rate import PublicationRateConfig
from grasp_safety_filter.nodes.safety_filter import SafetyFilterEndpoint
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint
from hand_sim_node.events import EventLog

MODES = ('nominal', 'filtered')
BAG_DIRECTORY = 'bag'
SUMMARY_FILE = 'summary.json'


@dataclass(frozen=True)
class RunOptions:
    """What to run.

    Attributes:
        config: Scenario parameter file (ROS 2 format).
        mode: ``"nominal"`` (filter off: u* = u_nom) or ``"filtered"``.
        duration: Overrides the scenario's ``duration`` (s), if given.
        time_step: Overrides ``time_step`` (s), if given.
        integrator: Overrides ``integrator`` (``"ode3"`` or ``"rk4"``), if given.
        storage: Bag storage, ``"mcap"`` (default, as ``ros2 bag record``) or ``"sqlite3"``.
        overrides: ``{dotted name: value}`` replacing the scenario file's parameters, for
            every node that declares the name (e.g. ``{"barrier.alpha1.gain": 10.0}``).
    """

    config: Path
    mode: str = 'filtered'
    duration: float | None = None
    time_step: float | None = None
    integrator: str | None = None
    storage: str = 'mcap'
    overrides: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.mode not in MODES:
            raise ValueError(f'mode: expected one of {list(MODES)}, got {self.mode!r}')
        for name in self.overrides:
            if not any(schema.get(name) for schema in NODE_SCHEMAS.values()):
                known = sorted({n for schema in NODE_SCHEMAS.values() for n in schema.names})
                hint = suggestion(name, known)
                raise ParameterError(f"override '{name}': no node declares it{hint}")


@dataclass(frozen=True)
class Recording:
    """What the live run itself observed, to compare with what its bag says.

    Attributes:
        interrupted: None when the simulator finished (ran to its duration or stopped on a
            violation), else the signal that interrupted it (``"SIGINT"`` or ``"SIGTERM"``;
            a run ended by another exception raises it instead).
        live_log: The simulator's own constraint record of the run.
        stop_reason: The simulator's stop reason (``"duration"`` when it ran to the end).
        t_end: Simulated time reached, s.
    """

    interrupted: str | None
    live_log: EventLog
    stop_reason: str | None
    t_end: float


@dataclass(frozen=True)
class RunResult:
    """Where a run's results are and what they say."""

    out_dir: Path
    bag: Path
    summary: dict[str, Any]
    figures: list[Path]
    wall_time: float
    recording: Recording


Progress = Callable[[float, float], None]
"""Called with (simulated time, duration) as the run advances."""


def _subscribers(
    sim: HandSimEndpoint,
    nominal: NominalControllerEndpoint,
    safety_filter: SafetyFilterEndpoint,
) -> dict[str, list[Callable[[Any], list[Any]]]]:
    """Return each topic's subscriber callbacks, wired as the ROS graph wires the nodes."""
    return {
        topics.JOINT_STATES: [nominal.on_joint_states, safety_filter.on_joint_states],
        topics.OBJECT_ODOM: [nominal.on_odom, safety_filter.on_odom],
        topics.OBJECT_REFERENCE: [nominal.on_reference],
        topics.EFFORT_NOMINAL: [safety_filter.on_effort_nominal],
        topics.EFFORT_COMMAND: [sim.on_command],
    }


def build_endpoints(
    options: RunOptions, msgs: MessageNamespace
) -> tuple[HandSimEndpoint, NominalControllerEndpoint, SafetyFilterEndpoint]:
    """Build the three nodes' endpoints, each with its own model, as the launch file does."""
    params = {
        node: load_node_parameters(
            options.config,
            node,
            overrides={k: v for k, v in options.overrides.items() if NODE_SCHEMAS[node].get(k)},
        )
        for node in (HAND_SIM_NODE, NOMINAL_CONTROLLER_NODE, SAFETY_FILTER_NODE)
    }
    sim_config = SimConfig.from_parameters(params[HAND_SIM_NODE])
    overrides = {
        name: value
        for name, value in (
            ('duration', options.duration),
            ('time_step', options.time_step),
            ('integrator', options.integrator),
        )
        if value is not None
    }
    sim_config = dataclasses.replace(sim_config, **overrides)
    sim = HandSimEndpoint(GraspModel.from_parameters(params[HAND_SIM_NODE]), sim_config, msgs)
    nominal_params = params[NOMINAL_CONTROLLER_NODE]
    nominal = NominalControllerEndpoint(
        GraspModel.from_parameters(nominal_params),
        NominalConfig.from_parameters(nominal_params),
        msgs,
    )
    filter_params = params[SAFETY_FILTER_NODE]
    safety_filter = SafetyFilterEndpoint(
        GraspModel.from_parameters(filter_params),
        SafetyFilterConfig.from_parameters(filter_params),
        InputPolicyConfig.from_parameters(filter_params),
        msgs,
        enabled=options.mode == 'filtered',
        publication_rate_config=PublicationRateConfig.from_parameters(filter_params),
    )
    return sim, nominal, safety_filter


def record_run(options: RunOptions, bag_path: Path, progress: Progress | None = None) -> Recording:
    """Run the scenario in lockstep and record every message to ``bag_path`` (replaced).

    The bag is closed and readable however the run ends; an interrupted one has
    ``interrupted`` in its custom data. An exception other than an interrupt propagates
    after the bag is closed.
    """
    typestore = get_typestore(Stores.ROS2_JAZZY)
    msgs = MessageNamespace.from_typestore(typestore)
    # Bad parameters fail here, before an earlier bag is replaced.
    sim, nominal, safety_filter = build_endpoints(options, msgs)
    if bag_path.exists():
        shutil.rmtree(bag_path)
    with (
        interrupt_on_signals(),
        BagRecorder(bag_path, storage=options.storage, typestore=typestore) as bag,
    ):
        subscribers = _subscribers(sim, nominal, safety_filter)
        duration = sim.config.duration
        interrupted = None
        try:
            queue = deque(sim.start())
            while queue:
                topic, stamp_ns, msg = queue.popleft()
                data = bag.write(topic, stamp_ns, msg)
                handlers = subscribers.get(topic)
                if handlers:
                    received = typestore.deserialize_cdr(data, msg.__msgtype__)
                    for handler in handlers:
                        queue.extend(handler(received))
                if progress is not None and topic == topics.JOINT_STATES:
                    progress(sim.t, duration)
        except KeyboardInterrupt as interrupt:
            interrupted = signal_name(interrupt)
            bag.set_custom_data('interrupted', interrupted)
        except Exception as error:
            bag.set_custom_data('interrupted', type(error).__name__)
            raise
        simulator = sim.simulator
        return Recording(interrupted, simulator.log, simulator.stop_reason, simulator.t)


def analyze_bag(bag_path: Path, out_dir: Path) -> tuple[dict[str, Any], list[Path]]:
    """Figures and ``summary.json`` of a recorded run, into ``out_dir``."""
    run = load_run(bag_path)
    summary = summarize(run)
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / SUMMARY_FILE).write_text(json.dumps(summary, indent=2) + '\n')
    return summary, plot_run(run, out_dir)


def run(options: RunOptions, out_dir: Path, progress: Progress | None = None) -> RunResult:
    """Run, record and analyse one scenario run into ``out_dir`` (its bag is replaced).

    Raises:
        KeyboardInterrupt: After the bag and summary of the partial run are written, so the
            caller can exit with the usual status.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    bag_path = out_dir / BAG_DIRECTORY
    start = time.perf_counter()
    recording = record_run(options, bag_path, progress)
    wall_time = time.perf_counter() - start
    summary, figures = analyze_bag(bag_path, out_dir)
    if recording.interrupted is not None:
        summary['interrupted'] = recording.interrupted
        (out_dir / SUMMARY_FILE).write_text(json.dumps(summary, indent=2) + '\n')
        raise KeyboardInterrupt(recording.interrupted)
    return RunResult(out_dir, bag_path, summary, figures, wall_time, recording)
