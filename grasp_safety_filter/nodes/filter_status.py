"""The safety filter's ``/diagnostics`` status of a tick: level, summary and values.

:class:`~grasp_safety_filter.nodes.safety_filter.SafetyFilterEndpoint` publishes one
``safety_filter`` status (keys and values: :mod:`grasp_safety_filter.io.diagnostic_keys`)
per answered tick; this module turns a tick's outcome into it. ERROR when the QP gave no
usable answer, WARN when it was relaxed or the filter is off, OK otherwise.

Values on every tick: ``filter.enabled``, ``filter.switched_at`` (after a switch),
``status`` (a ``TickStatus``: ``nominal``, ``solved``, ``relaxed``,
``fallback_last_good``, ``fallback_nominal``, ``disabled``; ``input_held`` or
``input_fallback`` on a rejected input and on the watchdog's statuses; ``grasp_invalid``,
``grasp_held``, ``grasp_fallback`` on a state that is not a grasp, with the ``grasp.*``
values), ``solve_time_us`` (the QP solve, hard and relaxed), ``step_time_us``
(the whole filter step, ``SafetyFilter.solve``: rows, QP, margins), ``tick_time_us`` (the
whole tick: model terms, filter step, messages), ``iterations``, ``relaxed``,
``relaxed_families`` (comma-separated), ``max_violation``, ``active`` (comma-separated row
names), ``min_margin.<family>`` per constraint family, the publication counts and the hold
policy's ``input.*`` values.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any

from grasp_safety_filter.control.filter_result import FilterResult
from grasp_safety_filter.io.diagnostic_keys import (
    FAILED_STATUSES,
    FILTER_DIAGNOSTIC,
    Key,
    min_margin,
    TickStatus,
)
from grasp_safety_filter.io.messages import (
    DiagnosticLevel,
    MessageNamespace,
    Stamp,
)
from grasp_safety_filter.nodes.outgoing import diagnostic_status, Outgoing

_STATUS_TEXT: dict[TickStatus, str] = {
    TickStatus.NOMINAL: 'u* = u_nom: every constraint holds',
    TickStatus.SOLVED: 'QP solved',
    TickStatus.RELAXED: 'QP infeasible, relaxed',
    TickStatus.FALLBACK_LAST_GOOD: 'no QP solution: last good u*',
    TickStatus.FALLBACK_NOMINAL: 'no QP solution: u_nom clipped to the actuator limits',
}


def status_message(
    msgs: MessageNamespace,
    t: Stamp,
    enabled: bool,
    level: DiagnosticLevel,
    text: str,
    values: Mapping[str, Any],
) -> Outgoing:
    """Return the ``safety_filter`` status stamped ``t`` (ns, or s): enabled, ``values``."""
    values = {Key.FILTER_ENABLED: enabled, **values}
    return diagnostic_status(msgs, t, FILTER_DIAGNOSTIC, level, text, values)


@dataclass(frozen=True)
class TickContext:
    """The endpoint's values that go with a computed tick's status, in their key order.

    Attributes:
        switched_at: Node-clock time of the last switch on or off, s (None before any).
        counters: The publication counts (``ticks``, ``count.<status>``).
        hold_values: The hold policy's ``input.*`` values.
        resumed_after: On the first tick after the input watchdog took over: the
            wall-clock time without one, s (said, and at least WARN); else None.

    """

    switched_at: float | None
    counters: Mapping[str, Any]
    hold_values: Mapping[str, Any]
    resumed_after: float | None = None


def tick_status(
    result: FilterResult | None,
    margins: Mapping[str, float],
    step_time: float,
    tick_time: float,
    context: TickContext,
) -> tuple[DiagnosticLevel, str, dict[str, Any]]:
    """Level, summary and values of a computed tick.

    Args:
        result: The filter's result; None when the filter is off (u* = u_nom).
        margins: Barrier value h per row at u*.
        step_time: The filter step (``SafetyFilter.solve``), s.
        tick_time: The whole tick, s.
        context: The endpoint's values.

    """
    values: dict[str, Any] = {}
    if context.switched_at is not None:
        values[Key.FILTER_SWITCHED_AT] = context.switched_at
    if result is None:
        # Not an error, but nothing is enforced: say so at WARN on every tick.
        level, text = DiagnosticLevel.WARN, 'filter OFF: u* = u_nom, constraints not enforced'
        values[Key.STATUS] = TickStatus.DISABLED.value
        values[Key.SOLVE_TIME_US] = 0.0
        values[Key.ITERATIONS] = 0
        values[Key.RELAXED] = False
        values[Key.RELAXED_FAMILIES] = ''
        values[Key.MAX_VIOLATION] = 0.0
        values[Key.ACTIVE] = ''
    else:
        status = TickStatus.of(result.status)
        level, text = status_level_and_text(status, result.relaxed)
        if result.relaxed_families:
            text += ': ' + ', '.join(result.relaxed_families)
        values[Key.STATUS] = status.value
        values[Key.SOLVE_TIME_US] = result.solve_time * 1e6
        values[Key.ITERATIONS] = result.iterations
        values[Key.RELAXED] = result.relaxed
        values[Key.RELAXED_FAMILIES] = ','.join(result.relaxed_families)
        values[Key.MAX_VIOLATION] = result.max_violation
        values[Key.ACTIVE] = ','.join(result.active)
    values[Key.STEP_TIME_US] = step_time * 1e6
    values[Key.TICK_TIME_US] = tick_time * 1e6
    values.update(context.counters)
    values.update(min_margin_values(margins))
    values.update(context.hold_values)
    if context.resumed_after is not None:
        values[Key.INPUT_RESUMED_AFTER] = context.resumed_after
        resumed = context.resumed_after
        text += f'; inputs back after {resumed:.3f} s without a tick (watchdog ended)'
        level = max(level, DiagnosticLevel.WARN)
    return level, text, values


def status_level_and_text(status: TickStatus, relaxed: bool) -> tuple[DiagnosticLevel, str]:
    """Level and summary of a filter status: ERROR without a QP answer, WARN if relaxed."""
    if status in FAILED_STATUSES:
        level = DiagnosticLevel.ERROR
    elif relaxed:
        level = DiagnosticLevel.WARN
    else:
        level = DiagnosticLevel.OK
    return level, _STATUS_TEXT.get(status, f'QP {status.value}')


def min_margin_values(margins: Mapping[str, float]) -> dict[str, float]:
    """``min_margin.<family>``: the smallest barrier value per family (first name component)."""
    smallest: dict[str, float] = {}
    for name, h in margins.items():
        family = name.split('/', 1)[0]
        smallest[family] = min(smallest.get(family, math.inf), h)
    return {min_margin(family): h for family, h in smallest.items()}
