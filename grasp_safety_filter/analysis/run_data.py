"""A recorded run as arrays: read from any bag with this package's topics.

Works on bags written by the ROS-free runner and by ``ros2 bag record`` alike: everything
is taken from the messages (header stamps, ``/grasp/scenario``), nothing from the runner.

A recorder that subscribed late misses the start of the run: every analysed topic whose
first message is stamped after the run's start (:data:`RUN_START`, the simulator's t_0) is
listed in :attr:`RunData.missed_start`, and the run is analysed from where its data begin
(contact samples older than the first joint state are left out).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import bag_topics, BagReadError, read_bag
from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.messages import (
    contacts_from_msg,
    diagnostics_from_msg,
    effort_from_msg,
    header_stamp_ns,
    joint_state_from_msg,
    MessageError,
    nanoseconds_to_seconds,
)
from grasp_safety_filter.nodes.scenario import scenario_from_msg, ScenarioError
from hand_sim_node.endpoint import DIAGNOSTIC_NAME as SIM_DIAGNOSTIC

#: Simulation time at which a run starts, s: ``hand_sim_node`` starts every run at t_0 = 0,
#: with the scenario and the state at t_0.
RUN_START = 0.0


class RunDataError(ValueError):
    """The bag cannot be analysed: unreadable, or lacks or mangles what the analysis needs.

    The message is one line naming the bag and the topic or problem.
    """


@dataclass
class RunData:
    """One run's series, aligned on the simulator's steps.

    Attributes:
        scenario: The ``/grasp/scenario`` document (names, limits, mu, workspace, duration).
        mode: ``"filtered"`` or ``"nominal"`` (filter off or absent).
        t: Step start times, shape (K,), s (one per ``/hand/contacts`` sample).
        q: Joint angles at ``t``, shape (K, m), rad.
        xi_cf: Fingertip contact coordinates ``(a, b)``, shape (K, n, 2), rad.
        force: Contact forces ``(f_x, f_y, f_n)`` on the object, contact frames, (K, n, 3), N.
        required_friction: ``beta_i``, shape (K, n).
        t_command: Stamps of the commands, shape (C,), s.
        u_nominal, u_command: Nominal and commanded torques at ``t_command``, (C, m), N·m.
        filter_values: The safety filter's published tick statuses, in stamp order (one per
            stamp; keys :class:`~grasp_safety_filter.io.diagnostic_keys.Key`): every tick's,
            or with ``diagnostics.period`` every event's and one per period of a steady run.
        t_filter: Stamps of ``filter_values``, shape (F,), s.
        watchdog_values: The filter's input-watchdog statuses (inputs missing) during the
            run, bag order.
        watchdog_after_end: How many came after the simulator's end-of-run status (its inputs
            stop when the run ends: the filter falls back until it is shut down).
        stop_reason: Why the simulator stopped (``"duration"`` when it ran to the end), or None
            if the bag has no end-of-run status (an interrupted recording).
        t_end: Time the run reached, s.
        missed_start: Analysed topics whose first message is stamped after the run's start
            (the recording began late): topic -> that first stamp, s. Empty if none.
    """

    scenario: dict[str, Any]
    mode: str
    t: np.ndarray
    q: np.ndarray
    xi_cf: np.ndarray
    force: np.ndarray
    required_friction: np.ndarray
    t_command: np.ndarray
    u_nominal: np.ndarray
    u_command: np.ndarray
    filter_values: list[dict[str, str]] = field(default_factory=list)
    t_filter: np.ndarray = field(default_factory=lambda: np.zeros(0))
    watchdog_values: list[dict[str, str]] = field(default_factory=list)
    watchdog_after_end: int = 0
    stop_reason: str | None = None
    t_end: float = 0.0
    missed_start: dict[str, float] = field(default_factory=dict)

    @property
    def joint_names(self) -> list[str]:
        """Joint names, command order."""
        return list(self.scenario['joint_names'])

    @property
    def contact_names(self) -> list[str]:
        """Contact names."""
        return list(self.scenario['contact_names'])

    @property
    def joint_lower_limits(self) -> np.ndarray:
        """q_min, rad."""
        return np.asarray(self.scenario['joint_lower_limits'], dtype=float)

    @property
    def joint_upper_limits(self) -> np.ndarray:
        """q_max, rad."""
        return np.asarray(self.scenario['joint_upper_limits'], dtype=float)

    @property
    def fingertip_workspace(self) -> tuple[float, float, float, float]:
        """``(a_min, a_max, b_min, b_max)``, rad."""
        box = self.scenario['fingertip_workspace']
        return (box['a_min'], box['a_max'], box['b_min'], box['b_max'])

    @property
    def mu(self) -> float:
        """Friction coefficient."""
        return float(self.scenario['friction_coefficient'])

    @property
    def joints_per_finger(self) -> int:
        """Joints of each finger when they are listed finger by finger, else 1."""
        m, n = len(self.joint_names), len(self.contact_names)
        return m // n if n and m % n == 0 else 1


def load_run(bag: Path | str) -> RunData:
    """Read a run from a rosbag2 directory (mcap or sqlite3).

    Raises:
        RunDataError: No readable bag at ``bag``, or a topic the analysis needs is missing,
            empty, of another type or with messages it cannot use (a bad scenario too).
    """
    try:
        return _load_run(Path(bag))
    except RunDataError:
        raise
    except (BagReadError, ScenarioError, MessageError) as error:
        text = ' '.join(str(error).split())
        raise RunDataError(text if str(bag) in text else f'{bag}: {text}') from error


def _load_run(bag: Path) -> RunData:
    wanted = (
        topics.SCENARIO,
        topics.CONTACTS,
        topics.JOINT_STATES,
        topics.EFFORT_NOMINAL,
        topics.EFFORT_COMMAND,
        topics.DIAGNOSTICS,
    )
    recorded = bag_topics(bag)
    for name in wanted:
        if name in recorded and recorded[name].msgtype != topics.topic_spec(name).msgtype:
            raise RunDataError(
                f'{bag}: {name} has type {recorded[name].msgtype}; the analysis needs '
                f'{topics.topic_spec(name).msgtype}'
            )
    messages = read_bag(bag, topics=wanted)
    for topic in (topics.SCENARIO, topics.CONTACTS, topics.JOINT_STATES):
        if not messages.get(topic):
            raise RunDataError(f'{bag}: no messages on {topic}; the analysis needs it')
    scenario = scenario_from_msg(messages[topics.SCENARIO][0][1])
    joint_names, contact_names = scenario['joint_names'], scenario['contact_names']

    q_by_stamp = {}
    for _, msg in messages[topics.JOINT_STATES]:
        q_by_stamp[header_stamp_ns(msg)] = joint_state_from_msg(
            msg, joint_names, source=topics.JOINT_STATES
        ).position
    contact_msgs = sorted((msg for _, msg in messages[topics.CONTACTS]), key=header_stamp_ns)
    # Samples before the first joint state were missed by the recorder (see missed_start).
    first_state = min(q_by_stamp)
    contact_msgs = [msg for msg in contact_msgs if header_stamp_ns(msg) >= first_state]
    if not contact_msgs:
        raise RunDataError(f'{bag}: no contact sample at or after the first joint state')
    contacts = [contacts_from_msg(msg, contact_names) for msg in contact_msgs]
    stamps = [header_stamp_ns(msg) for msg in contact_msgs]
    missing = [s for s in stamps if s not in q_by_stamp]
    if missing:
        raise RunDataError(
            f'{bag}: {len(missing)} contact samples have no joint state of the same stamp '
            f'(first at {missing[0] * 1e-9:.9f} s)'
        )

    def efforts(topic: str) -> dict[int, np.ndarray]:
        # The first message of a stamp is the tick's answer; the filter's watchdog may repeat
        # a fallback later with the same stamp (the node clock stood still).
        by_stamp: dict[int, np.ndarray] = {}
        for _, msg in messages.get(topic, []):
            stamp = header_stamp_ns(msg)
            if stamp not in by_stamp:
                by_stamp[stamp] = effort_from_msg(msg, joint_names, source=topic).effort
        return by_stamp

    nominal, command = efforts(topics.EFFORT_NOMINAL), efforts(topics.EFFORT_COMMAND)
    command_stamps = sorted(set(nominal) & set(command))
    filter_values: dict[int, dict[str, str]] = {}
    watchdog_values: list[dict[str, str]] = []
    watchdog_after_end = 0
    stop_reason, t_end = None, None
    for _, msg in messages.get(topics.DIAGNOSTICS, []):
        data = diagnostics_from_msg(msg)
        for report in data.reports:
            if report.name == FILTER_DIAGNOSTIC and Key.STATUS in report.values:
                if report.values.get(Key.INPUT_WATCHDOG) == 'true' and stop_reason is not None:
                    watchdog_after_end += 1
                elif report.values.get(Key.INPUT_WATCHDOG) == 'true':
                    watchdog_values.append(dict(report.values))
                else:
                    filter_values[header_stamp_ns(msg)] = dict(report.values)
            elif report.name == SIM_DIAGNOSTIC and 'run.stop_reason' in report.values:
                stop_reason = report.values['run.stop_reason']
                t_end = float(report.values['run.t_end'])
    enabled = [v.get(Key.FILTER_ENABLED) for v in filter_values.values()]
    mode = 'filtered' if enabled and all(e == 'true' for e in enabled) else 'nominal'
    first_stamps = {
        topics.JOINT_STATES: min(q_by_stamp),
        topics.CONTACTS: min(header_stamp_ns(msg) for _, msg in messages[topics.CONTACTS]),
    }
    for topic, by_stamp in (
        (topics.EFFORT_NOMINAL, nominal),
        (topics.EFFORT_COMMAND, command),
        (topics.DIAGNOSTICS, filter_values),
    ):
        if by_stamp:
            first_stamps[topic] = min(by_stamp)
    step = float(scenario['time_step'])
    missed_start = {
        topic: nanoseconds_to_seconds(stamp)
        for topic, stamp in first_stamps.items()
        if nanoseconds_to_seconds(stamp) > RUN_START + 0.5 * step
    }
    m = len(joint_names)
    return RunData(
        scenario=scenario,
        mode=mode,
        t=np.array([c.t for c in contacts]),
        q=np.array([q_by_stamp[s] for s in stamps]).reshape(-1, m),
        xi_cf=np.array([c.xi_cf for c in contacts]),
        force=np.array([c.force for c in contacts]),
        required_friction=np.array([c.required_friction for c in contacts]),
        t_command=np.array(command_stamps, dtype=float) * 1e-9,
        u_nominal=np.array([nominal[s] for s in command_stamps]).reshape(-1, m),
        u_command=np.array([command[s] for s in command_stamps]).reshape(-1, m),
        filter_values=[filter_values[s] for s in sorted(filter_values)],
        t_filter=np.array(sorted(filter_values), dtype=float) * 1e-9,
        watchdog_values=watchdog_values,
        watchdog_after_end=watchdog_after_end,
        stop_reason=stop_reason,
        t_end=t_end if t_end is not None else max(q_by_stamp) * 1e-9,
        missed_start=missed_start,
    )
