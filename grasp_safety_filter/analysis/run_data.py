"""A recorded run as arrays: read from any bag with this package's topics.

Works on bags written by the ROS-free runner and by ``ros2 bag record`` alike: everything
is taken from the messages (header stamps, ``/grasp/scenario``), nothing from the runner.

The bag is streamed, one message at a time: of each tick only its numbers are kept, packed
(:mod:`~grasp_safety_filter.analysis.columns`, some 50 float64 per tick), and of the
filter's statuses and margins only what the summary reads
(:mod:`~grasp_safety_filter.analysis.filter_statuses`,
:mod:`~grasp_safety_filter.analysis.barriers`). Memory is a few hundred bytes per tick,
not the messages (kilobytes per tick: a 15 s run's bag would take hundreds of MB). The
topics are read by :mod:`~grasp_safety_filter.analysis.topic_readers`: the JointState ones
packed and checked once, and on two cores (the object's odometry and the margins in a
forked child), with the same result and errors as a one-pass, message-by-message read.

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

from grasp_safety_filter.analysis.barriers import BarrierReader
from grasp_safety_filter.analysis.filter_statuses import FilterStatuses
from grasp_safety_filter.analysis.topic_readers import Diagnostics, read_topics, Series
from grasp_safety_filter.analysis.tracking import ObjectTracking, TRACKING_TOPICS
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import BagReadError, iter_bag, open_bag, OpenBag
from grasp_safety_filter.io.messages import MessageError, nanoseconds_to_seconds
from grasp_safety_filter.io.sim_diagnostic_keys import PlantEvents
from grasp_safety_filter.nodes.scenario import (
    OBJECT_FACES_KEY,
    scenario_from_msg,
    scenario_per_contact,
    scenario_workspace,
    ScenarioError,
    TORSIONAL_FRICTION_KEY,
)

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
        filter_statuses: The safety filter's published tick statuses, one per stamp in stamp
            order: every tick's, or with ``diagnostics.period`` every event's and one per
            period of a steady run.
        watchdog_statuses: The filter's input-watchdog statuses (inputs missing) during the
            run, counted by ``status``.
        watchdog_after_end: How many came after the simulator's end-of-run status (its inputs
            stop when the run ends: the filter falls back until it is shut down).
        stop_reason: Why the simulator stopped (``"duration"`` when it ran to the end), or None
            if the bag has no end-of-run status (an interrupted recording).
        t_end: Time the run reached, s.
        missed_start: Analysed topics whose first message is stamped after the run's start
            (the recording began late): topic -> that first stamp, s. Empty if none.
        barriers: The filter's smallest barrier value per row family over the run, from
            ``/safety_filter/margins`` (:meth:`BarrierReader.summary`); None without them.
        xi_co: Object surface contact coordinates at ``t``, shape (K, n, 2) (m on a face);
            None if not read.
        plant_events: The real contact events of a plant that measures them (MuJoCo): the
            last record the simulator published; None for the rigid plant.
        tracking: The object pose against the reference the nominal controller tracked
            (:mod:`~grasp_safety_filter.analysis.tracking`); None without ``/object/odom``.
        torsion: Soft fingers' torsions about the contact normals at ``t``, shape (K, n),
            N·m; None for point contacts.
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
    filter_statuses: FilterStatuses = field(default_factory=FilterStatuses)
    watchdog_statuses: dict[str, int] = field(default_factory=dict)
    watchdog_after_end: int = 0
    stop_reason: str | None = None
    t_end: float = 0.0
    missed_start: dict[str, float] = field(default_factory=dict)
    barriers: dict[str, Any] | None = None
    xi_co: np.ndarray | None = None
    plant_events: PlantEvents | None = None
    tracking: ObjectTracking | None = None
    torsion: np.ndarray | None = None

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
    def workspace_per_contact(self) -> np.ndarray:
        """Each contact's ``(a_min, a_max, b_min, b_max)``, shape (n, 4), rad."""
        return np.asarray(scenario_workspace(self.scenario), dtype=float).reshape(-1, 4)

    @property
    def mu_per_contact(self) -> np.ndarray:
        """Each contact's friction coefficient mu_i, shape (n,)."""
        return np.asarray(scenario_per_contact(self.scenario, 'friction_coefficient'), float)

    @property
    def torsional_friction_per_contact(self) -> np.ndarray | None:
        """Soft fingers' torsional friction mu_t,i, shape (n,), m; None for point contacts.

        From the scenario document's
        :data:`~grasp_safety_filter.nodes.scenario.TORSIONAL_FRICTION_KEY` (absent: point
        contacts).
        """
        if TORSIONAL_FRICTION_KEY not in self.scenario:
            return None
        return np.asarray(scenario_per_contact(self.scenario, TORSIONAL_FRICTION_KEY), float)

    @property
    def object_face_half_widths(self) -> np.ndarray | None:
        """Each contact's face half extents ``(h_u, h_v)``, (n, 2), m; None if not recorded.

        From the scenario document's
        :data:`~grasp_safety_filter.nodes.scenario.OBJECT_FACES_KEY` (a box object's runs;
        ``inf`` stands for a contact without an edge).
        """
        rows = self.scenario.get(OBJECT_FACES_KEY)
        if not isinstance(rows, list) or len(rows) != len(self.contact_names):
            return None
        try:
            half = np.array(
                [[np.inf if h is None else h for h in row] for row in rows], dtype=float
            )
        except (TypeError, ValueError):
            return None
        return half if half.shape == (len(rows), 2) and np.all(half > 0.0) else None

    @property
    def fingertip_workspace(self) -> tuple[float, float, float, float]:
        """``(a_min, a_max, b_min, b_max)``, rad, that every contact's box contains.

        The box itself when all contacts share it; else the intersection of theirs (see
        :attr:`workspace_per_contact`).
        """
        box = self.workspace_per_contact
        return (
            float(box[:, 0].max()),
            float(box[:, 1].min()),
            float(box[:, 2].max()),
            float(box[:, 3].min()),
        )

    @property
    def mu(self) -> float:
        """Friction coefficient: the one all contacts share, else the smallest mu_i."""
        return float(self.mu_per_contact.min())


