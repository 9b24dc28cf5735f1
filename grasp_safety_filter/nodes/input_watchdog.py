"""The safety filter's input watchdog: which inputs stopped, and for how long (wall clock).

A dead simulator, nominal controller or driver sends nothing, so no tick comes to be
answered. :class:`InputWatchdog` keeps the steady-clock times of the last message per
input topic and of the last answered tick; the endpoint
(:meth:`~grasp_safety_filter.nodes.safety_filter.SafetyFilterEndpoint.watchdog`) asks it
periodically whether the ticks stopped for longer than ``input.hold_timeout`` and, before
the first tick, whether a "waiting" report is due. Times are s on the caller's steady
clock; the ROS-free runner passes none and the watchdog never acts.

Once no tick has been answered for more than ``input.hold_timeout`` s of wall-clock time,
each call of the endpoint's watchdog returns the hold policy's fallback on
``/hand/effort_command`` and an ERROR status naming the inputs that stopped and for how
long; the first tick answered afterwards says how long the inputs were missing.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
import math

#: Wall-clock period of the watchdog's "waiting for a first tick" status before any tick, s.
WAITING_REPORT_PERIOD = 1.0


@dataclass(frozen=True)
class Silence:
    """Inputs stopped: no tick answered for longer than the hold timeout.

    Attributes:
        elapsed: Wall-clock time since the last answered tick, s.
        missing: The topics with no message since that tick.
        silent: Per topic, wall-clock time since its last message, s (``inf``: never).

    """

    elapsed: float
    missing: list[str]
    silent: dict[str, float]

    def describe(self) -> str:
        """Which inputs are silent, and for how long."""
        if self.missing:
            return ', '.join(
                f'nothing on {topic} for {self.silent[topic]:.3f} s' for topic in self.missing
            )
        return 'inputs arrive, but no complete valid set of one stamp'


class InputWatchdog:
    """Wall-clock bookkeeping of the inputs and ticks (module docstring).

    Args:
        topics: The input topics a tick needs.

    """

    def __init__(self, topics: Sequence[str]) -> None:
        self.topics = tuple(topics)
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
        """Record a message on ``topic`` at ``wall``, s."""
        self._received[topic] = wall

    def accepted(self, wall: float) -> float | None:
        """Record a tick answered at ``wall``, s.

        Returns:
            The wall-clock time without one if the watchdog had taken over, s; else None.

        """
        resumed_after = None
        if self._since is not None and self._accepted is not None:
            resumed_after = wall - self._accepted
            self._since = None
        self._accepted = wall
        return resumed_after

    def answered_again(self, wall: float) -> None:
        """Record the last tick answered again at ``wall``, s: its inputs came again.

        A lockstep simulator that waited for its command in vain publishes its state again
        and is answered again: its inputs did not stop. Once the watchdog has taken over,
        only a new tick ends it (and says so).
        """
        if self._accepted is not None and self._since is None:
            self._accepted = wall

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
            topic
            for topic in self.topics
            if self._received.get(topic, -math.inf) <= self._accepted
        ]
        silent = {topic: now_wall - self._received.get(topic, -math.inf) for topic in self.topics}
        if self._since is None:
            self._since = now_wall
        return Silence(elapsed, missing, silent)

    def waiting(self, now_wall: float) -> tuple[float, list[str]] | None:
        """Before any tick: every :data:`WAITING_REPORT_PERIOD` s, how long and for what.

        Returns:
            The wall-clock wait so far, s, and the topics not received yet; None when no
            report is due (the first call only starts the wait).

        """
        if self._waiting_since is None:
            self._waiting_since = self._waiting_reported = now_wall
            return None
        if now_wall - self._waiting_reported < WAITING_REPORT_PERIOD:
            return None
        self._waiting_reported = now_wall
        missing = [topic for topic in self.topics if topic not in self._received]
        return now_wall - self._waiting_since, missing
