"""The ROS-free lockstep runner: the three nodes' endpoints wired in-process, recorded to a bag.

Every message the endpoints exchange goes through CDR exactly as through the middleware,
is written to a rosbag2 bag with the topic names, types and QoS the ROS graph records, and
is delivered, deserialised, to its subscribers in publication order. The simulator's
lockstep makes this the same stream a ``ros2 launch`` run of the paper demo records.

Results (figures and ``summary.json``) are then produced from the bag alone, by the same
analysis ``grasp-analyze`` runs on any recording.

A run's options and results are in :mod:`~grasp_safety_filter.run_types`, what it may write
into an output directory in :mod:`~grasp_safety_filter.output_dir`; their public names are
importable from here as well.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Sequence
import json
from pathlib import Path
import shutil
import time
from typing import Any

from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.analysis.figures import plot_run
from grasp_safety_filter.analysis.run_data import load_run, RunDataError
from grasp_safety_filter.analysis.summary import summarize
from grasp_safety_filter.control.hold_policy import InputPolicyConfig
from grasp_safety_filter.control.nominal_config import NominalConfig
from grasp_safety_filter.control.safety_filter import SafetyFilterConfig
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import BagRecorder
from grasp_safety_filter.io.files import write_file
from grasp_safety_filter.io.interrupts import (
    deferred_interrupts,
    interrupt_on_signals,
    signal_name,
)
from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.schemas import (
    HAND_SIM_NODE,
    load_node_parameters,
    node_overrides,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.model.fingers import Finger, fingers_from_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.grasp_watch import GraspCheckConfig
from grasp_safety_filter.nodes.nominal_controller import NominalControllerEndpoint
from grasp_safety_filter.nodes.publication_rate import PublicationRateConfig
from grasp_safety_filter.nodes.safety_filter import SafetyFilterEndpoint
from grasp_safety_filter.nodes.shared_parse import SharedParse
from grasp_safety_filter.output_dir import (
    ANALYSIS_DIRECTORY,
    BAG_DIRECTORY,
    BAG_FILE_SUFFIXES,
    check_output_dir,
    OUTPUT_NAMES,
    OUTPUT_SUBDIRECTORIES,
    SUMMARY_FILE,
    VERDICT_FILE,
)
from grasp_safety_filter.run_types import MODES, Recording, RunOptions, RunResult
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint
from hand_sim_node.plant import PlantConfig

__all__ = [
    'ANALYSIS_DIRECTORY',
    'BAG_DIRECTORY',
    'BAG_FILE_SUFFIXES',
    'MODES',
    'OUTPUT_NAMES',
    'OUTPUT_SUBDIRECTORIES',
    'SUMMARY_FILE',
    'VERDICT_FILE',
    'Callback',
    'Progress',
    'Recording',
    'RunInterrupted',
    'RunOptions',
    'RunResult',
    'analyze_bag',
    'build_endpoints',
    'check_output_dir',
    'record_run',
    'run',
    'scenario_hand',
]


def _remove(path: Path) -> None:
    """Remove a previous bag; a symbolic link itself, never what it points to."""
    if path.is_symlink() or path.is_file():
        path.unlink()
    elif path.exists():
        shutil.rmtree(path)


Progress = Callable[[float, float], None]
"""Called with (simulated time, duration) as the run advances."""


Callback = Callable[[Any], list[Any]]
"""A subscriber callback: a delivered message in, the messages it publishes out."""


def _subscribers(
    sim: HandSimEndpoint,
    nominal: NominalControllerEndpoint,
    safety_filter: SafetyFilterEndpoint,
    wrap_filter_callback: Callable[[Callback], Callback] | None = None,
) -> dict[str, list[Callback]]:
    """Return each topic's subscriber callbacks, wired as the ROS graph wires the nodes.

    ``wrap_filter_callback``: see :func:`record_run`.
    """
    wrap = wrap_filter_callback or (lambda callback: callback)
    return {
        topics.JOINT_STATES: [nominal.on_joint_states, wrap(safety_filter.on_joint_states)],
        topics.OBJECT_ODOM: [nominal.on_odom, wrap(safety_filter.on_odom)],
        topics.OBJECT_REFERENCE: [nominal.on_reference],
        topics.EFFORT_NOMINAL: [wrap(safety_filter.on_effort_nominal)],
        topics.EFFORT_COMMAND: [sim.on_command],
    }


def build_endpoints(
    options: RunOptions, msgs: MessageNamespace, parse: SharedParse | None = None
) -> tuple[HandSimEndpoint, NominalControllerEndpoint, SafetyFilterEndpoint]:
    """Build the three nodes' endpoints, each with its own model, as the launch file does.

    ``parse``: shared by the nominal controller and the safety filter (a runner that hands
    both the same message objects, unchanged: :mod:`~grasp_safety_filter.nodes.shared_parse`);
    None: each parses its inputs itself, as in a ROS graph.
    """
    params = {
        node: load_node_parameters(
            options.config, node, overrides=node_overrides(options.overrides, node)
        )
        for node in (HAND_SIM_NODE, NOMINAL_CONTROLLER_NODE, SAFETY_FILTER_NODE)
    }
    overrides = {
        name: value
        for name, value in (
            ('duration', options.duration),
            ('time_step', options.time_step),
            ('integrator', options.integrator),
        )
        if value is not None
    }
    # The runner is the lockstep graph: a file's hardware mode (lockstep false) runs in
    # lockstep here, and its scenario says so. One SimConfig of the values in force: its
    # checks across them (command_delay against time_step, lockstep) see the run's.
    sim_config = SimConfig.from_parameters(
        {**params[HAND_SIM_NODE], 'lockstep': True, **overrides}
    )
    sim = HandSimEndpoint(
        GraspModel.from_parameters(params[HAND_SIM_NODE]),
        sim_config,
        msgs,
        plant_config=PlantConfig.from_parameters(params[HAND_SIM_NODE]),
    )
    nominal_params = params[NOMINAL_CONTROLLER_NODE]
    nominal = NominalControllerEndpoint(
        GraspModel.from_parameters(nominal_params),
        NominalConfig.from_parameters(nominal_params),
        msgs,
        GraspCheckConfig.from_parameters(nominal_params),
        parse=parse,
    )
    filter_params = params[SAFETY_FILTER_NODE]
    safety_filter = SafetyFilterEndpoint(
        GraspModel.from_parameters(filter_params),
        SafetyFilterConfig.from_parameters(filter_params),
        InputPolicyConfig.from_parameters(filter_params),
        msgs,
        enabled=options.mode == 'filtered',
        publication_rate_config=PublicationRateConfig.from_parameters(filter_params),
        grasp_check_config=GraspCheckConfig.from_parameters(filter_params),
        parse=parse,
    )
    return sim, nominal, safety_filter


def scenario_hand(options: RunOptions) -> tuple[list[Finger], GraspModel]:
    """Return the scenario hand's joints by finger and its model."""
    overrides = node_overrides(options.overrides, HAND_SIM_NODE)
    params = load_node_parameters(options.config, HAND_SIM_NODE, overrides=overrides)
    return fingers_from_parameters(params), GraspModel.from_parameters(params)


