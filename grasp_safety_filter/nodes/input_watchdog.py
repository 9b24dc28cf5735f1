"""The safety filter's input watchdog: which inputs stopped, and for how long (wall clock).

A dead simulator, nominal controller or driver sends nothing, so no tick comes to be
answered. :class:`InputWatchdog` keeps the steady-clock times of the last message per
input topic and of the last answered tick; the endpoint
(:meth:`~grasp_safety_filter.nodes.safety_filter.SafetyFilterEndpoint.watchdog`) asks it
periodically whether the ticks stopped for longer than ``input.hold_timeout`` and, before
the first tick, whether a "waiting" report is due, and what it says (the inputs not
received yet, or the last rejection). Times are s on the caller's steady clock; the
ROS-free runner passes none and the watchdog never acts.

Once no tick has been answered for more than ``input.hold_timeout`` s of wall-clock time,
each call of the endpoint's watchdog returns the hold policy's fallback on
``/hand/effort_command`` and an ERROR status naming the inputs that stopped and for how
long; the first tick answered afterwards says how long the inputs were missing.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
import math

#: Wall-clock period of the watchdog's "waiting for a first tick" status before any tick, s.
WAITING_REPORT_PERIOD = 1.0

#: Period of the safety filter's input watchdog, s (steady clock): the fallback is repeated
#: at this period while the inputs stay away, which keeps a driver with a command timeout of
#: 20 ms fed.
WATCHDOG_PERIOD = 0.02

#: Why u_nom may be missing while the state arrives (the safety filter's reports say it).
NOMINAL_HINT = (
    'the nominal controller publishes u_nom only for the ticks it makes of its own inputs: '
    'see its status on /diagnostics'
)

#: What a watchdog says when every input arrives but no tick comes of them.
NO_TICK = 'inputs arrive, but no complete valid set of one stamp'


def _hint(hints: Mapping[str, str], topic: str) -> str:
    hint = hints.get(topic)
    return f' ({hint})' if hint else ''


def describe_missing(
    missing: Sequence[str], silent: Mapping[str, float] | None, hints: Mapping[str, str]
) -> str:
    """Say which inputs are silent (for how long, when known), with their hints."""
    if not missing:
        return NO_TICK
    if silent is None:
        return 'nothing on ' + ', '.join(f'{topic}{_hint(hints, topic)}' for topic in missing)
    return ', '.join(
        f'nothing on {topic} for {silent[topic]:.3f} s{_hint(hints, topic)}' for topic in missing
    )


@dataclass(frozen=True)
class Silence:
    """Inputs stopped: no tick answered for longer than the hold timeout.

    Attributes:
        elapsed: Wall-clock time since the last answered tick, s.
        missing: The topics (as the node named them) with no message since that tick.
        silent: Per topic, wall-clock time since its last message, s (``inf``: never).
        hints: Per topic, why it may be silent.

    """

    elapsed: float
    missing: list[str]
    silent: dict[str, float]
    hints: Mapping[str, str] = field(default_factory=dict)

    def describe(self) -> str:
        """Which inputs are silent, and for how long (and why they may be)."""
        return describe_missing(self.missing, self.silent, self.hints)


class InputWatchdog:
    """Wall-clock bookkeeping of the inputs and ticks (module docstring).

    Args:
        names: The input topics a tick needs, by table name: their names as the node
            resolved them (remapped), for the reports.
        hints: Per table name, why that input may be missing (said with it).
        wall_clock: The clock of the handlers' ``wall`` (``time.monotonic``), read when a
            tick is answered: the watchdog waits from the answer, so a slow tick is not
            followed by the fallback. None: a tick is dated by its last input's ``wall``.
        no_tick: What a "waiting" report says when every input arrives but no tick comes.

    """

    def __init__(
        self,
        names: Mapping[str, str],
        hints: Mapping[str, str] | None = None,
        wall_clock: Callable[[], float] | None = None,
        no_tick: str = NO_TICK,
    ) -> None:
        self.topics = tuple(names)
        self.names = dict(names)
        self.hints = {self.names[topic]: hint for topic, hint in (hints or {}).items()}
        self._wall_clock = wall_clock
        self._no_tick = no_tick
        self._last_rejection: str | None = None
        self._received: dict[str, float] = {}
        self._accepted: float | None = None
        self._since: float | None = None
        self._waiting_since: float | None = None
        self._waiting_reported = 0.0

    @property
    def started(self) -> bool:
        """Whether a tick has been answered (with a wall-clock time)."""
        return self._accepted is not None

    def received(self, topic: str, wall: float) -> None:
        """Record a message on ``topic`` (table name) at ``wall``, s."""
        self._received[topic] = wall

    def rejected(self, error: Exception) -> None:
        """Record a rejected input: the "waiting" report names the last one."""
        self._last_rejection = str(error)

    def _answered(self, wall: float) -> float:
        """Return when a tick whose last input came at ``wall`` is answered, s."""
        return wall if self._wall_clock is None else max(wall, self._wall_clock())

    def accepted(self, wall: float) -> float | None:
        """Record a tick whose last input came at ``wall``, s, answered (now, on the clock).

        Returns:
            The wall-clock time without one if the watchdog had taken over, s; else None.

        """
        wall = self._answered(wall)
        resumed_after = None
        if self._since is not None and self._accepted is not None:
            resumed_after = wall - self._accepted
            self._since = None
        self._accepted = wall
        return resumed_after

    def answered_again(self, wall: float) -> None:
        """Record the last tick answered again, its inputs in at ``wall``, s: they came again.

        A lockstep simulator that waited for its command in vain publishes its state again
        and is answered again: its inputs did not stop. Once the watchdog has taken over,
        only a new tick ends it (and says so).
        """
        if self._accepted is not None and self._since is None:
            self._accepted = self._answered(wall)

    def silence(self, now_wall: float, hold_timeout: float) -> Silence | None:
        """Return the silence if no tick came for more than ``hold_timeout`` s, else None.

        The watchdog takes over at the first silence; :meth:`accepted` ends it.
        """
        if self._accepted is None:
            return None
        elapsed = now_wall - self._accepted
        if elapsed <= hold_timeout:
            return None
        missing = [
            self.names[topic]
            for topic in self.topics
            if self._received.get(topic, -math.inf) <= self._accepted
        ]
        silent = {
            self.names[topic]: now_wall - self._received.get(topic, -math.inf)
            for topic in self.topics
        }
        if self._since is None:
            self._since = now_wall
        return Silence(elapsed, missing, silent, self.hints)

    def waiting(self, now_wall: float) -> tuple[float, list[str], str] | None:
        """Before any tick: every :data:`WAITING_REPORT_PERIOD` s, how long and for what.

        Returns:
            The wall-clock wait so far, s, the topics (as the node named them) not received
            yet, and what the first tick waits for (with their hints; with every input in,
            also the last rejection); None when no report is due (the first call only starts
            the wait).

        """
        if self._waiting_since is None:
            self._waiting_since = self._waiting_reported = now_wall
            return None
        if now_wall - self._waiting_reported < WAITING_REPORT_PERIOD:
            return None
        self._waiting_reported = now_wall
        missing = [self.names[topic] for topic in self.topics if topic not in self._received]
        if missing:
            what = describe_missing(missing, None, self.hints)
        else:
            what = self._no_tick
            if self._last_rejection is not None:
                what += f'; the last rejected: {self._last_rejection}'
        return now_wall - self._waiting_since, missing, what
