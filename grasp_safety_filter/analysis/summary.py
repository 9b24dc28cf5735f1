"""A run's verdict, ``summary.json``: violations, margins and filter timing from its series.

The constraint families are judged by :class:`hand_sim_node.events.EventMonitor`, the code
the simulator judges a live run with, so a bag and its run always agree.

Keys (later additions never rename one)::

    {"mode", "completed", "t_end", "duration_requested", "stop_reason",
     "missed_start": {topic: first_stamp},
     "violations": {family: {"count", "first_t"}},
     "first_violated_by": {family: {"name", "side"}},
     "min_margin": {"fingertip_workspace", "joint_limits", "friction"},
     "max_required_friction", "mu",
     "filter": {"steps", "relaxed_steps", "failed_steps", "rejected_steps",
                "watchdog_fallbacks", "watchdog_statuses_after_end",
                "statuses": {status: steps},
                "relaxed_families": {family: steps},
                "qp_solve_us": {"median", "p99"}, "step_us": {"median", "p99"},
                "tick_us": {"median", "p99"}},
     "barriers": {"messages", "unreadable", "min_h": {row family: h}},
     "plant",
     "contact_events": {"contact_lost": {contact: t}, "object_dropped",
                        "slip_distance": {contact: m}},
     "object_tracking": {"reference", "samples",
                         "position_error_m": {"rms", "max", "final"},
                         "orientation_error_rad": {"rms", "max", "final"}}}

``object_tracking`` compares the object pose (``/object/odom``) with the reference sample
the nominal controller tracked at the same stamp (``/object/reference_sample``): position
error norm and rotation angle between the orientations
(:mod:`~grasp_safety_filter.analysis.tracking`); in a bag without that topic
``reference`` is ``"no reference recorded"`` and the errors are null. Absent from a bag
without ``/object/odom``.

``plant`` is ``"rigid"`` (our model) or the plant whose real contact events the simulator
published (``"mujoco"``); only then is ``contact_events`` there: per contact when it was
first lost (no touch, no force; null: never), when the object dropped (null: never), and
per contact the distance its fingertip slipped on the object over the run, m.

``first_violated_by`` names, for each violated family, the contact or joint whose
constraint was violated first and which bound (``side``: ``"a_max"``, ``"upper"``, ... or
``""`` for slip and separation); of several at the same instant, the first in the family's
order (contacts or joints in their listed order).

``missed_start`` lists the topics whose recording began after the run's start (a recorder
that subscribed late), with their first stamp in s; the verdict is then drawn from the
part that was recorded. Filter steps are the ticks the filter answered: ``failed_steps``
those without a QP answer (the filter's own fallback, an ERROR), ``rejected_steps`` those
with rejected input (the hold policy's held or fallback command), ``statuses`` every
``status`` value (:class:`~grasp_safety_filter.io.diagnostic_keys.TickStatus`) with its
count (exact also when ``diagnostics.period`` thins the published statuses: each status
carries the counts so far); ``watchdog_fallbacks`` counts the fallback commands the input
watchdog sent while no input came during the run, ``watchdog_statuses_after_end`` its
statuses after the simulator's end of run (its inputs stop then: expected, not a fault).

Each contact is judged against its own friction coefficient and fingertip workspace (slip
when beta_i > mu_i): ``min_margin.friction`` is the smallest ``mu_i - beta_i`` and ``mu`` is
one number when the contacts share it, else the list of mu_i in contact order. Soft fingers
(the scenario's ``torsional_friction`` mu_t,i) also slip when their torsion exceeds
``mu_t,i f_n,i``: their margin is ``mu_i - max(beta_i, mu_i |tau_i| / (mu_t,i f_n,i))``, with
the torsions of ``/hand/contacts``; ``max_required_friction`` stays the largest ``beta_i``.

A margin is the smallest barrier value h over the run in its own units (negative =
violated); infinite values (a separated contact) are written as null. ``barriers`` is what
the filter itself saw, from ``/safety_filter/margins`` (when recorded): the smallest h of
each of its row families (``no_slip``, ``joint_limits``, ...; the QP's rows at u*, or at
u_nom with the filter off), the messages read, and those that could not be read (nameless
ones before any that named the rows, as in a recording that began late; malformed ones).

Filter times are the node's own, per tick: the QP solve, the whole filter step
(``SafetyFilter.solve``) and the whole tick (model terms, filter step, messages); in a
lockstep run they include the cache and allocator effects of the simulator sharing the
process.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable
import math
from typing import Any

import numpy as np

from grasp_safety_filter.analysis.filter_statuses import TIME_KEYS
from grasp_safety_filter.analysis.run_data import RunData
from grasp_safety_filter.analysis.verdict import INTERRUPTED
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.diagnostic_keys import (
    FAILED_STATUSES,
    INPUT_STATUSES,
    Key,
    TickStatus,
)
from grasp_safety_filter.io.plant_schema import RIGID_PLANT
from grasp_safety_filter.model.per_contact import compact
from hand_sim_node.constraint_margins import ConstraintMargins, Event
from hand_sim_node.event_log import EventLog
from hand_sim_node.events import EventMonitor


def _finite_or_none(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _percentiles(
    values: list[float], weights: list[int] | None = None
) -> dict[str, float | None]:
    """Median and p99 of ``values``, each counted ``weights`` times (default once).

    With weights, the inverted CDF (the smallest value whose cumulative weight reaches the
    quantile), as ``numpy.percentile(..., method='inverted_cdf')``.
    """
    if not values:
        return {'median': None, 'p99': None}
    array = np.asarray(values, dtype=float)
    if weights is None:
        return {'median': float(np.median(array)), 'p99': float(np.percentile(array, 99))}
    order = np.argsort(array, kind='stable')
    cumulative = np.cumsum(np.asarray(weights, dtype=float)[order])

    def quantile(q: float) -> float:
        index = int(np.searchsorted(cumulative, q * cumulative[-1], side='left'))
        return float(array[order][min(index, len(array) - 1)])

    return {'median': quantile(0.5), 'p99': quantile(0.99)}


def _tick_weights(run: RunData) -> np.ndarray:
    """How many ticks each published status stands for: those since the previous one.

    A steady status published once per ``diagnostics.period`` stands for the ticks of its
    period, so that times are percentiles over ticks, not over published statuses.
    Statuses without counts (an older bag) stand for one tick each.
    """
    weights = np.ones(len(run.filter_statuses), dtype=np.int64)
    previous = 0
    for k, ticks in enumerate(run.filter_statuses.ticks.tolist()):
        if ticks >= 0:
            weights[k] = max(ticks - previous, 1)
            previous = ticks
    return weights


def _monitor(run: RunData) -> EventMonitor:
    """Return the simulator's event monitor for the run's hand and scenario."""
    return EventMonitor(
        run.joint_lower_limits,
        run.joint_upper_limits,
        tuple(run.workspace_per_contact.T),
        run.mu_per_contact,
        run.joint_names,
        run.contact_names,
        run.object_face_half_widths,
        run.torsional_friction_per_contact,
    )


def _margins_at(monitor: EventMonitor, run: RunData, k: int) -> ConstraintMargins:
    """Return sample k's margins (a soft finger's wrench: 3n forces, then n torsions)."""
    forces = run.force[k].reshape(-1)
    wrench = forces if run.torsion is None else np.concatenate((forces, run.torsion[k]))
    xi_co = None if run.xi_co is None else run.xi_co[k]
    return monitor.margins_at(run.t[k], run.q[k], run.xi_cf[k], wrench, xi_co)


def constraint_log(run: RunData) -> EventLog:
    """Judge every step of the run with the simulator's event monitor."""
    monitor = _monitor(run)
    log = EventLog()
    for k in range(len(run.t)):
        margins = _margins_at(monitor, run, k)
        log.record(margins, monitor.events(margins))
    return log


