"""Times in messages (``builtin_interfaces``, integer ns, float s) and input stamp checks."""

from __future__ import annotations

from fractions import Fraction
import math
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.errors import (
    FutureStampError,
    MessageError,
    OutOfOrderError,
    StaleInputError,
)
from grasp_safety_filter.io.messages.namespace import MessageNamespace

NANOSECONDS_PER_SECOND = 1_000_000_000
"""Nanoseconds per second (a stamp is ``sec * NANOSECONDS_PER_SECOND + nanosec``)."""
_INT32_MAX = 2**31 - 1

#: The last float converted by :func:`seconds_to_nanoseconds` and its ns: one tick's
#: stamp is converted for each input checked and each message built (one tuple: replaced
#: whole, so a reader in another thread never pairs a time with another's ns).
_LAST_CONVERSION: tuple[float, int] = (0.0, 0)


def seconds_to_nanoseconds(t: float) -> int:
    """Time in s to the nearest integer ns; raise MessageError unless finite and >= 0."""
    global _LAST_CONVERSION
    last = _LAST_CONVERSION
    if t.__class__ is float and t == last[0]:
        return last[1]
    if not math.isfinite(t) or t < 0.0:
        raise MessageError(f'time: expected a finite number of seconds >= 0, got {t!r}')
    # Exact rational product: a float product could round a time ns / 1e9 to ns +- 1.
    if not isinstance(t, float):
        return round(Fraction(t) * NANOSECONDS_PER_SECOND)
    # A float is numerator / 2**k exactly: the same product and rounding (half to even,
    # as round(Fraction)) in integers, without building Fractions.
    numerator, denominator = t.as_integer_ratio()
    ns, remainder = divmod(numerator * NANOSECONDS_PER_SECOND, denominator)
    twice = 2 * remainder
    if twice > denominator or (twice == denominator and ns & 1):
        ns += 1
    _LAST_CONVERSION = (t, ns)
    return ns


def nanoseconds_to_seconds(ns: int) -> float:
    """Time in integer ns to s, correctly rounded (int / int true division)."""
    return int(ns) / NANOSECONDS_PER_SECOND


#: A time as the message builders take it: a stamp in integer ns (an ``int``, passed on
#: exactly: a command answers a state with the state's own stamp) or a time in float s
#: (simulation time, exact to the ns below 2**23 s; at today's epoch a float in s resolves
#: only about 0.24 us, so wall-clock stamps travel as ns).
Stamp = int | float


def stamp_nanoseconds(t: Stamp) -> int:
    """Return a :data:`Stamp` in integer ns: an ``int`` as it is, a float (s) rounded.

    Raises:
        MessageError: A negative ns, or a time that :func:`seconds_to_nanoseconds` refuses.

    """
    if isinstance(t, int | np.integer) and not isinstance(t, bool):
        if t < 0:
            raise MessageError(f'stamp: expected integer ns >= 0, got {t}')
        return int(t)
    return seconds_to_nanoseconds(t)


def _sec_nanosec(t: Stamp, what: str) -> tuple[int, int]:
    ns = stamp_nanoseconds(t)
    sec, nanosec = divmod(ns, NANOSECONDS_PER_SECOND)
    if sec > _INT32_MAX:
        raise MessageError(f'{what}: {t!r} s does not fit builtin_interfaces (int32 seconds)')
    return sec, nanosec


def time_to_msg(msgs: MessageNamespace, t: Stamp) -> Any:
    """Return ``t`` (a :data:`Stamp`, >= 0) as ``builtin_interfaces/Time``."""
    sec, nanosec = _sec_nanosec(t, 'time')
    return msgs.Time(sec=sec, nanosec=nanosec)


def time_msg_to_nanoseconds(msg: Any, what: str = 'time') -> int:
    """Return a ``builtin_interfaces`` Time or Duration as integer ns.

    Raises:
        MessageError: ``nanosec`` outside ``[0, 1e9)`` or ``sec`` negative (no time here
            is before the clock's origin, and seconds_to_nanoseconds refuses it).

    """
    sec, nanosec = int(msg.sec), int(msg.nanosec)
    if not 0 <= nanosec < NANOSECONDS_PER_SECOND:
        raise MessageError(f'{what}: nanosec must be in [0, 1e9), got {nanosec}')
    if sec < 0:
        raise MessageError(f'{what}: sec must be >= 0, got {sec}')
    return sec * NANOSECONDS_PER_SECOND + nanosec


def time_from_msg(msg: Any, what: str = 'time') -> float:
    """Return a ``builtin_interfaces`` Time or Duration in s."""
    return nanoseconds_to_seconds(time_msg_to_nanoseconds(msg, what))


def header_stamp_ns(msg: Any) -> int:
    """Return the header stamp of a stamped message in integer ns (e.g. a bag timestamp)."""
    return time_msg_to_nanoseconds(msg.header.stamp, 'header.stamp')


def header_msg(msgs: MessageNamespace, t: Stamp, frame_id: str) -> Any:
    """Build a ``std_msgs/Header`` stamped ``t`` (a :data:`Stamp`) in ``frame_id``."""
    return msgs.Header(stamp=time_to_msg(msgs, t), frame_id=frame_id)


def duration_to_msg(msgs: MessageNamespace, t: float) -> Any:
    """Build a ``builtin_interfaces/Duration`` of ``t`` s (a point's ``time_from_start``)."""
    sec, nanosec = _sec_nanosec(t, 'time_from_start')
    return msgs.Duration(sec=sec, nanosec=nanosec)


def clock_to_msg(msgs: MessageNamespace, t: Stamp) -> Any:
    """Build a ``rosgraph_msgs/Clock`` at ``t`` (a :data:`Stamp`)."""
    return msgs.Clock(clock=time_to_msg(msgs, t))


def clock_from_msg(msg: Any) -> float:
    """Return the time of a Clock message, s."""
    return time_from_msg(msg.clock, 'clock')


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
