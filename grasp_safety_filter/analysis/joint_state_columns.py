"""A ``sensor_msgs/JointState`` topic's fields packed per message, checked once at the end.

A run's ``/hand/joint_states``, ``/hand/contacts`` and effort topics send the same names
in every message. Parsing each message on its own (``joint_state_from_msg``,
``contacts_from_msg``, ``effort_from_msg``: match the names, check each field) costs tens
of µs a message; :class:`JointStateColumns` instead keeps each message's stamp and fields
packed (:class:`~grasp_safety_filter.analysis.columns.Column`) and checks them all at once
in :meth:`JointStateColumns.rows`.

It is a fast path only: a topic whose messages are not all as expected (other or
reordered names, a field of another length, a value that is not finite, a bad stamp)
raises :class:`UnusualMessagesError`, and the caller reads the bag again with the
per-message parsers, which give the result or the error of a message-by-message read.
What it accepts, those parsers accept, with the same numbers.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from grasp_safety_filter.analysis.columns import Column
from grasp_safety_filter.io.messages import match_names, MessageError, NANOSECONDS_PER_SECOND

#: The fields of a JointState, in message order.
FIELDS = ('position', 'velocity', 'effort')


class UnusualMessagesError(Exception):
    """Messages the packed path does not take: read them with the per-message parsers."""


class JointStateColumns:
    """One JointState topic's messages, packed (module docstring).

    Args:
        source: The topic (the parsers' ``source``).
        expected_names: The names the analysis reads, in its order.
        kind: The names' kind in the parsers' messages (``"joint"``, ``"contact entry"``).
        required: Per field of :data:`FIELDS`, whether it must have one entry per name
            (else it may also be empty).

    """

    def __init__(
        self, source: str, expected_names: Sequence[str], kind: str, required: Sequence[bool]
    ) -> None:
        self.source, self.kind = source, kind
        self.expected_names = tuple(expected_names)
        self.required = tuple(required)
        self.names: list[str] | None = None
        self.unusual = False
        self.sec = Column((), np.int64)
        self.nanosec = Column((), np.int64)
        self.fields: list[Column] | None = None
        self.sizes = [0, 0, 0]  # per field: 0 (all empty so far) or len(names)

    def __len__(self) -> int:
        """Return the number of messages added."""
        return len(self.sec)

    def add(self, msg: Any) -> None:
        """Keep one message's stamp and fields (marks the topic unusual if they differ)."""
        if self.unusual:
            return
        names = msg.name
        if self.names is None:
            self.names = list(names)
            self.fields = [Column((len(names),)) for _ in FIELDS]
        elif names != self.names:
            self.unusual = True
            return
        n = len(names)
        count = len(self)
        for i, values in enumerate((msg.position, msg.velocity, msg.effort)):
            size = len(values)
            if size == n and (self.sizes[i] == n or count == 0 or not n):
                self.sizes[i] = n
                self.fields[i].append(values)  # type: ignore[index]
            elif size != 0 or self.required[i] or self.sizes[i]:
                self.unusual = True  # a length the parsers refuse, or mixed lengths
                return
        stamp = msg.header.stamp
        self.sec.append(stamp.sec)
        self.nanosec.append(stamp.nanosec)

    def rows(
        self, allow_positive_inf: Sequence[bool] | None = None
    ) -> tuple[np.ndarray, list[np.ndarray | None]]:
        """Return the stamps, ns (M,), and each field in the expected names' order.

        Args:
            allow_positive_inf: Per received name, whether ``+inf`` is admissible in
                ``position`` (as the parsers' ``allow_positive_inf``).

        Returns:
            Stamps (M,) and, per field of :data:`FIELDS`, its values (M, len(names)) or None
            where every message left it empty.

        Raises:
            UnusualMessagesError: The messages are not all as the parsers take them.

        """
        if self.unusual:
            raise UnusualMessagesError(self.source)
        if self.names is None or self.fields is None:  # no message: no rows
            empty = np.zeros((0, len(self.expected_names)))
            return np.zeros(0, np.int64), [empty, empty, empty]
        try:
            order = match_names(self.source, self.names, self.expected_names, self.kind)
        except MessageError:
            raise UnusualMessagesError(self.source) from None
        sec, nanosec = self.sec.array(), self.nanosec.array()
        if (sec < 0).any() or (nanosec < 0).any() or (nanosec >= NANOSECONDS_PER_SECOND).any():
            raise UnusualMessagesError(self.source)
        fields: list[np.ndarray | None] = []
        for i, column in enumerate(self.fields):
            if not self.sizes[i] and not len(column):
                fields.append(None)
                continue
            values = column.array()
            good = np.isfinite(values)
            if i == 0 and allow_positive_inf is not None:
                good |= np.asarray(allow_positive_inf, dtype=bool) & (values == np.inf)
            if not good.all():
                raise UnusualMessagesError(self.source)
            fields.append(values[:, order])
        return sec * NANOSECONDS_PER_SECOND + nanosec, fields
