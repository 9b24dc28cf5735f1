"""The safety filter's ``/diagnostics`` status, defined once: its name, keys and values.

:class:`~grasp_safety_filter.nodes.safety_filter.SafetyFilterEndpoint` and
:class:`~grasp_safety_filter.control.hold_policy.HoldPolicy` write them;
:mod:`grasp_safety_filter.analysis` reads them back from a bag. Both sides use the names
below, never the strings, so a status or key that one side writes and the other does not
know cannot go unnoticed.

The grasp keys (``grasp.*``) are also the nominal controller's (its status
:data:`NOMINAL_DIAGNOSTIC`) on a state that is not a grasp.

Every ``safety_filter`` status that answers a tick (or stands in for a missing one) has a
:attr:`Key.STATUS` whose value is a :class:`TickStatus`: how the published u* was obtained.
"""

from __future__ import annotations

from enum import Enum

from grasp_safety_filter.control.safety_filter import FilterStatus

#: Name of the safety filter's ``DiagnosticStatus``.
FILTER_DIAGNOSTIC = 'safety_filter'

#: Name of the nominal controller's ``DiagnosticStatus``.
NOMINAL_DIAGNOSTIC = 'nominal_controller'


class TickStatus(str, Enum):
    """The :attr:`Key.STATUS` value: how the u* published for a tick was obtained.

    The QP's own outcomes are the :class:`FilterStatus` values (the same strings); the
    endpoint adds the pass-through and the hold policy's two answers to bad or missing input.
    """

    NOMINAL = FilterStatus.NOMINAL.value
    SOLVED = FilterStatus.SOLVED.value
    RELAXED = FilterStatus.RELAXED.value
    FALLBACK_LAST_GOOD = FilterStatus.FALLBACK_LAST_GOOD.value
    FALLBACK_NOMINAL = FilterStatus.FALLBACK_NOMINAL.value
    DISABLED = 'disabled'
    """The filter is switched off: u* = u_nom (validated input)."""
    INPUT_HELD = 'input_held'
    """Input rejected or missing for at most ``input.hold_timeout``: the last safe u* again."""
    INPUT_FALLBACK = 'input_fallback'
    """Input rejected or missing for longer: the hold policy's fallback command."""
    GRASP_INVALID = 'grasp_invalid'
    """No state has passed the start-up grasp check yet: the fallback command, no QP."""
    GRASP_HELD = 'grasp_held'
    """A contact's gap or penetration is above tolerance for at most ``input.hold_timeout``
    since the last safe u*: that u* again, no QP."""
    GRASP_FALLBACK = 'grasp_fallback'
    """A contact's gap or penetration is above tolerance for longer: the fallback, no QP."""
    INPUT_IGNORED = 'input_ignored'
    """An input rejected where it answers no tick: before the first tick (no command has
    been computed yet, so none is sent) or a tracker sample (the ticks go on with the
    object's estimate). No command."""

    @classmethod
    def of(cls, status: FilterStatus) -> TickStatus:
        """Return the tick status of a QP outcome (or of a tick status: itself)."""
        of = _OF_FILTER_STATUS.get(status)
        return of if of is not None else cls(status.value)


#: :meth:`TickStatus.of`, looked up (an Enum call by value costs a tick a few microseconds).
_OF_FILTER_STATUS = {status: TickStatus(status.value) for status in FilterStatus}


#: The QP gave no usable answer: the filter's own fallback went out (an ERROR).
FAILED_STATUSES = frozenset({TickStatus.FALLBACK_LAST_GOOD, TickStatus.FALLBACK_NOMINAL})

#: The input was rejected or missing: no u* was computed, the hold policy answered.
INPUT_STATUSES = frozenset({TickStatus.INPUT_HELD, TickStatus.INPUT_FALLBACK})

#: The state is not a grasp (start-up check, or a contact lost at run time): no u* computed.
GRASP_STATUSES = frozenset(
    {TickStatus.GRASP_INVALID, TickStatus.GRASP_HELD, TickStatus.GRASP_FALLBACK}
)


class InputMode(Enum):
    """The hold policy's mode (:attr:`Key.INPUT_MODE`): how the last command was obtained."""

    OK = 'ok'
    HOLDING = 'holding'
    FALLBACK = 'fallback'


#: The tick status of each answer of the hold policy to rejected or missing input.
INPUT_MODE_STATUS: dict[InputMode, TickStatus] = {
    InputMode.HOLDING: TickStatus.INPUT_HELD,
    InputMode.FALLBACK: TickStatus.INPUT_FALLBACK,
}


