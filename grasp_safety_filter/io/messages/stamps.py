"""Input stamps: stale, future and out-of-order stamps rejected per topic."""

from __future__ import annotations

import math

from grasp_safety_filter.io.messages.errors import (
    FutureStampError,
    MessageError,
    OutOfOrderError,
    StaleInputError,
)


class StampGuard:
    """Rejects stale, future and out-of-order input stamps, per topic.

    A stamp is stale when ``stamp < now - max_age``, in the future when
    ``stamp > now + max_age`` (a clock error or a garbled stamp: accepted, it would make
    every later valid message look out of order), and out of order when it is strictly
    older than the last stamp accepted on the same topic (an equal stamp is accepted: a
    repeated sample is not a reordering). A last accepted stamp that is itself in the
    future of ``now`` (possible only when ``now`` was not a clock, e.g. the stamp of a
    first message) is no reference: it is forgotten.
    """

    def __init__(self, max_age: float) -> None:
        """Create a guard.

        Args:
            max_age: Largest admissible age of an input, s, > 0.

        """
        if not math.isfinite(max_age) or max_age <= 0.0:
            raise ValueError(f'max_age: expected a finite number > 0 s, got {max_age!r}')
        self.max_age = float(max_age)
        self._last: dict[str, float] = {}

    def accept(self, topic: str, stamp: float, now: float) -> None:
        """Check ``stamp`` (s) against ``now`` (s) and the topic's last stamp; record it.

        Raises:
            StaleInputError: The stamp is older than ``now - max_age``.
            FutureStampError: The stamp is later than ``now + max_age``.
            OutOfOrderError: The stamp is older than the last one accepted on ``topic``.
            MessageError: ``stamp`` or ``now`` is not finite.

        """
        if not (math.isfinite(stamp) and math.isfinite(now)):
            raise MessageError(f'{topic}: stamp {stamp!r} s and now {now!r} s must be finite')
        if stamp < now - self.max_age:
            raise StaleInputError(
                f'{topic}: stale stamp {stamp:.9f} s at now {now:.9f} s (age '
                f'{now - stamp:.9f} s > max_age {self.max_age} s)'
            )
        if stamp > now + self.max_age:
            raise FutureStampError(
                f'{topic}: future stamp {stamp:.9f} s at now {now:.9f} s (ahead by '
                f'{stamp - now:.9f} s > max_age {self.max_age} s)'
            )
        last = self._last.get(topic)
        if last is not None and last > now + self.max_age:
            last = None  # accepted against a stamp, not a clock: no reference now
        if last is not None and stamp < last:
            raise OutOfOrderError(
                f'{topic}: out-of-order stamp {stamp:.9f} s, older than the last accepted '
                f'{last:.9f} s'
            )
        self._last[topic] = float(stamp)

    def last_stamp(self, topic: str) -> float | None:
        """Return the last stamp accepted on ``topic``, s, or None."""
        return self._last.get(topic)

    def reset(self) -> None:
        """Forget every topic's last stamp (e.g. after a simulation reset)."""
        self._last.clear()
