"""``trajectory_msgs/MultiDOFJointTrajectory``: the object reference from a planner."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.errors import MessageError, name_list
from grasp_safety_filter.io.messages.fields import (
    check_frame,
    finite_vector,
    match_names,
    matrix_from_quaternion_xyzw,
    PALM_FRAME,
    quaternion_msg,
    shaped_array,
    twist_from_msg,
    twist_msg,
    unit_quaternion,
    vector3_msg,
)
from grasp_safety_filter.io.messages.namespace import MessageNamespace
from grasp_safety_filter.io.messages.stamps import (
    duration_to_msg,
    header_msg,
    time_from_msg,
)

REFERENCE_JOINT = 'object'

# ----------------------------------------------------------------------------------------
# Object reference


@dataclass(frozen=True)
class ObjectReference:
    """A desired object state, palm frame.

    Attributes:
        p_object_in_palm: Desired centre of mass, shape (3,), m.
        R_object_to_palm: Desired orientation, shape (3, 3).
        twist_object: Desired ``(v_o, w_o)`` in palm coordinates, shape (6,).
        acceleration_object: Desired ``(a_o, alpha_o)`` in palm coordinates, shape (6,).

    """

    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    twist_object: np.ndarray
    acceleration_object: np.ndarray


@dataclass(frozen=True)
class ReferenceTrajectory:
    """A parsed ``/object/reference``: points held piecewise constant in time.

    Attributes:
        t: Header stamp (start of the trajectory), s.
        time_from_start: Point times relative to ``t``, shape (k,), strictly increasing, s.
        points: The k references.

    """

    t: float
    time_from_start: np.ndarray
    points: tuple[ObjectReference, ...]

    def active_index(self, t: float) -> int:
        """Index of the last point with ``time_from_start <= t - self.t``, or 0 (the first)."""
        return max(int(np.searchsorted(self.time_from_start, t - self.t, side='right')) - 1, 0)

    def sample(self, t: float) -> ObjectReference:
        """Return the point in force at ``t`` (:meth:`active_index`)."""
        return self.points[self.active_index(t)]


def reference_to_msg(
    msgs: MessageNamespace,
    t: float,
    time_from_start: Sequence[float],
    points: Sequence[ObjectReference],
    frame_id: str = PALM_FRAME,
) -> Any:
    """Build a ``trajectory_msgs/MultiDOFJointTrajectory`` of the single joint ``"object"``.

    Each point holds one transform (the object pose in ``frame_id``), one twist
    ``(v_o, w_o)`` and one acceleration ``(a_o, alpha_o)``, all in ``frame_id``
    coordinates (the object origin's linear velocity and acceleration, not
    body-frame quantities).

    Args:
        msgs: Message classes.
        t: Header stamp, the trajectory start, s.
        time_from_start: Point times relative to ``t``, s, strictly increasing.
        points: One reference per time.
        frame_id: Reference frame.

    """
    if len(time_from_start) != len(points) or not points:
        raise MessageError(
            f'reference: expected one time_from_start per point and at least one point, got '
            f'{len(time_from_start)} times and {len(points)} points'
        )
    point_msgs = []
    for tau, ref in zip(time_from_start, points, strict=True):
        p = shaped_array('reference p_object_in_palm', ref.p_object_in_palm, (3,))
        R = shaped_array('reference R_object_to_palm', ref.R_object_to_palm, (3, 3))
        twist = shaped_array('reference twist_object', ref.twist_object, (6,))
        acceleration = shaped_array('reference acceleration_object', ref.acceleration_object, (6,))
        transform = msgs.Transform(
            translation=vector3_msg(msgs, p), rotation=quaternion_msg(msgs, R)
        )
        point_msgs.append(
            msgs.MultiDOFJointTrajectoryPoint(
                transforms=[transform],
                velocities=[twist_msg(msgs, twist)],
                accelerations=[twist_msg(msgs, acceleration)],
                time_from_start=duration_to_msg(msgs, float(tau)),
            )
        )
    return msgs.MultiDOFJointTrajectory(
        header=header_msg(msgs, t, frame_id), joint_names=[REFERENCE_JOINT], points=point_msgs
    )


#: Most points an object reference may hold. Parsing costs ~50 us a point in the
#: subscriber's callback, which the controller's tick waits for: 1000 points (10 s at
#: 100 Hz) take ~50 ms; a longer plan is sent in pieces.
MAX_REFERENCE_POINTS = 1000


def reference_from_msg(
    msg: Any, frame_id: str = PALM_FRAME, source: str = 'reference'
) -> ReferenceTrajectory:
    """Parse an object reference trajectory.

    The joint ``"object"`` must appear exactly once in ``joint_names`` (no other joints).
    Per point, ``transforms`` has one entry per joint; ``velocities`` and
    ``accelerations`` have one entry per joint or are empty (then zero).

    Raises:
        MessageError: Wrong frame or joints; no points or more than
            :data:`MAX_REFERENCE_POINTS` (refused before any is read); wrong per-point
            lengths; non-finite values; a non-unit quaternion; negative or non-increasing
            ``time_from_start``.

    """
    check_frame(source, 'header.frame_id', msg.header.frame_id, frame_id)
    (j,) = match_names(source, msg.joint_names, [REFERENCE_JOINT], 'joint')
    n_joints = len(msg.joint_names)
    if not msg.points:
        raise MessageError(f'{source}: expected at least one point, got none')
    if len(msg.points) > MAX_REFERENCE_POINTS:
        raise MessageError(
            f'{source}: expected at most {MAX_REFERENCE_POINTS} points '
            f'(MAX_REFERENCE_POINTS), got {len(msg.points)}: send a longer plan in pieces'
        )
    times, points = [], []
    for k, point in enumerate(msg.points):
        where = f'{source}: point {k}'
        lengths = {
            f: len(getattr(point, f)) for f in ('transforms', 'velocities', 'accelerations')
        }
        for f, length in lengths.items():
            allowed = (n_joints,) if f == 'transforms' else (0, n_joints)
            if length not in allowed:
                raise MessageError(
                    f"{where}: '{f}' has {length} entries, expected "
                    f'{" or ".join(map(str, allowed))} (joints {name_list(msg.joint_names)})'
                )
        transform = point.transforms[j]
        translation = transform.translation
        p = finite_vector(where, 'translation', (translation.x, translation.y, translation.z))
        quaternion = unit_quaternion(where, 'rotation', transform.rotation)
        twist = (
            twist_from_msg(where, 'velocity', point.velocities[j])
            if lengths['velocities']
            else np.zeros(6)
        )
        acceleration = (
            twist_from_msg(where, 'acceleration', point.accelerations[j])
            if lengths['accelerations']
            else np.zeros(6)
        )
        tau = time_from_msg(point.time_from_start, f'{where}: time_from_start')
        if tau < 0.0 or (times and tau <= times[-1]):
            raise MessageError(
                f'{where}: time_from_start must be >= 0 and strictly increasing, got {tau!r} '
                f'after {times[-1] if times else None!r}'
            )
        times.append(tau)
        points.append(
            ObjectReference(
                p_object_in_palm=p,
                R_object_to_palm=matrix_from_quaternion_xyzw(quaternion),
                twist_object=twist,
                acceleration_object=acceleration,
            )
        )
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return ReferenceTrajectory(t=t, time_from_start=np.array(times), points=tuple(points))
