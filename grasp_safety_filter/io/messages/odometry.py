"""The object's pose and twist in the palm frame: ``Odometry``, or ``PoseStamped`` (no twist).

The simulator publishes ``nav_msgs/Odometry`` (pose and twist); an object tracker often
publishes a ``geometry_msgs/PoseStamped`` (pose only), stamped with its capture time.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.fields import (
    check_frame,
    finite_vector,
    matrix_from_quaternion_xyzw,
    OBJECT_FRAME,
    PALM_FRAME,
    quaternion_msg,
    shaped_array,
    twist_from_msg,
    twist_msg,
    unit_quaternion,
)
from grasp_safety_filter.io.messages.namespace import MessageNamespace
from grasp_safety_filter.io.messages.stamps import (
    header_msg,
    nanoseconds_to_seconds,
    Stamp,
    time_msg_to_nanoseconds,
)

#: Covariance of the exact simulator state (a copy goes into each message).
_ZERO_COVARIANCE = np.zeros(36)
_ZERO_COVARIANCE.flags.writeable = False


@dataclass(frozen=True)
class ObjectStateData:
    """A parsed ``/object/odom`` sample, palm frame.

    Attributes:
        t: Header stamp, s.
        stamp_ns: Header stamp, integer ns.
        p_object_in_palm: Object centre of mass, shape (3,), m.
        R_object_to_palm: Object orientation, shape (3, 3).
        twist_object: ``(v_o, w_o)`` in palm coordinates, shape (6,), (m/s, rad/s); None
            from a ``PoseStamped``, which has no twist.

    """

    t: float
    stamp_ns: int
    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    twist_object: np.ndarray | None


def odometry_to_msg(
    msgs: MessageNamespace,
    t: Stamp,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    twist_object: np.ndarray,
    frame_id: str = PALM_FRAME,
    child_frame_id: str = OBJECT_FRAME,
) -> Any:
    """Build the object's ``nav_msgs/Odometry``.

    The pose is the object frame in the palm frame (``frame_id``). Following REP 105 and
    the Odometry definition, the twist is expressed in the child (object) frame:
    ``v_child = R_object_to_palm^T v_o``, ``w_child = R_object_to_palm^T w_o``, where
    ``(v_o, w_o)`` is the palm-frame twist of the model. Covariances are zero (exact
    simulator state).

    Args:
        msgs: Message classes.
        t: Stamp: integer ns, or s.
        p_object_in_palm: Shape (3,), m.
        R_object_to_palm: Shape (3, 3), a rotation.
        twist_object: ``(v_o, w_o)`` in palm coordinates, shape (6,).
        frame_id: Pose frame.
        child_frame_id: Object frame.

    """
    p = shaped_array('p_object_in_palm', p_object_in_palm, (3,))
    R = shaped_array('R_object_to_palm', R_object_to_palm, (3, 3))
    twist = shaped_array('twist_object', twist_object, (6,))
    twist_in_object = np.concatenate((R.T @ twist[:3], R.T @ twist[3:]))
    x, y, z = p.tolist()
    return msgs.Odometry(
        header=header_msg(msgs, t, frame_id),
        child_frame_id=child_frame_id,
        pose=msgs.PoseWithCovariance(
            pose=msgs.Pose(
                position=msgs.Point(x=x, y=y, z=z), orientation=quaternion_msg(msgs, R)
            ),
            covariance=msgs.float_array(_ZERO_COVARIANCE),
        ),
        twist=msgs.TwistWithCovariance(
            twist=twist_msg(msgs, twist_in_object),
            covariance=msgs.float_array(_ZERO_COVARIANCE),
        ),
    )


def odometry_from_msg(
    msg: Any,
    frame_id: str = PALM_FRAME,
    child_frame_id: str = OBJECT_FRAME,
    source: str = 'Odometry',
) -> ObjectStateData:
    """Parse an object Odometry; the twist is returned in palm coordinates.

    Raises:
        MessageError: Unexpected frames, non-finite values, or a quaternion whose norm
            differs from 1 by more than 1e-6.

    """
    check_frame(source, 'header.frame_id', msg.header.frame_id, frame_id)
    check_frame(source, 'child_frame_id', msg.child_frame_id, child_frame_id)
    pose = msg.pose.pose
    p = finite_vector(source, 'pose.position', (pose.position.x, pose.position.y, pose.position.z))
    R = matrix_from_quaternion_xyzw(unit_quaternion(source, 'pose.orientation', pose.orientation))
    twist_in_object = twist_from_msg(source, 'twist', msg.twist.twist)
    twist = np.concatenate((R @ twist_in_object[:3], R @ twist_in_object[3:]))
    return _object_state(msg, source, p, R, twist)


def pose_stamped_to_msg(
    msgs: MessageNamespace,
    t: Stamp,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    frame_id: str = PALM_FRAME,
) -> Any:
    """Build the object's ``geometry_msgs/PoseStamped``: its pose in the frame ``frame_id``."""
    p = shaped_array('p_object_in_palm', p_object_in_palm, (3,))
    R = shaped_array('R_object_to_palm', R_object_to_palm, (3, 3))
    x, y, z = p.tolist()
    return msgs.PoseStamped(
        header=header_msg(msgs, t, frame_id),
        pose=msgs.Pose(position=msgs.Point(x=x, y=y, z=z), orientation=quaternion_msg(msgs, R)),
    )


def pose_stamped_from_msg(
    msg: Any, frame_id: str = PALM_FRAME, source: str = 'PoseStamped'
) -> ObjectStateData:
    """Parse an object ``PoseStamped`` (palm frame ``frame_id``); its twist is None.

    Raises:
        MessageError: Another frame, non-finite values, or a quaternion whose norm differs
            from 1 by more than 1e-6.

    """
    check_frame(source, 'header.frame_id', msg.header.frame_id, frame_id)
    pose = msg.pose
    p = finite_vector(source, 'pose.position', (pose.position.x, pose.position.y, pose.position.z))
    R = matrix_from_quaternion_xyzw(unit_quaternion(source, 'pose.orientation', pose.orientation))
    return _object_state(msg, source, p, R, None)


def _object_state(
    msg: Any, source: str, p: np.ndarray, R: np.ndarray, twist: np.ndarray | None
) -> ObjectStateData:
    stamp_ns = time_msg_to_nanoseconds(msg.header.stamp, f'{source}: header.stamp')
    return ObjectStateData(
        t=nanoseconds_to_seconds(stamp_ns),
        stamp_ns=stamp_ns,
        p_object_in_palm=p,
        R_object_to_palm=R,
        twist_object=twist,
    )