def events_at(run: RunData, k: int) -> tuple[Event, ...]:
    """Return the constraints the simulator's event monitor finds violated at sample k."""
    monitor = _monitor(run)
    return monitor.events(_margins_at(monitor, run, k))


def tick_counts(run: RunData) -> dict[str, int]:
    """Count the run's ticks by status, including those whose status was not published.

    A status carries the counts of every tick so far (``count.<status>``); the ticks
    answered after the last published one repeat its status (a steady run between two
    ``diagnostics.period``; when the recording missed the first commands, those between the
    last status and the first recorded command are counted on the time-step grid). Statuses
    without counts (a bag of an older version): one tick each.
    """
    statuses = run.filter_statuses
    if statuses.counts is not None:
        counts = dict(statuses.counts)
    else:
        counts = dict(Counter(statuses.status))
    if len(statuses):
        last, t_last = statuses.status[-1], statuses.t[-1]
        later = int(np.count_nonzero(run.t_command > t_last + 0.5e-9))
        if later and topics.EFFORT_COMMAND in run.missed_start:
            # The recording missed the commands of the ticks between the last status and
            # its first command: one tick per time step (the lockstep grid).
            step = float(run.scenario['time_step'])
            later += max(0, round((float(run.t_command[0]) - t_last) / step) - 1)
        if later:
            counts[last] = counts.get(last, 0) + later
    return counts


