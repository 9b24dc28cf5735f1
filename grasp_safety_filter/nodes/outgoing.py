"""What an endpoint hands back: the messages to publish, in order, each with its bag stamp.

Every node of the package is split into a message-level *endpoint* (pure Python: parses
input messages, calls the cores, builds output messages) and a thin rclpy shell. An
endpoint's methods return a list of :class:`Outgoing`; the rclpy shell publishes each
``msg`` on ``topic`` in list order, and the ROS-free runner writes it to the bag at
``stamp_ns`` and hands it to the subscribers' endpoints. Both therefore see the same
message stream.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any, NamedTuple

from grasp_safety_filter.io.messages import (
    DiagnosticLevel,
    DiagnosticReport,
    diagnostics_to_msg,
    header_stamp_ns,
    MessageNamespace,
    Stamp,
    time_msg_to_nanoseconds,
)
from grasp_safety_filter.io.topics import DIAGNOSTICS


class Outgoing(NamedTuple):
    """One message to publish.

    Attributes:
        topic: Absolute topic name (a key of :data:`grasp_safety_filter.io.topics.TOPICS`).
        stamp_ns: The message's time, integer ns: its header stamp, the clock of a
            ``rosgraph_msgs/Clock``, or the run start for unstamped messages. The runner
            uses it as the bag timestamp.
        msg: The message, of the namespace's classes (rclpy or rosbags).

    """

    topic: str
    stamp_ns: int
    msg: Any


def stamped(topic: str, msg: Any) -> Outgoing:
    """Wrap a stamped message (a ``header`` or a ``rosgraph_msgs/Clock``) with its stamp."""
    if hasattr(msg, 'header'):
        return Outgoing(topic, header_stamp_ns(msg), msg)
    return Outgoing(topic, time_msg_to_nanoseconds(msg.clock, 'clock'), msg)


def diagnostic_status(
    msgs: MessageNamespace,
    t: Stamp,
    name: str,
    level: DiagnosticLevel,
    text: str,
    values: Mapping[str, Any],
) -> Outgoing:
    """Return ``/diagnostics`` with one status ``name`` stamped ``t`` (integer ns, or s)."""
    report = DiagnosticReport.create(name, level, text, values)
    return stamped(DIAGNOSTICS, diagnostics_to_msg(msgs, t, report))
