"""``sensor_msgs/JointState``: joint states and joint efforts, matched by joint name."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.errors import MessageError
from grasp_safety_filter.io.messages.fields import (
    array_field,
    match_names,
    unique_names,
)
from grasp_safety_filter.io.messages.namespace import MessageNamespace
from grasp_safety_filter.io.messages.stamps import (
    header_msg,
    nanoseconds_to_seconds,
    Stamp,
    time_msg_to_nanoseconds,
)


@dataclass(frozen=True)
class JointStateData:
    """A parsed ``/hand/joint_states`` sample, in the caller's joint order.

    Attributes:
        t: Header stamp, s.
        stamp_ns: Header stamp, integer ns (exact: what an answer to it is stamped with).
        position: Joint angles, shape (m,), rad.
        velocity: Joint velocities, shape (m,), rad/s.
        effort: Applied joint torques, shape (m,), N·m; None when the message has none
            (many hand drivers publish no effort; the filter does not need it).

    """

    t: float
    stamp_ns: int
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray | None


@dataclass(frozen=True)
class EffortData:
    """A parsed effort command, in the caller's joint order.

    Attributes:
        t: Header stamp, s.
        stamp_ns: Header stamp, integer ns.
        effort: Joint torques, shape (m,), N·m.

    """

    t: float
    stamp_ns: int
    effort: np.ndarray


#: The float fields of a JointState, in message order.
_FIELDS = ('position', 'velocity', 'effort')


def joint_state_to_msg(
    msgs: MessageNamespace,
    t: Stamp,
    names: Sequence[str],
    position: np.ndarray | None,
    velocity: np.ndarray | None,
    effort: np.ndarray | None,
    frame_id: str = '',
) -> Any:
    """Build a ``sensor_msgs/JointState``; ``None`` fields are sent empty.

    Args:
        msgs: Message classes.
        t: Stamp: integer ns, or s (:data:`~grasp_safety_filter.io.messages.fields.Stamp`).
        names: Joint names, one per array entry.
        position: Joint angles, rad.
        velocity: Joint velocities, rad/s.
        effort: Joint torques, N·m.
        frame_id: Header frame (empty for joint states by ROS convention).

    """
    name = unique_names('message', names, 'entry')
    fields = {
        field_name: (
            msgs.empty_float_array()
            if values is None
            else _sized_field(msgs, field_name, values, len(name))
        )
        for field_name, values in zip(_FIELDS, (position, velocity, effort), strict=True)
    }
    return msgs.JointState(header=header_msg(msgs, t, frame_id), name=list(name), **fields)


def _sized_field(msgs: MessageNamespace, field_name: str, values: Any, n_names: int) -> Any:
    """Return ``values`` as a message float array; raise MessageError unless one per name."""
    array = msgs.float_array(values)
    if len(array) != n_names:
        raise MessageError(
            f"message: '{field_name}' has {len(array)} entries, expected "
            f'{n_names} (one per name)'
        )
    return array


def joint_state_from_msg(
    msg: Any, joint_names: Sequence[str], source: str = 'JointState', others: bool = False
) -> JointStateData:
    """Parse a JointState carrying position and velocity (effort optional) of ``joint_names``.

    Args:
        msg: A ``sensor_msgs/JointState``.
        joint_names: Expected joints; the result follows this order.
        source: Name used in error messages (e.g. the topic).
        others: Joints not in ``joint_names`` are ignored (a ``joint_state_broadcaster``'s
            ``/joint_states`` carries every joint of the robot, an arm's too); their values
            are still checked, as the message's own. False: they are refused.

    Raises:
        MessageError: Duplicate, unknown (unless ``others``) or missing names; a field whose
            length is not the number of names; a non-finite value.

    """
    order = match_names(source, msg.name, joint_names, 'joint', others=others)
    names = list(msg.name)
    arrays = {
        f: array_field(source, getattr(msg, f), f, names, required=f != 'effort')
        for f in ('position', 'velocity', 'effort')
    }
    stamp_ns = time_msg_to_nanoseconds(msg.header.stamp, f'{source}: header.stamp')
    return JointStateData(
        t=nanoseconds_to_seconds(stamp_ns),
        stamp_ns=stamp_ns,
        **{f: None if a is None else a[order] for f, a in arrays.items()},
    )


def effort_to_msg(
    msgs: MessageNamespace, t: Stamp, names: Sequence[str], effort: np.ndarray
) -> Any:
    """Build a JointState with names and efforts (N·m) only: position and velocity empty."""
    return joint_state_to_msg(msgs, t, names, None, None, effort)


def effort_values(
    msg: Any, joint_names: Sequence[str], source: str = 'effort JointState'
) -> np.ndarray:
    """Return the efforts of an effort-only JointState of exactly ``joint_names``, N·m.

    Position and velocity may be empty or have one entry per name (then ignored but still
    checked to be finite, since a producer that sends them garbage is not trusted). The
    stamp is not read (a hand driver does not check it).

    Raises:
        MessageError: As :func:`joint_state_from_msg`.

    """
    order = match_names(source, msg.name, joint_names, 'joint')
    names = msg.name  # matched: a sequence of distinct names (its length and error texts)
    effort = array_field(source, msg.effort, 'effort', names, required=True)
    for f in ('position', 'velocity'):
        array_field(source, getattr(msg, f), f, names, required=False)
    return effort[order]


def effort_from_msg(
    msg: Any, joint_names: Sequence[str], source: str = 'effort JointState'
) -> EffortData:
    """Parse an effort-only JointState of exactly ``joint_names``: its efforts and stamp.

    Raises:
        MessageError: As :func:`effort_values`, or a stamp that is no time.

    """
    effort = effort_values(msg, joint_names, source)
    stamp_ns = time_msg_to_nanoseconds(msg.header.stamp, f'{source}: header.stamp')
    return EffortData(t=nanoseconds_to_seconds(stamp_ns), stamp_ns=stamp_ns, effort=effort)