def filter_summary(run: RunData) -> dict[str, Any]:
    """Count the filter's steps by status; QP, filter-step and tick times.

    Counts are exact (:func:`tick_counts`). Every relaxed, failed or rejected tick's status
    is published, so ``relaxed_families`` counts, per family, the relaxed steps that gave up
    one of its rows; the times are percentiles over ticks, each published status standing
    for the ticks since the previous one (:func:`_tick_weights`): exact with
    ``diagnostics.period`` 0, else a steady period's times are those of its published tick.
    """
    statuses = run.filter_statuses
    counts = tick_counts(run)
    relaxed_families: dict[str, int] = {}
    relaxed_lists = Counter(
        families
        for families, relaxed in zip(statuses.relaxed_families, statuses.relaxed, strict=True)
        if relaxed
    )
    for families, steps in relaxed_lists.items():
        for family in filter(None, families.split(',')):
            relaxed_families[family] = relaxed_families.get(family, 0) + steps

    def count(kinds: Iterable[TickStatus]) -> int:
        return sum(counts.get(status.value, 0) for status in kinds)

    weights = _tick_weights(run)

    def times(column: int) -> dict[str, float | None]:
        values = statuses.times_us[:, column]
        timed = ~np.isnan(values)
        return _percentiles(values[timed].tolist(), weights[timed].tolist())

    return {
        'steps': sum(counts.values()),
        'relaxed_steps': int(np.count_nonzero(statuses.relaxed)),
        'failed_steps': count(FAILED_STATUSES),
        'rejected_steps': count(INPUT_STATUSES),
        'watchdog_fallbacks': run.watchdog_statuses.get(TickStatus.INPUT_FALLBACK.value, 0),
        'watchdog_statuses_after_end': run.watchdog_after_end,
        'statuses': counts,
        'relaxed_families': relaxed_families,
        'qp_solve_us': times(TIME_KEYS.index(Key.SOLVE_TIME_US)),
        'step_us': times(TIME_KEYS.index(Key.STEP_TIME_US)),
        'tick_us': times(TIME_KEYS.index(Key.TICK_TIME_US)),
    }


def first_violated_by(log: EventLog) -> dict[str, dict[str, str]]:
    """Per violated family, the contact or joint (and bound) violated first in the run."""
    first: dict[str, dict[str, str]] = {}
    for event in log.onsets:  # in time order
        first.setdefault(event.family, {'name': event.name, 'side': event.side})
    return first


def summarize(run: RunData) -> dict[str, Any]:
    """Build the run's ``summary.json`` document."""
    log = constraint_log(run)
    duration = float(run.scenario['duration'])
    step = float(run.scenario['time_step'])
    completed = run.stop_reason == 'duration' or (
        run.stop_reason is None and run.t_end >= duration - 0.5 * step
    )
    stop_reason = None if completed else (run.stop_reason or INTERRUPTED)
    summary: dict[str, Any] = {
        'mode': run.mode,
        'completed': bool(completed),
        't_end': float(run.t_end),
        'duration_requested': duration,
        'stop_reason': stop_reason,
        'missed_start': dict(run.missed_start),
        'violations': log.violations(),
        'first_violated_by': first_violated_by(log),
        'min_margin': {k: _finite_or_none(v) for k, v in log.min_margin().items()},
        'max_required_friction': _finite_or_none(log.max_required_friction),
        'mu': compact(run.mu_per_contact),
    }
    events = run.plant_events
    summary['plant'] = RIGID_PLANT if events is None else events.plant
    if events is not None:
        summary['contact_events'] = {
            'contact_lost': {name: events.contact_lost.get(name) for name in run.contact_names},
            'object_dropped': events.object_dropped,
            'slip_distance': {
                name: events.slip_distance.get(name) for name in run.contact_names
            },
        }
    if run.mode == 'filtered':
        summary['filter'] = filter_summary(run)
    if run.tracking is not None:
        summary['object_tracking'] = run.tracking.summary()
    if run.barriers is not None:
        summary['barriers'] = {
            **run.barriers,
            'min_h': {k: _finite_or_none(v) for k, v in run.barriers['min_h'].items()},
        }
    return summary
