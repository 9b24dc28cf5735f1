"""``grasp-bench-realtime``'s figures, from what the processes of one run recorded.

Pure arithmetic on the records (:class:`RunRecords`), so that it is tested on synthetic
ones. Every stamp and receipt is ``time.time_ns()`` of the same machine: a state's stamp
is the driver's clock when it published it, a receipt the monitor's clock when the message
came in. The first ``warm_up_ns`` of the run are left out of every figure (start-up: the
tracker's first samples, the first ticks, DDS settling); the run starts with the first state
or, for a plant that stands still until its first command (the simulator's hardware mode),
with the first state answered (``start_ns``).

- **Periods**: the states published in the measured window.
- **Computed**: periods answered by a command stamped as their state that is not a hold or
  a fallback. The filter publishes every status that is not steady
  (:data:`~grasp_safety_filter.nodes.publication_rate.STEADY_STATUSES`) at once, stamped as
  the tick, so the ticks with :data:`NOT_COMPUTED` statuses are known exactly; the
  watchdog's statuses (``input.watchdog``) answer no period.
- **Latency**: receipt - stamp of the commands stamped as a state, and of the relay's copy
  of each state (the baseline: one bare rclpy hop more, as the filter's command).
- **Late periods**: commands that arrived after the next state's stamp plus the relay's
  median latency (the next state was already on its way to the filter: a tick that ended
  after the next began), and the driver's publications more than half a period late.
- **CPU per tick**: each process's user + system CPU time between the first and last
  readings inside the window, over the periods published between them.
"""

from __future__ import annotations

from bisect import bisect_left, bisect_right
from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grasp_safety_filter.io.diagnostic_keys import (
    FAILED_STATUSES,
    GRASP_STATUSES,
    INPUT_STATUSES,
)
from grasp_tools.bench_ros_graph import percentiles

#: Tick statuses whose command was not computed for its state: held or fallback commands
#: of the hold policy (rejected or missing input, no grasp) and the filter's own fallback
#: when the QP gave no answer.
NOT_COMPUTED = frozenset(s.value for s in INPUT_STATUSES | GRASP_STATUSES | FAILED_STATUSES)


@dataclass(frozen=True)
class FilterStatusRecord:
    """A ``safety_filter`` status as the monitor received it.

    Attributes:
        stamp: Header stamp, ns (the tick's state's, or the watchdog's now).
        status: Its ``status`` value (a ``TickStatus``; empty if it has none).
        watchdog: An input watchdog status (inputs missing): it answers no period.
        tick_time_us: Its ``tick_time_us`` value, µs (None if it has none).
    """

    stamp: int
    status: str
    watchdog: bool = False
    tick_time_us: float | None = None


@dataclass
class RunRecords:
    """What one run's processes recorded.

    Attributes:
        period_ns: The driver's period, ns.
        warm_up_ns: Left out of every figure from the first state's stamp on, ns.
        states: Stamps of the states published, ns, in order.
        commands: ``(stamp, receipt)`` of each ``/hand/effort_command`` received, ns.
        relay: ``(stamp, receipt)`` of each relayed state received, ns.
        statuses: The filter's statuses received.
        driver_lateness: Per state, how late the driver published it after its due time,
            ns (None: the driver records none, e.g. the simulator's hardware mode).
        cpu_samples: ``(time.time_ns(), {process: CPU s so far})`` readings, in order.
        start_ns: Where the run starts, ns (None: at the first state).
    """

    period_ns: int
    warm_up_ns: int
    states: Sequence[int]
    commands: Sequence[tuple[int, int]]
    relay: Sequence[tuple[int, int]]
    statuses: Sequence[FilterStatusRecord] = ()
    driver_lateness: Sequence[int] | None = None
    cpu_samples: Sequence[tuple[int, Mapping[str, float]]] = field(default_factory=list)
    start_ns: int | None = None


def first_receipts(received: Sequence[tuple[int, int]]) -> dict[int, int]:
    """Return each stamp's first receipt, ns (a stamp received twice counts once)."""
    first: dict[int, int] = {}
    for stamp, receipt in received:
        if stamp not in first or receipt < first[stamp]:
            first[stamp] = receipt
    return first


def window(records: RunRecords) -> tuple[int, int]:
    """Return the measured window of stamps, ns: from the end of the warm-up to the last state.

    Raises:
        ValueError: No state was published.
    """
    if not records.states:
        raise ValueError('no state was published: nothing to measure')
    start = records.states[0] if records.start_ns is None else records.start_ns
    return start + records.warm_up_ns, records.states[-1]


