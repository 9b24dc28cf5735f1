"""What the analysis keeps of each topic of a bag, read one message at a time.

:class:`TopicReaders` holds one reader per analysed topic: the per-tick numbers packed as
columns (:class:`Series`), the kept parts of ``/diagnostics`` (:class:`Diagnostics`), the
object tracking and the filter's barrier values. The topics are independent of one
another, so :func:`read_topics` reads them in two halves at once, one in a forked child
(:mod:`~grasp_safety_filter.analysis.forked`), on a bag large enough to gain from it; if
the child gives no result, or either half fails, everything is read again in one pass in
bag order, so that the result and any error are those of the one-pass read.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
from functools import partial
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.analysis.barriers import BarrierReader
from grasp_safety_filter.analysis.columns import Column
from grasp_safety_filter.analysis.filter_statuses import FilterStatusReader
from grasp_safety_filter.analysis.forked import ForkedCall
from grasp_safety_filter.analysis.joint_state_columns import (
    JointStateColumns,
    NANOSECONDS_PER_SECOND,
)
from grasp_safety_filter.analysis.tracking import TRACKING_TOPICS, TrackingReader
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import open_bag, OpenBag
from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.messages import (
    contact_entry_names,
    contact_quantities,
    contacts_from_msg,
    diagnostics_from_msg,
    effort_from_msg,
    header_stamp_ns,
    joint_state_from_msg,
)
from grasp_safety_filter.io.messages.contacts import positive_inf_allowed
from grasp_safety_filter.io.sim_diagnostic_keys import PlantEvents, SIM_DIAGNOSTIC, SimKey
from grasp_safety_filter.nodes.scenario import TORSIONAL_FRICTION_KEY

#: Topics read in the forked child (the object's two odometry streams and the margins:
#: about half of a run's reading time); the others are read by the caller.
CHILD_TOPICS = (*TRACKING_TOPICS, topics.MARGINS)
#: The JointState topics packed (:class:`JointStateColumns`): name kind and, per field
#: (position, velocity, effort), whether the parser requires one entry per name.
PACKED_TOPICS = {
    topics.JOINT_STATES: ('joint', (True, True, False)),
    topics.CONTACTS: ('contact entry', (True, True, False)),
    topics.EFFORT_NOMINAL: ('joint', (False, False, True)),
    topics.EFFORT_COMMAND: ('joint', (False, False, True)),
}
#: Fewest analysed messages for which reading in two processes pays for the fork (a few
#: ms) and the child's result sent back (some MB for a long run).
MIN_SPLIT_MESSAGES = 4000


class Series:
    """Per-tick numbers of a run, packed as the bag streams (see ``run_data``).

    ``torsion``: soft fingers' torsions, kept when the contacts are soft fingers.
    """

    def __init__(self, m: int, n: int, soft_finger: bool = False) -> None:
        self.joint_stamps = Column((), np.int64)
        self.q = Column((m,))
        self.contact_stamps = Column((), np.int64)
        self.contact_t = Column(())
        self.xi_cf = Column((n, 2))
        self.xi_co = Column((n, 2))
        self.force = Column((n, 3))
        self.required_friction = Column((n,))
        self.torsion = Column((n,)) if soft_finger else None
        self.effort_stamps = {
            topics.EFFORT_NOMINAL: Column((), np.int64),
            topics.EFFORT_COMMAND: Column((), np.int64),
        }
        self.efforts = {topics.EFFORT_NOMINAL: Column((m,)), topics.EFFORT_COMMAND: Column((m,))}


class Diagnostics:
    """What the analysis keeps of ``/diagnostics``, read in bag order."""

    def __init__(self, contact_names: list[str]) -> None:
        self.contact_names = contact_names
        self.plant_events: PlantEvents | None = None
        self.filter = FilterStatusReader()
        self.watchdog: Counter[str] = Counter()
        self.watchdog_after_end = 0
        self.stop_reason: str | None = None
        self.t_end: float | None = None

    def add(self, msg: Any) -> None:
        """Read one ``/diagnostics`` message."""
        for report in diagnostics_from_msg(msg).reports:
            values = report.values
            if report.name == FILTER_DIAGNOSTIC and Key.STATUS in values:
                if values.get(Key.INPUT_WATCHDOG) == 'true' and self.stop_reason is not None:
                    self.watchdog_after_end += 1
                elif values.get(Key.INPUT_WATCHDOG) == 'true':
                    self.watchdog[values[Key.STATUS]] += 1
                else:
                    self.filter.add(header_stamp_ns(msg), values)
            elif report.name == SIM_DIAGNOSTIC:
                events = PlantEvents.from_values(values, self.contact_names)
                if events is not None:
                    self.plant_events = events
                if SimKey.RUN_STOP_REASON in values:
                    self.stop_reason = values[SimKey.RUN_STOP_REASON]
                    self.t_end = float(values[SimKey.RUN_T_END])


class TopicReaders:
    """One reader per analysed topic of a run (module docstring).

    Args:
        scenario: The run's scenario document (its joint and contact names; with
            :data:`~grasp_safety_filter.nodes.scenario.TORSIONAL_FRICTION_KEY`, soft fingers,
            whose ``/hand/contacts`` must carry every contact's torsion).
        margins: Read ``/safety_filter/margins`` too (the bag has it, of its type).
        packed: Keep the JointState topics packed (:data:`PACKED_TOPICS`), checked and
            put into :attr:`series` by :meth:`unpack`; else parse each message.

    """

    def __init__(self, scenario: dict[str, Any], margins: bool, packed: bool = False) -> None:
        self.joint_names = list(scenario['joint_names'])
        self.contact_names = list(scenario['contact_names'])
        self.soft_finger = TORSIONAL_FRICTION_KEY in scenario
        self.series = Series(len(self.joint_names), len(self.contact_names), self.soft_finger)
        self.diagnostics = Diagnostics(list(self.contact_names))
        self.tracking = TrackingReader()
        self.barriers = BarrierReader() if margins else None
        self.packed: dict[str, JointStateColumns] = {}
        if packed:
            entries = contact_entry_names(self.contact_names, self.soft_finger)
            for topic, (kind, required) in PACKED_TOPICS.items():
                names = entries if topic == topics.CONTACTS else self.joint_names
                self.packed[topic] = JointStateColumns(topic, names, kind, required)

    def add(self, topic: str, msg: Any) -> None:
        """Read one message of ``topic``."""
        series = self.series
        packed = self.packed.get(topic)
        if packed is not None:
            packed.add(msg)
        elif topic == topics.JOINT_STATES:
            series.joint_stamps.append(header_stamp_ns(msg))
            series.q.append(joint_state_from_msg(msg, self.joint_names, source=topic).position)
        elif topic == topics.CONTACTS:
            contact = contacts_from_msg(
                msg, self.contact_names, source=topic, torsion=self.soft_finger
            )
            series.contact_stamps.append(header_stamp_ns(msg))
            series.contact_t.append(contact.t)
            series.xi_cf.append(contact.xi_cf)
            series.xi_co.append(contact.xi_co)
            series.force.append(contact.force)
            series.required_friction.append(contact.required_friction)
            if series.torsion is not None:
                series.torsion.append(contact.torsion)
        elif topic in series.efforts:
            series.effort_stamps[topic].append(header_stamp_ns(msg))
            series.efforts[topic].append(
                effort_from_msg(msg, self.joint_names, source=topic).effort
            )
        elif topic == topics.DIAGNOSTICS:
            self.diagnostics.add(msg)
        elif topic in TRACKING_TOPICS:
            self.tracking.add(topic, msg)
        elif self.barriers is not None:
            self.barriers.add(msg, topic)

    def read(self, opened: OpenBag, wanted: Iterable[str]) -> None:
        """Read every message of the topics ``wanted`` in bag order."""
        for topic, _, msg in opened.messages(topics=wanted):
            self.add(topic, msg)
        self.unpack()

    def unpack(self) -> None:
        """Check the packed topics and put their numbers into :attr:`series`.

        Each is what :meth:`add` without packing keeps: the same stamps and numbers.

        Raises:
            UnusualMessagesError: A packed topic's messages are not all as the parsers
                take them (:mod:`~grasp_safety_filter.analysis.joint_state_columns`).

        """
        if not self.packed:
            return
        series = self.series
        stamps, (q, _, _) = self.packed[topics.JOINT_STATES].rows()
        series.joint_stamps, series.q = Column.of(stamps), Column.of(q)
        for topic in series.efforts:
            stamps, (_, _, effort) = self.packed[topic].rows()
            series.effort_stamps[topic] = Column.of(stamps)
            series.efforts[topic] = Column.of(effort)
        contacts = self.packed[topics.CONTACTS]
        allowed = positive_inf_allowed(tuple(contacts.names or ()))
        stamps, (values, _, _) = contacts.rows(allowed)
        n = len(self.contact_names)
        quantities = contact_quantities(self.soft_finger)
        values = values.reshape(len(stamps), n, len(quantities))
        quantity = quantities.index
        series.contact_stamps = Column.of(stamps)
        series.contact_t = Column.of(stamps / NANOSECONDS_PER_SECOND)
        series.xi_cf = Column.of(values[:, :, quantity('a') : quantity('b') + 1])
        series.xi_co = Column.of(values[:, :, quantity('u') : quantity('v') + 1])
        series.force = Column.of(values[:, :, quantity('force_x') : quantity('force_normal') + 1])
        series.required_friction = Column.of(values[:, :, quantity('required_friction')])
        if series.torsion is not None:
            series.torsion = Column.of(values[:, :, quantity('torsion')])
        self.packed = {}


def _child_half(
    bag: Path, scenario: dict[str, Any], margins: bool, wanted: list[str]
) -> tuple[TrackingReader, BarrierReader | None]:
    """Read the topics of :data:`CHILD_TOPICS` ``wanted`` (in the child): their readers."""
    readers = TopicReaders(scenario, margins)
    with open_bag(bag) as opened:  # its own: a file offset is shared across a fork
        readers.read(opened, wanted)
    return readers.tracking, readers.barriers


def read_topics(
    bag: Path, opened: OpenBag, scenario: dict[str, Any], wanted: list[str]
) -> TopicReaders:
    """Read the analysed topics ``wanted`` of an open bag: packed, in two processes if it pays.

    ``wanted`` includes :data:`~grasp_safety_filter.io.topics.MARGINS` when the margins
    are to be read. Returns and raises what the one-pass read of each message by its parser
    (``TopicReaders(scenario, margins).read``) returns and raises (module docstring).
    """
    margins = topics.MARGINS in wanted
    child = [name for name in wanted if name in CHILD_TOPICS]
    own = [name for name in wanted if name not in CHILD_TOPICS]
    recorded = opened.topics
    count = sum(recorded[name].count for name in wanted if name in recorded)
    readers = TopicReaders(scenario, margins, packed=True)
    try:
        if count >= MIN_SPLIT_MESSAGES and child and own:
            with ForkedCall(partial(_child_half, bag, scenario, margins, child)) as forked:
                readers.read(opened, own)
                readers.tracking, readers.barriers = forked.result()
        else:
            readers.read(opened, wanted)
        return readers
    except Exception:  # ForkedCallError, UnusualMessagesError, or either half failed
        pass  # read again in one pass, each message parsed: its result or its error
    readers = TopicReaders(scenario, margins)
    readers.read(opened, wanted)
    return readers
