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
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.analysis.barriers import BarrierReader
from grasp_safety_filter.analysis.columns import Column
from grasp_safety_filter.analysis.filter_statuses import FilterStatusReader
from grasp_safety_filter.analysis.forked import ForkedCall
from grasp_safety_filter.analysis.tracking import TRACKING_TOPICS, TrackingReader
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import open_bag, OpenBag
from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.messages import (
    contacts_from_msg,
    diagnostics_from_msg,
    effort_from_msg,
    header_stamp_ns,
    joint_state_from_msg,
)
from grasp_safety_filter.io.sim_diagnostic_keys import PlantEvents, SIM_DIAGNOSTIC, SimKey

#: Topics read in the forked child (the object's two odometry streams and the margins:
#: about half of a run's reading time); the others are read by the caller.
CHILD_TOPICS = (*TRACKING_TOPICS, topics.MARGINS)
#: Fewest analysed messages for which reading in two processes pays for the fork (a few
#: ms) and the child's result sent back (some MB for a long run).
MIN_SPLIT_MESSAGES = 4000


class Series:
    """Per-tick numbers of a run, packed as the bag streams (see ``run_data``)."""

    def __init__(self, m: int, n: int) -> None:
        self.joint_stamps = Column((), np.int64)
        self.q = Column((m,))
        self.contact_stamps = Column((), np.int64)
        self.contact_t = Column(())
        self.xi_cf = Column((n, 2))
        self.xi_co = Column((n, 2))
        self.force = Column((n, 3))
        self.required_friction = Column((n,))
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
        scenario: The run's scenario document (its joint and contact names).
        margins: Read ``/safety_filter/margins`` too (the bag has it, of its type).

    """

    def __init__(self, scenario: dict[str, Any], margins: bool) -> None:
        self.joint_names = list(scenario['joint_names'])
        self.contact_names = list(scenario['contact_names'])
        self.series = Series(len(self.joint_names), len(self.contact_names))
        self.diagnostics = Diagnostics(list(self.contact_names))
        self.tracking = TrackingReader()
        self.barriers = BarrierReader() if margins else None

    def add(self, topic: str, msg: Any) -> None:
        """Read one message of ``topic``."""
        series = self.series
        if topic == topics.JOINT_STATES:
            series.joint_stamps.append(header_stamp_ns(msg))
            series.q.append(joint_state_from_msg(msg, self.joint_names, source=topic).position)
        elif topic == topics.CONTACTS:
            contact = contacts_from_msg(msg, self.contact_names)
            series.contact_stamps.append(header_stamp_ns(msg))
            series.contact_t.append(contact.t)
            series.xi_cf.append(contact.xi_cf)
            series.xi_co.append(contact.xi_co)
            series.force.append(contact.force)
            series.required_friction.append(contact.required_friction)
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
    """Read the analysed topics ``wanted`` of an open bag, in two processes if it pays.

    ``wanted`` includes :data:`~grasp_safety_filter.io.topics.MARGINS` when the margins
    are to be read. Raises what the one-pass read (:meth:`TopicReaders.read`) raises.
    """
    margins = topics.MARGINS in wanted
    child = [name for name in wanted if name in CHILD_TOPICS]
    own = [name for name in wanted if name not in CHILD_TOPICS]
    recorded = opened.topics
    count = sum(recorded[name].count for name in wanted if name in recorded)
    if count >= MIN_SPLIT_MESSAGES and child and own:
        with ForkedCall(lambda: _child_half(bag, scenario, margins, child)) as forked:
            readers = TopicReaders(scenario, margins)
            try:
                readers.read(opened, own)
                readers.tracking, readers.barriers = forked.result()
                return readers
            except Exception:  # ForkedCallError, or either half failed
                pass  # read again in one pass: its result or its error (module docstring)
    readers = TopicReaders(scenario, margins)
    readers.read(opened, wanted)
    return readers