def _ms(values_ns: Sequence[int]) -> dict[str, float | None]:
    """Return :func:`percentiles` of durations given in ns, in ms."""
    return percentiles([v / 1e6 for v in values_ns])


def _ratio(a: float | None, b: float | None) -> float | None:
    """Return a / b (None when either is missing or b is 0)."""
    return a / b if a is not None and b else None


def cpu_per_tick(
    samples: Sequence[tuple[int, Mapping[str, float]]],
    states: Sequence[int],
    start: int,
    end: int,
) -> dict[str, float]:
    """Return each process's CPU time per period over the window, ms.

    Args:
        samples: ``(time ns, {process: CPU s so far})``, in time order.
        states: State stamps, ns, in order (the periods).
        start: Window start, ns.
        end: Window end, ns.

    Returns:
        ``{process: ms}`` over the first and last readings inside the window, for the
        processes read at both; empty if fewer than two readings fall inside or no period
        was published between them.
    """
    inside = [(t, cpu) for t, cpu in samples if start <= t <= end]
    if len(inside) < 2:
        return {}
    (t_a, cpu_a), (t_b, cpu_b) = inside[0], inside[-1]
    periods = bisect_right(states, t_b) - bisect_right(states, t_a)
    if periods <= 0:
        return {}
    return {name: 1e3 * (cpu_b[name] - cpu_a[name]) / periods for name in cpu_a if name in cpu_b}


def figures(records: RunRecords) -> dict[str, Any]:
    """Return the run's figures as the module docstring defines them, JSON-ready; times in ms.

    Raises:
        ValueError: No state was published.
    """
    start, end = window(records)
    states = list(records.states)
    first = bisect_left(states, start)
    measured = states[first:]
    measured_set = set(measured)
    commands = first_receipts(records.commands)
    relay = first_receipts(records.relay)
    statuses = [s for s in records.statuses if s.stamp in measured_set and not s.watchdog]
    not_computed = {s.stamp for s in statuses if s.status in NOT_COMPUTED}
    answered = [s for s in measured if s in commands]
    computed = [s for s in answered if s not in not_computed]
    latency = [commands[s] - s for s in answered]
    relay_latency = [relay[s] - s for s in measured if s in relay]
    command_ms = _ms(latency)
    relay_ms = _ms(relay_latency)
    # In integer ns: a stamp of today's epoch plus a float would resolve 256 ns only.
    relay_median_ns = round(float(np.median(relay_latency))) if relay_latency else None
    late = 0
    if relay_median_ns is not None:
        for k in range(first, len(states) - 1):
            stamp = states[k]
            if stamp in commands and commands[stamp] > states[k + 1] + relay_median_ns:
                late += 1
    periods = len(measured)
    driver_late = None
    if records.driver_lateness is not None:
        lateness = list(records.driver_lateness)[first:]
        driver_late = sum(1 for ns in lateness if ns > records.period_ns / 2)
    tick_times = [
        s.tick_time_us / 1e3
        for s in records.statuses
        if (s.stamp in measured_set and s.tick_time_us is not None)
    ]
    other_commands = sum(1 for stamp in commands if start <= stamp <= end) - len(answered)
    return {
        'periods': periods,
        'periods_published': len(states),
        'warm_up_s': records.warm_up_ns / 1e9,
        'window_s': (end - start) / 1e9,
        'period_ms': records.period_ns / 1e6,
        'answered': len(answered),
        'computed': len(computed),
        'computed_share': _ratio(len(computed), periods),
        'held_or_fallback': len(not_computed),
        'unanswered': periods - len(answered),
        'other_commands': other_commands,
        'statuses': dict(Counter(s.status for s in statuses)),
        'state_to_command_ms': command_ms,
        'relay_ms': relay_ms,
        'median_over_relay': _ratio(command_ms['median'], relay_ms['median']),
        'p99_over_relay': _ratio(command_ms['p99'], relay_ms['p99']),
        'late_periods': late,
        'late_share': _ratio(late, periods),
        'driver_late_periods': driver_late,
        'filter_tick_ms': percentiles(tick_times),
        'cpu_ms_per_tick': cpu_per_tick(records.cpu_samples, states, start, end),
    }