def load_run(bag: Path | str) -> RunData:
    """Read a run from a rosbag2 directory (mcap or sqlite3), streaming it (module doc).

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


#: Topics the analysis reads (``/safety_filter/margins`` only if of its type).
ANALYSED_TOPICS = (
    topics.SCENARIO,
    topics.CONTACTS,
    topics.JOINT_STATES,
    topics.EFFORT_NOMINAL,
    topics.EFFORT_COMMAND,
    topics.DIAGNOSTICS,
    *TRACKING_TOPICS,
)


def _first_per_stamp(stamps: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sorted distinct stamps and the index of each one's first message."""
    return np.unique(stamps, return_index=True)


def _read_scenario(bag: Path, opened: OpenBag | None = None) -> dict[str, Any]:
    """Read the first ``/grasp/scenario`` message: the names every other message is read by.

    ``opened``: the bag already open (None: opened here).
    """
    messages = (
        iter_bag(bag, topics=[topics.SCENARIO])
        if opened is None
        else opened.messages(topics=[topics.SCENARIO])
    )
    for _, _, msg in messages:
        return scenario_from_msg(msg)
    raise RunDataError(f'{bag}: no messages on {topics.SCENARIO}; the analysis needs it')


def read_scenario(bag: Path | str) -> dict[str, Any]:
    """Read a bag's scenario document (``/grasp/scenario``) alone.

    Raises:
        RunDataError: No readable bag at ``bag``, or no valid scenario in it.
    """
    try:
        return _read_scenario(Path(bag))
    except RunDataError:
        raise
    except (BagReadError, ScenarioError, MessageError) as error:
        text = ' '.join(str(error).split())
        raise RunDataError(text if str(bag) in text else f'{bag}: {text}') from error


def _load_run(bag: Path) -> RunData:
    with open_bag(bag) as opened:  # once: its metadata and index are read once
        return _read_run(bag, opened)


def _read_run(bag: Path, opened: OpenBag) -> RunData:
    recorded = opened.topics
    for name in ANALYSED_TOPICS:
        if name in recorded and recorded[name].msgtype != topics.topic_spec(name).msgtype:
            raise RunDataError(
                f'{bag}: {name} has type {recorded[name].msgtype}; the analysis needs '
                f'{topics.topic_spec(name).msgtype}'
            )
    scenario = _read_scenario(bag, opened)
    wanted = [name for name in ANALYSED_TOPICS if name != topics.SCENARIO]
    margins = recorded.get(topics.MARGINS)
    if margins is not None and margins.msgtype == topics.topic_spec(topics.MARGINS).msgtype:
        wanted.append(topics.MARGINS)
    readers = read_topics(bag, opened, scenario, wanted)
    series, diagnostics, barriers = readers.series, readers.diagnostics, readers.barriers
    for topic, column in (
        (topics.CONTACTS, series.contact_stamps),
        (topics.JOINT_STATES, series.joint_stamps),
    ):
        if not len(column):
            raise RunDataError(f'{bag}: no messages on {topic}; the analysis needs it')
    run = _assemble(bag, scenario, series, diagnostics, barriers)
    run.tracking = readers.tracking.finish()
    return run