def record_run(
    options: RunOptions,
    bag_path: Path,
    progress: Progress | None = None,
    replaces: tuple[Path, ...] = (),
    on_start: Callable[[], None] | None = None,
    wrap_filter_callback: Callable[[Callback], Callback] | None = None,
) -> Recording:
    """Run the scenario in lockstep and record every message to ``bag_path`` (replaced).

    The bag is closed and readable however the run ends; an interrupted one has
    ``interrupted`` in its custom data, and a further signal while it is being closed is
    ignored. An exception other than an interrupt propagates after the bag is closed.

    Args:
        options: What to run.
        bag_path: The bag directory.
        progress: Called as the run advances.
        replaces: Files removed with the earlier bag (both or neither: an outcome of the
            earlier run never stays beside this run's bag).
        on_start: Called once the earlier bag and ``replaces`` are gone.
        wrap_filter_callback: Called once with each of the safety filter's subscriber
            callbacks; the loop calls what it returns instead, which must hand the message
            to the callback and return its messages unchanged (e.g. ``grasp-bench``'s, which
            times it). None: the callbacks.

    """
    typestore = get_typestore(Stores.ROS2_JAZZY)
    msgs = MessageNamespace.from_typestore(typestore)
    # Bad parameters fail here, before an earlier bag is replaced.
    # _record hands each message to its subscribers unchanged: they may share its parse.
    sim, nominal, safety_filter = build_endpoints(options, msgs, SharedParse())
    with interrupt_on_signals():
        with deferred_interrupts():
            for path in (*replaces, bag_path):
                _remove(path)
        if on_start is not None:
            on_start()
        with BagRecorder(bag_path, storage=options.storage, typestore=typestore) as bag:
            return _record(
                sim, nominal, safety_filter, bag, typestore, progress, wrap_filter_callback
            )