class Key:
    """Keys of the ``safety_filter`` status's values (units in the comments)."""

    FILTER_ENABLED = 'filter.enabled'
    """``true`` while the filter filters, ``false`` while it passes u_nom through."""
    FILTER_SWITCHED_AT = 'filter.switched_at'
    """Node-clock time of the last switch on or off at run time, s (absent before any)."""
    STATUS = 'status'
    """A :class:`TickStatus` value."""
    SOLVE_TIME_US = 'solve_time_us'
    """The QP solve (hard and relaxed), µs."""
    STEP_TIME_US = 'step_time_us'
    """The whole filter step (``SafetyFilter.solve``: rows, QP, margins), µs."""
    TICK_TIME_US = 'tick_time_us'
    """The whole tick (model terms, filter step, messages), µs."""
    ITERATIONS = 'iterations'
    """OSQP iterations."""
    RELAXED = 'relaxed'
    """Whether the relaxed QP gave u*."""
    RELAXED_FAMILIES = 'relaxed_families'
    """Constraint families with a row given up, comma-separated."""
    MAX_VIOLATION = 'max_violation'
    """Largest row violation at u*, in the rows' own units."""
    ACTIVE = 'active'
    """Rows active at u*, comma-separated."""
    MIN_MARGIN_PREFIX = 'min_margin.'
    """Followed by a family name: its smallest barrier value h at u* (:func:`min_margin`)."""

    TICKS = 'ticks'
    """Ticks answered so far (every status counted, published or not)."""
    COUNT_PREFIX = 'count.'
    """Followed by a :class:`TickStatus` value: its ticks so far (:func:`status_count`)."""

    INPUT_MODE = 'input.mode'
    """An :class:`InputMode` value."""
    INPUT_FALLBACK = 'input.fallback'
    """The configured fallback (``zero`` or ``gravity_compensation``)."""
    INPUT_REJECTED_TICKS = 'input.rejected_ticks'
    """Ticks with rejected input so far."""
    INPUT_LAST_REJECTION = 'input.last_rejection'
    """Why the last rejected (or missing) input was (empty if none was)."""
    INPUT_TIME_SINCE_ACCEPTED = 'input.time_since_accepted'
    """Node-clock time since the last accepted tick, s (``inf`` before any)."""
    INPUT_TOPIC = 'input.topic'
    """On a rejected tick: the topic whose message was rejected (or ``state``)."""
    INPUT_IGNORED = 'input.ignored'
    """On an ``input_ignored`` status: the inputs rejected without a command so far."""
    INPUT_WATCHDOG = 'input.watchdog'
    """``true`` on the input watchdog's statuses (inputs missing), which answer no tick."""
    INPUT_MISSING = 'input.missing'
    """Watchdog: the topics with no message since the last accepted tick, comma-separated."""
    INPUT_WALL_TIME_SINCE_ACCEPTED = 'input.wall_time_since_accepted'
    """Watchdog: wall-clock time since the last accepted tick, s."""
    INPUT_SILENT_PREFIX = 'input.silent_for.'
    """Followed by a topic: wall-clock time since its last message, s (:func:`silent_for`)."""
    INPUT_RESUMED_AFTER = 'input.resumed_after'
    """On the first tick after the watchdog took over: wall-clock time without one, s."""

    GRASP_VALID = 'grasp.valid'
    """On a grasp status (filter or nominal controller): ``false``, the state is no grasp."""
    GRASP_CONTACTS = 'grasp.contacts'
    """The subjects that fail the grasp check (contacts, joints, ``hand``), comma-separated."""
    GRASP_FINDINGS = 'grasp.findings'
    """What fails, one finding per subject, ``; ``-separated (bounded)."""
    GRASP_GAP_TOLERANCE = 'grasp.gap_tolerance'
    """The largest admissible gap or penetration per contact, m."""


def min_margin(family: str) -> str:
    """Key of a constraint family's smallest barrier value."""
    return Key.MIN_MARGIN_PREFIX + family


def status_count(status: TickStatus) -> str:
    """Key of the number of ticks with ``status`` so far."""
    return Key.COUNT_PREFIX + status.value


def silent_for(topic: str) -> str:
    """Key of the wall-clock time since a topic's last message."""
    return Key.INPUT_SILENT_PREFIX + topic