def _assemble(
    bag: Path,
    scenario: dict[str, Any],
    series: Series,
    diagnostics: Diagnostics,
    barriers: BarrierReader | None,
) -> RunData:
    """Align the streamed series on the simulator's steps (one joint state per contact)."""
    joint_stamps = series.joint_stamps.array()
    # The last joint state of a stamp counts (a re-sent state repeats the same values).
    last_first = len(joint_stamps) - 1 - _first_per_stamp(joint_stamps[::-1])[1]
    state_stamps = joint_stamps[last_first]
    order = np.argsort(state_stamps, kind='stable')
    state_stamps, state_rows = state_stamps[order], last_first[order]
    all_contact_stamps = series.contact_stamps.array()
    # Samples before the first joint state were missed by the recorder (see missed_start).
    by_stamp = np.argsort(all_contact_stamps, kind='stable')
    kept = by_stamp[all_contact_stamps[by_stamp] >= state_stamps[0]]
    if not len(kept):
        raise RunDataError(f'{bag}: no contact sample at or after the first joint state')
    contact_stamps = all_contact_stamps[kept]
    position = np.minimum(np.searchsorted(state_stamps, contact_stamps), len(state_stamps) - 1)
    matched = state_stamps[position] == contact_stamps
    if not matched.all():
        missing = contact_stamps[~matched]
        raise RunDataError(
            f'{bag}: {len(missing)} contact samples have no joint state of the same stamp '
            f'(first at {missing[0] * 1e-9:.9f} s)'
        )
    # The first message of a stamp is the tick's answer; the filter's watchdog may repeat
    # a fallback later with the same stamp (the node clock stood still).
    nominal_stamps, nominal_first = _first_per_stamp(
        series.effort_stamps[topics.EFFORT_NOMINAL].array()
    )
    command_only, command_first = _first_per_stamp(
        series.effort_stamps[topics.EFFORT_COMMAND].array()
    )
    command_stamps, in_nominal, in_command = np.intersect1d(
        nominal_stamps, command_only, assume_unique=True, return_indices=True
    )
    statuses = diagnostics.filter.finish()
    mode = 'filtered' if len(statuses) and statuses.enabled.all() else 'nominal'
    first_stamps = {
        topics.JOINT_STATES: int(state_stamps[0]),
        topics.CONTACTS: int(all_contact_stamps.min()),
    }
    for topic, stamps in (
        (topics.EFFORT_NOMINAL, nominal_stamps),
        (topics.EFFORT_COMMAND, command_only),
        (topics.DIAGNOSTICS, diagnostics.filter.stamps()),
    ):
        if len(stamps):
            first_stamps[topic] = int(stamps.min())
    step = float(scenario['time_step'])
    missed_start = {
        topic: nanoseconds_to_seconds(stamp)
        for topic, stamp in first_stamps.items()
        if nanoseconds_to_seconds(stamp) > RUN_START + 0.5 * step
    }
    m = len(scenario['joint_names'])
    nominal_rows, command_rows = nominal_first[in_nominal], command_first[in_command]
    t_end = diagnostics.t_end
    return RunData(
        scenario=scenario,
        mode=mode,
        t=series.contact_t.array()[kept],
        q=series.q.array()[state_rows[position]].reshape(-1, m),
        xi_cf=series.xi_cf.array()[kept],
        force=series.force.array()[kept],
        required_friction=series.required_friction.array()[kept],
        t_command=command_stamps.astype(float) * 1e-9,
        u_nominal=series.efforts[topics.EFFORT_NOMINAL].array()[nominal_rows].reshape(-1, m),
        u_command=series.efforts[topics.EFFORT_COMMAND].array()[command_rows].reshape(-1, m),
        filter_statuses=statuses,
        watchdog_statuses=dict(diagnostics.watchdog),
        watchdog_after_end=diagnostics.watchdog_after_end,
        stop_reason=diagnostics.stop_reason,
        t_end=t_end if t_end is not None else int(state_stamps[-1]) * 1e-9,
        missed_start=missed_start,
        barriers=None if barriers is None else barriers.summary(),
        xi_co=series.xi_co.array()[kept],
        plant_events=diagnostics.plant_events,
        torsion=None if series.torsion is None else series.torsion.array()[kept],
    )