def _record(
    sim: HandSimEndpoint,
    nominal: NominalControllerEndpoint,
    safety_filter: SafetyFilterEndpoint,
    bag: BagRecorder,
    typestore: Any,
    progress: Progress | None,
    wrap_filter_callback: Callable[[Callback], Callback] | None = None,
) -> Recording:
    """Run the lockstep loop into an open bag (see :func:`record_run`)."""
    subscribers = _subscribers(sim, nominal, safety_filter, wrap_filter_callback)
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
        with deferred_interrupts(raise_pending=False):  # already stopping
            bag.set_custom_data('interrupted', interrupted)
            bag.close(raise_pending_interrupt=False)
    except Exception as error:
        bag.set_custom_data('interrupted', type(error).__name__)
        raise
    return Recording(interrupted, sim.plant.log, sim.stop_reason, sim.t)


def _write_summary(out_dir: Path, summary: dict[str, Any]) -> None:
    write_file(out_dir / SUMMARY_FILE, json.dumps(summary, indent=2) + '\n')


def analyze_bag(
    bag_path: Path,
    out_dir: Path,
    force: bool = False,
    fingers: Sequence[Finger] | None = None,
    model: GraspModel | None = None,
    animate: bool = False,
) -> tuple[dict[str, Any], list[Path]]:
    """Figures and ``summary.json`` of a recorded run, into ``out_dir``.

    ``fingers``, ``model``: the run's hand's joints by finger and its model, for the figures
    (None: not known; without the model the grasp is not drawn in space); ``animate``: also
    ``animation.gif``.

    Raises:
        RunDataError: The bag cannot be analysed.
        OutputError: ``out_dir`` is not ours to write into (see :func:`check_output_dir`).

    """
    out_dir = Path(out_dir)
    check_output_dir(out_dir, force, inputs=(Path(bag_path),))
    run = load_run(bag_path)
    summary = summarize(run)
    out_dir.mkdir(parents=True, exist_ok=True)
    _write_summary(out_dir, summary)
    return summary, plot_run(run, out_dir, fingers, model, animate)


class RunInterrupted(KeyboardInterrupt):
    """A run stopped by a signal, with what of it is on disk.

    Attributes:
        signal: ``"SIGINT"`` or ``"SIGTERM"``.
        bag: This run's closed, readable bag, or None (interrupted before recording).
        summary: This run's ``summary.json``, or None (interrupted before it was written).

    """

    def __init__(self, signal: str, bag: Path | None, summary: Path | None) -> None:
        super().__init__(f'interrupted by {signal}')
        self.signal, self.bag, self.summary = signal, bag, summary


def run(
    options: RunOptions, out_dir: Path, progress: Progress | None = None, force: bool = False
) -> RunResult:
    """Run, record and analyse one scenario run into ``out_dir`` (its bag is replaced).

    Signals (SIGINT, SIGTERM) stop the run, not the bookkeeping: the bag is closed and the
    summary written however many arrive; one during the analysis waits for the summary.

    Raises:
        OutputError: ``out_dir`` is not ours to write into (see :func:`check_output_dir`).
        RunInterrupted: A signal stopped it; says which of its bag and summary exist.
    """
    out_dir = Path(out_dir)
    check_output_dir(out_dir, force)
    fingers, model = scenario_hand(options)
    out_dir.mkdir(parents=True, exist_ok=True)
    bag_path, summary_path = out_dir / BAG_DIRECTORY, out_dir / SUMMARY_FILE
    started, written = [False], [False]
    with interrupt_on_signals():
        try:
            start = time.perf_counter()
            recording = record_run(
                options, bag_path, progress, (summary_path,), lambda: started.__setitem__(0, True)
            )
            wall_time = time.perf_counter() - start
            with deferred_interrupts():
                try:
                    run_data = load_run(bag_path)
                except RunDataError:
                    if recording.interrupted is None:
                        raise
                    # Stopped before a first step: a bag with too little for a summary.
                    raise _interrupted(recording.interrupted, True, False, out_dir) from None
                summary = summarize(run_data)
                if recording.interrupted is not None:
                    summary['interrupted'] = recording.interrupted
                _write_summary(out_dir, summary)
                written[0] = True
            figures = plot_run(run_data, out_dir, fingers, model, options.animate)
        except RunInterrupted:
            raise  # stopped before a first step: it names its own signal
        except KeyboardInterrupt as interrupt:
            raise _interrupted(signal_name(interrupt), started[0], written[0], out_dir) from None
    if recording.interrupted is not None:
        raise _interrupted(recording.interrupted, True, True, out_dir)
    return RunResult(out_dir, bag_path, summary, figures, wall_time, recording)


def _interrupted(signal: str, started: bool, written: bool, out_dir: Path) -> RunInterrupted:
    bag = out_dir / BAG_DIRECTORY
    readable = started and (bag / 'metadata.yaml').is_file()
    return RunInterrupted(
        signal, bag if readable else None, out_dir / SUMMARY_FILE if written else None
    )
