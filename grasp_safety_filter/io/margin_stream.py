"""The compact ``/safety_filter/margins`` stream: row names only when needed.

Every tick's barrier values go out as a ``sensor_msgs/JointState`` whose ``position`` holds
``h`` per row (and ``velocity`` ``dh/dt`` when known, else empty). The row names (some 60
strings, 3/4 of the message) are sent only

- in the first message,
- whenever they change (a filter rebuilt with other constraint families),
- and at least once per :data:`NAMES_PERIOD` of stamps, so that a subscriber or recorder
  that joined late knows them within that time;

the other messages have an empty ``name``: their rows are those of the last message that
named them. :class:`MarginEncoder` makes such a stream (the filter endpoint),
:class:`MarginDecoder` reads it back (the analysis, monitors). A message with names is an
ordinary, self-describing JointState; only the nameless ones need the decoder.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages import (
    MarginData,
    margins_from_msg,
    margins_to_msg,
    MessageNamespace,
    seconds_to_nanoseconds,
    Stamp,
    stamp_nanoseconds,
)

#: Longest stamp interval between two margins messages that name their rows, s.
NAMES_PERIOD = 1.0


class MarginEncoder:
    """Builds the compact margins stream (module docstring) of one publisher."""

    def __init__(self, names_period: float = NAMES_PERIOD) -> None:
        """Start a stream: its first message names its rows.

        Args:
            names_period: Longest stamp interval between two messages with names, s.

        """
        self.names_period_ns = seconds_to_nanoseconds(names_period)
        self._names: tuple[str, ...] | None = None
        self._named_at_ns: int | None = None

    def encode(
        self,
        msgs: MessageNamespace,
        t: Stamp,
        names: Sequence[str],
        h: np.ndarray,
        h_dot: np.ndarray | None = None,
    ) -> Any:
        """Return the margins message of stamp ``t`` (ns, or s), with the names if they are due."""
        stamp = stamp_nanoseconds(t)
        same = names is self._names or (
            self._names is not None and tuple(names) == self._names
        )
        due = (
            not same
            or self._named_at_ns is None
            or not 0 <= stamp - self._named_at_ns < self.names_period_ns
        )
        if due:
            self._names = tuple(names) if not isinstance(names, tuple) else names
            self._named_at_ns = stamp
        return margins_to_msg(msgs, t, names, h, h_dot, with_names=due)


class MarginDecoder:
    """Reads a margins stream in order: remembers the rows of the last message with names.

    Attributes:
        names: The rows named last (None before the first message with names).
        skipped: Messages without names received before any with names (a late joiner's
            first messages): they cannot be read.

    """

    def __init__(self) -> None:
        """Start with no rows known."""
        self.names: tuple[str, ...] | None = None
        self.skipped = 0

    def decode(self, msg: Any, source: str = 'margins') -> MarginData | None:
        """Return the message's margins; None for a nameless one before any rows are known.

        Raises:
            MessageError: A malformed message (as :func:`margins_from_msg`; a nameless one
                must have one value per row known).

        """
        if len(msg.name) == 0 and len(msg.position) > 0 and self.names is None:
            self.skipped += 1
            return None
        data = margins_from_msg(msg, source=source, row_names=self.names)
        if len(msg.name):
            self.names = data.names
        return data
