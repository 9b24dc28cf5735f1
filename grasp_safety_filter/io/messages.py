"""Conversion between numpy arrays and ROS 2 messages, with input validation.

Every function works with two families of message classes: rclpy's generated classes
(in a ROS graph) and the ``rosbags`` ROS2_JAZZY typestore dataclasses (in the ROS-free
runner and when reading bags). The field names are the same; what differs is what the
fields hold, which a :class:`MessageNamespace` knows:

- variable-length ``float64[]`` fields: rclpy wants a Python sequence of floats (it
  rejects numpy arrays), rosbags wants a float64 numpy array (it serialises with
  ``ndarray.view``);
- ``byte`` fields (``DiagnosticStatus.level``): rclpy holds ``bytes`` of length 1,
  rosbags an ``int``.

Parsing (``*_from_msg``) accepts either representation. It never returns values computed
from bad input: non-finite numbers, arrays whose length does not match the names, unknown,
missing or duplicate names, unexpected frames and non-unit quaternions raise
:class:`MessageError` with a message naming the source, the entry, the field, what was
expected and what was received (received names: the first :data:`NAMES_SHOWN` and a
count; any report text at most :data:`MAX_REPORT_TEXT` characters, :func:`bounded_text`).
Joints and contacts are matched by name, in any order. Building (``*_to_msg``) checks
shapes and names, not values: a producer that publishes a NaN is caught by its consumer.
:class:`StampGuard` rejects stale, future and out-of-order stamps.

Times are float seconds on the numpy side and ``builtin_interfaces`` ``(sec, nanosec)``
in messages; the conversion rounds to the nearest nanosecond, so any time ``ns / 1e9``
(``ns`` an integer, the time below 2**23 s = 97 days, where a float still resolves
nanoseconds) round-trips exactly. Rotations round-trip through unit quaternions
(``x, y, z, w`` order in messages) to within a few ulp, not bit for bit.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from enum import IntEnum
from fractions import Fraction
import importlib
import math
from typing import Any

import numpy as np

from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.quaternion import from_rotation_matrix, rotation_matrix

#: Default frame names of the message functions: the paper's hand's palm (its URDF's root
#: link) and the object. A model names its own (``GraspModel.palm_frame``, ``object_frame``:
#: ``model.palm_frame``, ``model.object_frame``), and the endpoints pass those.
PALM_FRAME = 'palm'
OBJECT_FRAME = 'object'
REFERENCE_JOINT = 'object'

CONTACT_QUANTITIES: tuple[str, ...] = (
    'a',
    'b',
    'u',
    'v',
    'psi',
    'force_x',
    'force_y',
    'force_normal',
    'required_friction',
    'penetration',
)
"""Per-contact entries of ``/hand/contacts``, in publishing order."""

_QUATERNION_NORM_TOLERANCE = 1e-6
_ROTATION_TOLERANCE = 1e-6
_NANOSECONDS_PER_SECOND = 1_000_000_000
_INT32_MAX = 2**31 - 1

# Attribute of MessageNamespace -> ROS 2 message type.
_MESSAGE_TYPES: dict[str, str] = {
    'Time': 'builtin_interfaces/msg/Time',
    'Duration': 'builtin_interfaces/msg/Duration',
    'Header': 'std_msgs/msg/Header',
    'Point': 'geometry_msgs/msg/Point',
    'Quaternion': 'geometry_msgs/msg/Quaternion',
    'Vector3': 'geometry_msgs/msg/Vector3',
    'Pose': 'geometry_msgs/msg/Pose',
    'Twist': 'geometry_msgs/msg/Twist',
    'Transform': 'geometry_msgs/msg/Transform',
    'PoseWithCovariance': 'geometry_msgs/msg/PoseWithCovariance',
    'TwistWithCovariance': 'geometry_msgs/msg/TwistWithCovariance',
    'JointState': 'sensor_msgs/msg/JointState',
    'Odometry': 'nav_msgs/msg/Odometry',
    'MultiDOFJointTrajectory': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
    'MultiDOFJointTrajectoryPoint': 'trajectory_msgs/msg/MultiDOFJointTrajectoryPoint',
    'DiagnosticArray': 'diagnostic_msgs/msg/DiagnosticArray',
    'DiagnosticStatus': 'diagnostic_msgs/msg/DiagnosticStatus',
    'KeyValue': 'diagnostic_msgs/msg/KeyValue',
    'Clock': 'rosgraph_msgs/msg/Clock',
    'String': 'std_msgs/msg/String',
}


#: Longest text of a rejection or error report (status message, ``input.last_rejection``),
#: characters: a message with 100k names must not make every later /diagnostics huge.
MAX_REPORT_TEXT = 1000

#: Names listed in a rejection text before the rest are only counted.
NAMES_SHOWN = 5

# Longest text of one received name (or frame id) in a rejection text, characters.
_NAME_TEXT = 64


def bounded_text(text: str, limit: int = MAX_REPORT_TEXT) -> str:
    """Return ``text``, cut to ``limit`` characters with a note of how many were cut."""
    if len(text) <= limit:
        return text
    note = f' ... ({len(text)} characters in all)'
    return text[: max(limit - len(note), 0)] + note[-limit:]


def name_list(names: Sequence[str], shown: int = NAMES_SHOWN) -> str:
    """Return ``['a', 'b', ... (N more)]``: the first ``shown`` names (bounded), a count."""
    listed = [repr(bounded_text(str(n), _NAME_TEXT)) for n in list(names)[:shown]]
    if len(names) > shown:
        listed.append(f'... ({len(names) - shown} more)')
    return '[' + ', '.join(listed) + ']'


class MessageError(ValueError):
    """A message cannot be converted: bad values, lengths, names, frames or stamps."""


class StaleInputError(MessageError):
    """A message's stamp is older than the allowed age."""


class OutOfOrderError(MessageError):
    """A message's stamp is older than the last one accepted on its topic."""


class FutureStampError(MessageError):
    """A message's stamp is ahead of the clock by more than the allowed age."""


@dataclass(frozen=True)
class MessageNamespace:
    """The message classes to build, and how their fields hold values.

    Build one with :meth:`from_typestore` (rosbags) or :meth:`from_rclpy` (nodes).

    Attributes:
        Time, Duration, Header, Point, Quaternion, Vector3, Pose, Twist, Transform,
        PoseWithCovariance, TwistWithCovariance, JointState, Odometry,
        MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint, DiagnosticArray,
        DiagnosticStatus, KeyValue, Clock, String: The message classes.
        sequences_as_lists: Float arrays are Python lists (rclpy), else float64 numpy
            arrays (rosbags).
        byte_as_bytes: ``byte`` fields are ``bytes`` of length 1 (rclpy), else ``int``.

    """

    Time: Any
    Duration: Any
    Header: Any
    Point: Any
    Quaternion: Any
    Vector3: Any
    Pose: Any
    Twist: Any
    Transform: Any
    PoseWithCovariance: Any
    TwistWithCovariance: Any
    JointState: Any
    Odometry: Any
    MultiDOFJointTrajectory: Any
    MultiDOFJointTrajectoryPoint: Any
    DiagnosticArray: Any
    DiagnosticStatus: Any
    KeyValue: Any
    Clock: Any
    String: Any
    sequences_as_lists: bool
    byte_as_bytes: bool

    @classmethod
    def from_typestore(cls, typestore: Any = None) -> MessageNamespace:
        """Classes of a rosbags typestore (default: ``Stores.ROS2_JAZZY``)."""
        if typestore is None:
            from rosbags.typesys import get_typestore, Stores

            typestore = get_typestore(Stores.ROS2_JAZZY)
        classes = {name: typestore.types[msgtype] for name, msgtype in _MESSAGE_TYPES.items()}
        return cls(**classes, sequences_as_lists=False, byte_as_bytes=False)

    @classmethod
    def from_rclpy(cls) -> MessageNamespace:
        """Classes of the installed ROS 2 Python message packages (needs a ROS 2 install)."""
        classes = {name: rclpy_message_class(msgtype) for name, msgtype in _MESSAGE_TYPES.items()}
        return cls(**classes, sequences_as_lists=True, byte_as_bytes=True)

    def float_array(self, values: np.ndarray) -> Any:
        """Return a float array in the form this namespace's sequence fields take."""
        array = np.array(values, dtype=np.float64).ravel()
        return [float(v) for v in array] if self.sequences_as_lists else array

    def byte(self, value: int) -> Any:
        """Return a ``byte`` field value."""
        return bytes([value]) if self.byte_as_bytes else int(value)


def rclpy_message_class(msgtype: str) -> Any:
    """Return the rclpy class of a ``"pkg/msg/Type"`` message type (needs a ROS 2 install)."""
    package, _, name = msgtype.split('/')
    return getattr(importlib.import_module(f'{package}.msg'), name)


def byte_value(raw: Any) -> int:
    """Return the value of a ``byte`` field in either form (rclpy ``bytes``, rosbags ``int``)."""
    return raw[0] if isinstance(raw, bytes | bytearray) else int(raw)


# ----------------------------------------------------------------------------------------
# Time


def seconds_to_nanoseconds(t: float) -> int:
    """Time in s to the nearest integer ns; raise MessageError unless finite and >= 0."""
    if not math.isfinite(t) or t < 0.0:
        raise MessageError(f'time: expected a finite number of seconds >= 0, got {t!r}')
    # Exact rational product: a float product could round a time ns / 1e9 to ns +- 1.
    return round(Fraction(t) * _NANOSECONDS_PER_SECOND)


def nanoseconds_to_seconds(ns: int) -> float:
    """Time in integer ns to s, correctly rounded (int / int true division)."""
    return int(ns) / _NANOSECONDS_PER_SECOND


def _sec_nanosec(t: float, what: str) -> tuple[int, int]:
    ns = seconds_to_nanoseconds(t)
    sec, nanosec = divmod(ns, _NANOSECONDS_PER_SECOND)
    if sec > _INT32_MAX:
        raise MessageError(f'{what}: {t!r} s does not fit builtin_interfaces (int32 seconds)')
    return sec, nanosec


def time_to_msg(msgs: MessageNamespace, t: float) -> Any:
    """Time ``t`` (s, >= 0) as ``builtin_interfaces/Time``."""
    sec, nanosec = _sec_nanosec(t, 'time')
    return msgs.Time(sec=sec, nanosec=nanosec)


def time_msg_to_nanoseconds(msg: Any, what: str = 'time') -> int:
    """Return a ``builtin_interfaces`` Time or Duration as integer ns.

    Raises:
        MessageError: ``nanosec`` outside ``[0, 1e9)`` or ``sec`` negative (no time here
            is before the clock's origin, and seconds_to_nanoseconds refuses it).

    """
    sec, nanosec = int(msg.sec), int(msg.nanosec)
    if not 0 <= nanosec < _NANOSECONDS_PER_SECOND:
        raise MessageError(f'{what}: nanosec must be in [0, 1e9), got {nanosec}')
    if sec < 0:
        raise MessageError(f'{what}: sec must be >= 0, got {sec}')
    return sec * _NANOSECONDS_PER_SECOND + nanosec


def time_from_msg(msg: Any, what: str = 'time') -> float:
    """Return a ``builtin_interfaces`` Time or Duration in s."""
    return nanoseconds_to_seconds(time_msg_to_nanoseconds(msg, what))


def header_stamp_ns(msg: Any) -> int:
    """Return the header stamp of a stamped message in integer ns (e.g. a bag timestamp)."""
    return time_msg_to_nanoseconds(msg.header.stamp, 'header.stamp')


def _header(msgs: MessageNamespace, t: float, frame_id: str) -> Any:
    return msgs.Header(stamp=time_to_msg(msgs, t), frame_id=frame_id)


def _duration_to_msg(msgs: MessageNamespace, t: float) -> Any:
    sec, nanosec = _sec_nanosec(t, 'time_from_start')
    return msgs.Duration(sec=sec, nanosec=nanosec)


# ----------------------------------------------------------------------------------------
# Validation helpers


def _check_frame(source: str, what: str, received: str, expected: str) -> None:
    if received != expected:
        got = bounded_text(repr(received), _NAME_TEXT)
        raise MessageError(f'{source}: {what} must be {expected!r}, got {got}')


def _names(source: str, names: Sequence[str], kind: str) -> list[str]:
    """Received names as a list; raise on duplicates."""
    received = [str(n) for n in names]
    duplicates = sorted(n for n, count in Counter(received).items() if count > 1)
    if duplicates:
        raise MessageError(
            f'{source}: {len(duplicates)} duplicate {kind} names {name_list(duplicates)}'
        )
    return received


def _match_names(
    source: str, received_names: Sequence[str], expected_names: Sequence[str], kind: str
) -> np.ndarray:
    """Index of each expected name in the received names (any order, each exactly once)."""
    received = _names(source, received_names, kind)
    index = {name: i for i, name in enumerate(received)}
    expected = set(expected_names)
    unknown = [n for n in received if n not in expected]
    if unknown:
        raise MessageError(
            f'{source}: {len(unknown)} unknown {kind} names {name_list(unknown)}; expected '
            f'{list(expected_names)}'
        )
    missing = [n for n in expected_names if n not in index]
    if missing:
        raise MessageError(
            f'{source}: missing {kind} names {missing}; received {len(received)} '
            f'{name_list(received)}'
        )
    return np.array([index[n] for n in expected_names], dtype=int)


def _array_field(
    source: str,
    values: Any,
    field_name: str,
    names: Sequence[str],
    *,
    required: bool,
    allow_positive_inf: Sequence[bool] | None = None,
) -> np.ndarray | None:
    """Return a float field with one finite entry per name; ``None`` if optional and empty.

    Args:
        source: Name used in error messages.
        values: The field's values.
        field_name: The field's name.
        names: The message's names.
        required: The field must have one entry per name (else it may also be empty).
        allow_positive_inf: Per name, whether ``+inf`` is admissible there.

    """
    array = np.asarray(values, dtype=np.float64).ravel()
    if array.size == 0 and not required:
        return None
    if array.size != len(names):
        expectation = 'one entry per name' if required else 'none or one entry per name'
        raise MessageError(
            f"{source}: '{field_name}' has {array.size} entries, expected {expectation} "
            f'({len(names)})'
        )
    bad = ~np.isfinite(array)
    if allow_positive_inf is not None:
        bad &= ~(np.asarray(allow_positive_inf, dtype=bool) & (array == np.inf))
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        name = bounded_text(str(names[i]), _NAME_TEXT)
        raise MessageError(f"{source}: '{field_name}' of '{name}' is {float(array[i])!r}")
    return array


def _vector(source: str, what: str, values: Sequence[float]) -> np.ndarray:
    array = np.array([float(v) for v in values], dtype=np.float64)
    if not np.isfinite(array).all():
        raise MessageError(f'{source}: {what} must be finite, got {array.tolist()}')
    return array


def _unit_quaternion(source: str, what: str, msg: Any) -> np.ndarray:
    quaternion = _vector(source, what, (msg.x, msg.y, msg.z, msg.w))
    norm = float(np.linalg.norm(quaternion))
    if abs(norm - 1.0) > _QUATERNION_NORM_TOLERANCE:
        raise MessageError(
            f'{source}: {what} must be a unit quaternion (|norm - 1| <= '
            f'{_QUATERNION_NORM_TOLERANCE}), got norm {norm!r}'
        )
    return quaternion / norm


def _shaped(what: str, values: Any, shape: tuple[int, ...]) -> np.ndarray:
    array = np.asarray(values, dtype=np.float64)
    if array.shape != shape:
        raise MessageError(f'{what}: expected shape {shape}, got {array.shape}')
    return array


# ----------------------------------------------------------------------------------------
# Rotations


def quaternion_xyzw_from_matrix(R: np.ndarray) -> np.ndarray:
    """Return the unit quaternion ``(x, y, z, w)``, ``w >= 0``, of a rotation matrix.

    Raises:
        MessageError: ``R`` is not 3x3 or not a rotation within 1e-6.

    """
    R = _shaped('rotation matrix', R, (3, 3))
    if not np.isfinite(R).all():
        raise MessageError(f'rotation matrix: expected finite entries, got {R.tolist()}')
    error = float(np.abs(R.T @ R - np.eye(3)).max())
    if error > _ROTATION_TOLERANCE or np.linalg.det(R) < 0.0:
        raise MessageError(
            f'rotation matrix: expected orthonormal with det +1 (within '
            f'{_ROTATION_TOLERANCE}), got |R^T R - I| = {error:.3g}, det {np.linalg.det(R):.6g}'
        )
    return from_rotation_matrix(R)


def matrix_from_quaternion_xyzw(quaternion: np.ndarray) -> np.ndarray:
    """Rotation matrix of a unit quaternion ``(x, y, z, w)`` (normalised first)."""
    return rotation_matrix(quaternion)


def _quaternion_msg(msgs: MessageNamespace, R: np.ndarray) -> Any:
    x, y, z, w = quaternion_xyzw_from_matrix(R)
    return msgs.Quaternion(x=float(x), y=float(y), z=float(z), w=float(w))


def _vector3_msg(msgs: MessageNamespace, v: np.ndarray) -> Any:
    return msgs.Vector3(x=float(v[0]), y=float(v[1]), z=float(v[2]))


def _twist_msg(msgs: MessageNamespace, twist: np.ndarray) -> Any:
    return msgs.Twist(linear=_vector3_msg(msgs, twist[:3]), angular=_vector3_msg(msgs, twist[3:]))


def _twist_from_msg(source: str, what: str, msg: Any) -> np.ndarray:
    return _vector(
        source,
        what,
        (msg.linear.x, msg.linear.y, msg.linear.z, msg.angular.x, msg.angular.y, msg.angular.z),
    )


# ----------------------------------------------------------------------------------------
# Joint states and efforts


@dataclass(frozen=True)
class JointStateData:
    """A parsed ``/hand/joint_states`` sample, in the caller's joint order.

    Attributes:
        t: Header stamp, s.
        position: Joint angles, shape (m,), rad.
        velocity: Joint velocities, shape (m,), rad/s.
        effort: Applied joint torques, shape (m,), N·m; None when the message has none
            (many hand drivers publish no effort; the filter does not need it).

    """

    t: float
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray | None


@dataclass(frozen=True)
class EffortData:
    """A parsed effort command, in the caller's joint order.

    Attributes:
        t: Header stamp, s.
        effort: Joint torques, shape (m,), N·m.

    """

    t: float
    effort: np.ndarray


def _check_names_and_lengths(names: Sequence[str], **arrays: np.ndarray | None) -> None:
    _names('message', names, 'entry')
    for field_name, values in arrays.items():
        if values is not None and np.asarray(values).size != len(names):
            raise MessageError(
                f"message: '{field_name}' has {np.asarray(values).size} entries, expected "
                f'{len(names)} (one per name)'
            )


def joint_state_to_msg(
    msgs: MessageNamespace,
    t: float,
    names: Sequence[str],
    position: np.ndarray | None,
    velocity: np.ndarray | None,
    effort: np.ndarray | None,
    frame_id: str = '',
) -> Any:
    """Build a ``sensor_msgs/JointState``; ``None`` fields are sent empty.

    Args:
        msgs: Message classes.
        t: Stamp, s.
        names: Joint names, one per array entry.
        position: Joint angles, rad.
        velocity: Joint velocities, rad/s.
        effort: Joint torques, N·m.
        frame_id: Header frame (empty for joint states by ROS convention).

    """
    _check_names_and_lengths(names, position=position, velocity=velocity, effort=effort)
    empty = np.zeros(0)
    return msgs.JointState(
        header=_header(msgs, t, frame_id),
        name=[str(n) for n in names],
        position=msgs.float_array(empty if position is None else position),
        velocity=msgs.float_array(empty if velocity is None else velocity),
        effort=msgs.float_array(empty if effort is None else effort),
    )


def joint_state_from_msg(
    msg: Any, joint_names: Sequence[str], source: str = 'JointState'
) -> JointStateData:
    """Parse a JointState carrying position and velocity (effort optional) of ``joint_names``.

    Args:
        msg: A ``sensor_msgs/JointState``.
        joint_names: Expected joints; the result follows this order.
        source: Name used in error messages (e.g. the topic).

    Raises:
        MessageError: Duplicate, unknown or missing names; a field whose length is not the
            number of names; a non-finite value.

    """
    order = _match_names(source, msg.name, joint_names, 'joint')
    names = list(msg.name)
    arrays = {
        f: _array_field(source, getattr(msg, f), f, names, required=f != 'effort')
        for f in ('position', 'velocity', 'effort')
    }
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return JointStateData(t=t, **{f: None if a is None else a[order] for f, a in arrays.items()})


def effort_to_msg(
    msgs: MessageNamespace, t: float, names: Sequence[str], effort: np.ndarray
) -> Any:
    """Build a JointState with names and efforts (N·m) only: position and velocity empty."""
    return joint_state_to_msg(msgs, t, names, None, None, effort)


def effort_from_msg(
    msg: Any, joint_names: Sequence[str], source: str = 'effort JointState'
) -> EffortData:
    """Parse an effort-only JointState of exactly ``joint_names``.

    Position and velocity may be empty or have one entry per name (then ignored but still
    checked to be finite, since a producer that sends them garbage is not trusted).

    Raises:
        MessageError: As :func:`joint_state_from_msg`.

    """
    order = _match_names(source, msg.name, joint_names, 'joint')
    names = list(msg.name)
    effort = _array_field(source, msg.effort, 'effort', names, required=True)
    for f in ('position', 'velocity'):
        _array_field(source, getattr(msg, f), f, names, required=False)
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return EffortData(t=t, effort=effort[order])


# ----------------------------------------------------------------------------------------
# Object odometry


@dataclass(frozen=True)
class ObjectStateData:
    """A parsed ``/object/odom`` sample, palm frame.

    Attributes:
        t: Header stamp, s.
        p_object_in_palm: Object centre of mass, shape (3,), m.
        R_object_to_palm: Object orientation, shape (3, 3).
        twist_object: ``(v_o, w_o)`` in palm coordinates, shape (6,), (m/s, rad/s).

    """

    t: float
    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    twist_object: np.ndarray


def odometry_to_msg(
    msgs: MessageNamespace,
    t: float,
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
        t: Stamp, s.
        p_object_in_palm: Shape (3,), m.
        R_object_to_palm: Shape (3, 3), a rotation.
        twist_object: ``(v_o, w_o)`` in palm coordinates, shape (6,).
        frame_id: Pose frame.
        child_frame_id: Object frame.

    """
    p = _shaped('p_object_in_palm', p_object_in_palm, (3,))
    R = _shaped('R_object_to_palm', R_object_to_palm, (3, 3))
    twist = _shaped('twist_object', twist_object, (6,))
    twist_in_object = np.concatenate((R.T @ twist[:3], R.T @ twist[3:]))
    covariance = msgs.float_array(np.zeros(36))
    return msgs.Odometry(
        header=_header(msgs, t, frame_id),
        child_frame_id=child_frame_id,
        pose=msgs.PoseWithCovariance(
            pose=msgs.Pose(
                position=msgs.Point(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                orientation=_quaternion_msg(msgs, R),
            ),
            covariance=covariance,
        ),
        twist=msgs.TwistWithCovariance(
            twist=_twist_msg(msgs, twist_in_object), covariance=msgs.float_array(np.zeros(36))
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
    _check_frame(source, 'header.frame_id', msg.header.frame_id, frame_id)
    _check_frame(source, 'child_frame_id', msg.child_frame_id, child_frame_id)
    pose = msg.pose.pose
    p = _vector(source, 'pose.position', (pose.position.x, pose.position.y, pose.position.z))
    R = matrix_from_quaternion_xyzw(_unit_quaternion(source, 'pose.orientation', pose.orientation))
    twist_in_object = _twist_from_msg(source, 'twist', msg.twist.twist)
    twist = np.concatenate((R @ twist_in_object[:3], R @ twist_in_object[3:]))
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return ObjectStateData(t=t, p_object_in_palm=p, R_object_to_palm=R, twist_object=twist)


# ----------------------------------------------------------------------------------------
# Contacts


@dataclass(frozen=True)
class ContactData:
    """Contact coordinates, rates and forces of n contacts, in the caller's contact order.

    Attributes:
        t: Stamp, s.
        xi_cf: Fingertip surface coordinates ``(a, b)``, shape (n, 2), rad.
        xi_co: Object surface coordinates ``(u, v)``, shape (n, 2) (m on a face).
        psi: Angle between the surfaces' first tangent axes, shape (n,), rad.
        xi_cf_dot, xi_co_dot, psi_dot: Their rates, shapes (n, 2), (n, 2), (n,).
        force: Contact force on the object in the contact frame ``(f_x, f_y, f_n)``,
            shape (n, 3), N.
        required_friction: ``|f_t| / f_n``, shape (n,); ``+inf`` when ``f_n <= 0``.
        penetration: Normal interpenetration, shape (n,), m.

    """

    t: float
    xi_cf: np.ndarray
    xi_co: np.ndarray
    psi: np.ndarray
    xi_cf_dot: np.ndarray
    xi_co_dot: np.ndarray
    psi_dot: np.ndarray
    force: np.ndarray
    required_friction: np.ndarray
    penetration: np.ndarray

    @classmethod
    def from_grasp_state(cls, state: GraspState, force: np.ndarray) -> ContactData:
        """Take the contact part of a grasp state, with the contact forces ``force`` (3n,)."""
        forces = np.asarray(force, dtype=np.float64).reshape(-1, 3)
        return cls(
            t=state.t,
            xi_cf=np.array(state.xi_cf),
            xi_co=np.array(state.xi_co),
            psi=np.array(state.psi),
            xi_cf_dot=np.array(state.xi_cf_dot),
            xi_co_dot=np.array(state.xi_co_dot),
            psi_dot=np.array(state.psi_dot),
            force=forces,
            required_friction=state.required_friction(forces),
            penetration=np.array(state.penetration),
        )

    def _columns(self) -> tuple[np.ndarray, np.ndarray]:
        """Values and rates, shape (n, len(CONTACT_QUANTITIES)), in publishing order."""
        n = np.asarray(self.psi).shape[0]
        zeros = np.zeros(n)
        values = np.column_stack(
            (
                self.xi_cf,
                self.xi_co,
                self.psi,
                self.force,
                self.required_friction,
                self.penetration,
            )
        )
        rates = np.column_stack(
            (self.xi_cf_dot, self.xi_co_dot, self.psi_dot, zeros, zeros, zeros, zeros, zeros)
        )
        return values, rates


def contact_entry_names(contact_names: Sequence[str]) -> list[str]:
    """Names of ``/hand/contacts`` entries: ``"<contact>/<quantity>"``, contact-major."""
    return [f'{c}/{q}' for c in contact_names for q in CONTACT_QUANTITIES]


def contacts_to_msg(
    msgs: MessageNamespace, data: ContactData, contact_names: Sequence[str]
) -> Any:
    """Build ``/hand/contacts``: a JointState used as a stamped named-value list.

    Layout (public): for each contact ``c`` in order, ten entries named
    ``c/a, c/b, c/u, c/v, c/psi, c/force_x, c/force_y, c/force_normal,
    c/required_friction, c/penetration``;

    - ``position`` holds the value: ``a, b`` fingertip surface coordinates (rad), ``u, v``
      object surface coordinates (m on a face), ``psi`` (rad), ``force_*`` the contact
      force on the object in the contact frame (N), ``required_friction`` ``|f_t|/f_n``
      (``+inf`` when the contact separates), ``penetration`` (m);
    - ``velocity`` holds the rate for ``a, b, u, v, psi`` and 0.0 for the others;
    - ``effort`` is empty; ``header.frame_id`` is empty (each value is in its own frame).
    """
    n = len(contact_names)
    _names('contacts', contact_names, 'contact')
    shapes = {
        'xi_cf': (n, 2),
        'xi_co': (n, 2),
        'psi': (n,),
        'xi_cf_dot': (n, 2),
        'xi_co_dot': (n, 2),
        'psi_dot': (n,),
        'force': (n, 3),
        'required_friction': (n,),
        'penetration': (n,),
    }
    for name, shape in shapes.items():
        _shaped(f'contacts {name}', getattr(data, name), shape)
    values, rates = data._columns()
    return joint_state_to_msg(
        msgs, data.t, contact_entry_names(contact_names), values.ravel(), rates.ravel(), None
    )


def contacts_from_msg(
    msg: Any, contact_names: Sequence[str], source: str = 'contacts'
) -> ContactData:
    """Parse a ``/hand/contacts`` message of exactly ``contact_names`` (any entry order).

    Raises:
        MessageError: Duplicate, unknown or missing entries; position or velocity lengths
            not matching the names; a non-finite value (``required_friction`` may be
            ``+inf``); a non-empty effort of the wrong length.

    """
    expected = contact_entry_names(contact_names)
    order = _match_names(source, msg.name, expected, 'contact entry')
    names = list(msg.name)
    inf_ok = [name.rsplit('/', 1)[-1] == 'required_friction' for name in names]
    values = _array_field(
        source, msg.position, 'position', names, required=True, allow_positive_inf=inf_ok
    )
    rates = _array_field(source, msg.velocity, 'velocity', names, required=True)
    _array_field(source, msg.effort, 'effort', names, required=False)
    n, k = len(contact_names), len(CONTACT_QUANTITIES)
    values = values[order].reshape(n, k)
    rates = rates[order].reshape(n, k)
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return ContactData(
        t=t,
        xi_cf=values[:, 0:2],
        xi_co=values[:, 2:4],
        psi=values[:, 4],
        xi_cf_dot=rates[:, 0:2],
        xi_co_dot=rates[:, 2:4],
        psi_dot=rates[:, 4],
        force=values[:, 5:8],
        required_friction=values[:, 8],
        penetration=values[:, 9],
    )


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
        p = _shaped('reference p_object_in_palm', ref.p_object_in_palm, (3,))
        R = _shaped('reference R_object_to_palm', ref.R_object_to_palm, (3, 3))
        twist = _shaped('reference twist_object', ref.twist_object, (6,))
        acceleration = _shaped('reference acceleration_object', ref.acceleration_object, (6,))
        transform = msgs.Transform(
            translation=_vector3_msg(msgs, p), rotation=_quaternion_msg(msgs, R)
        )
        point_msgs.append(
            msgs.MultiDOFJointTrajectoryPoint(
                transforms=[transform],
                velocities=[_twist_msg(msgs, twist)],
                accelerations=[_twist_msg(msgs, acceleration)],
                time_from_start=_duration_to_msg(msgs, float(tau)),
            )
        )
    return msgs.MultiDOFJointTrajectory(
        header=_header(msgs, t, frame_id), joint_names=[REFERENCE_JOINT], points=point_msgs
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
    _check_frame(source, 'header.frame_id', msg.header.frame_id, frame_id)
    (j,) = _match_names(source, msg.joint_names, [REFERENCE_JOINT], 'joint')
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
        p = _vector(where, 'translation', (translation.x, translation.y, translation.z))
        quaternion = _unit_quaternion(where, 'rotation', transform.rotation)
        twist = (
            _twist_from_msg(where, 'velocity', point.velocities[j])
            if lengths['velocities']
            else np.zeros(6)
        )
        acceleration = (
            _twist_from_msg(where, 'acceleration', point.accelerations[j])
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


# ----------------------------------------------------------------------------------------
# Margins


@dataclass(frozen=True)
class MarginData:
    """Barrier values of the filter's constraint rows.

    Attributes:
        t: Stamp, s.
        names: Row names.
        h: Barrier values, shape (r,) (units of each row; >= 0 is safe).
        h_dot: Their time derivatives, shape (r,); NaN where the message carries none.

    """

    t: float
    names: tuple[str, ...]
    h: np.ndarray
    h_dot: np.ndarray


def margins_to_msg(
    msgs: MessageNamespace,
    t: float,
    names: Sequence[str],
    h: np.ndarray,
    h_dot: np.ndarray | None = None,
    with_names: bool = True,
) -> Any:
    """``/safety_filter/margins``: JointState with position = h, velocity = dh/dt.

    The compact form (:mod:`grasp_safety_filter.io.margin_stream`): ``with_names=False``
    leaves ``name`` empty, the rows being those of the last message that named them.
    Without ``h_dot`` the velocity is empty (8 bytes per row and message, not 16); ``h_dot``
    entries that are NaN (not defined for that row) are sent as 0.0. Effort is empty.
    """
    h_array = np.asarray(h, dtype=np.float64).ravel()
    if len(names) != h_array.size:
        raise ValueError(f'margins: {len(names)} names for {h_array.size} values')
    rates = None
    if h_dot is not None:
        rates = np.asarray(h_dot, dtype=np.float64).ravel()
        if rates.shape != h_array.shape:
            raise ValueError(f'margins: {rates.size} rates for {h_array.size} values')
        rates = np.where(np.isnan(rates), 0.0, rates)
    empty = np.zeros(0)
    return msgs.JointState(
        header=_header(msgs, t, ''),
        name=[str(n) for n in names] if with_names else [],
        position=msgs.float_array(h_array),
        velocity=msgs.float_array(empty if rates is None else rates),
        effort=msgs.float_array(empty),
    )


def margins_from_msg(
    msg: Any,
    names: Sequence[str] | None = None,
    source: str = 'margins',
    row_names: Sequence[str] | None = None,
) -> MarginData:
    """Parse margins; with ``names``, match them by name and return them in that order.

    Args:
        msg: The message.
        names: Return these rows, in this order (default: the message's order).
        source: Name used in error messages.
        row_names: The rows of a message without names (compact form): the names of the
            last message that had them. Ignored when the message names its rows.

    Raises:
        MessageError: Duplicate, unknown or missing names; lengths; non-finite values; a
            message without names and no ``row_names``.

    """
    if len(msg.name) == 0 and len(msg.position) > 0:
        if row_names is None:
            raise MessageError(
                f'{source}: {len(msg.position)} values without row names, and no earlier '
                'message named the rows'
            )
        received = list(row_names)
    else:
        received = _names(source, msg.name, 'margin')
    order = (
        np.arange(len(received))
        if names is None
        else _match_names(source, received, names, 'margin')
    )
    h = _array_field(source, msg.position, 'position', received, required=True)
    h_dot = _array_field(source, msg.velocity, 'velocity', received, required=False)
    if h_dot is None:
        h_dot = np.full(len(received), np.nan)
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return MarginData(t=t, names=tuple(received[i] for i in order), h=h[order], h_dot=h_dot[order])


# ----------------------------------------------------------------------------------------
# Diagnostics


class DiagnosticLevel(IntEnum):
    """``diagnostic_msgs/DiagnosticStatus`` levels."""

    OK = 0
    WARN = 1
    ERROR = 2
    STALE = 3


def format_diagnostic_value(value: Any) -> str:
    """Format a value as diagnostic text: floats with ``repr`` (``float()`` restores them)."""
    if isinstance(value, bool | np.bool_):
        return 'true' if value else 'false'
    if isinstance(value, int | np.integer):
        return str(int(value))
    if isinstance(value, float | np.floating):
        return repr(float(value))
    return str(value)


@dataclass(frozen=True)
class DiagnosticReport:
    """One ``DiagnosticStatus``.

    Attributes:
        name: Component name, e.g. ``"safety_filter"``.
        level: OK, WARN, ERROR or STALE.
        message: One-line summary.
        values: Key/value pairs (values already text: see :func:`format_diagnostic_value`).
        hardware_id: Hardware identifier, empty for software components.

    """

    name: str
    level: DiagnosticLevel
    message: str
    values: dict[str, str] = field(default_factory=dict)
    hardware_id: str = ''

    @classmethod
    def create(
        cls,
        name: str,
        level: DiagnosticLevel | int,
        message: str,
        values: Mapping[str, Any] | None = None,
        hardware_id: str = '',
    ) -> DiagnosticReport:
        """Build a report, formatting the values with :func:`format_diagnostic_value`."""
        text = {str(k): format_diagnostic_value(v) for k, v in (values or {}).items()}
        return cls(name, DiagnosticLevel(level), message, text, hardware_id)


@dataclass(frozen=True)
class DiagnosticsData:
    """A parsed DiagnosticArray.

    Attributes:
        t: Header stamp, s.
        reports: The statuses, in message order.

    """

    t: float
    reports: tuple[DiagnosticReport, ...]

    def report(self, name: str) -> DiagnosticReport:
        """Return the status named ``name`` (KeyError naming the known ones if absent)."""
        for report in self.reports:
            if report.name == name:
                return report
        raise KeyError(f'no diagnostic status {name!r}; have {[r.name for r in self.reports]}')


def diagnostics_to_msg(
    msgs: MessageNamespace, t: float, reports: DiagnosticReport | Sequence[DiagnosticReport]
) -> Any:
    """Build a ``diagnostic_msgs/DiagnosticArray`` of one or more statuses."""
    if isinstance(reports, DiagnosticReport):
        reports = [reports]
    statuses = [
        msgs.DiagnosticStatus(
            level=msgs.byte(DiagnosticLevel(r.level)),
            name=r.name,
            message=r.message,
            hardware_id=r.hardware_id,
            values=[msgs.KeyValue(key=k, value=v) for k, v in r.values.items()],
        )
        for r in reports
    ]
    return msgs.DiagnosticArray(header=_header(msgs, t, ''), status=statuses)


def diagnostics_from_msg(msg: Any, source: str = 'diagnostics') -> DiagnosticsData:
    """Parse a DiagnosticArray (``level`` as int or 1-byte ``bytes``).

    Raises:
        MessageError: A level outside OK..STALE or a duplicate key within a status.

    """
    reports = []
    for status in msg.status:
        level = byte_value(status.level)
        if level not in {int(member) for member in DiagnosticLevel}:
            raise MessageError(
                f'{source}: status {status.name!r} level must be 0..3, got {level!r}'
            )
        keys = _names(f'{source}: status {status.name!r}', [kv.key for kv in status.values], 'key')
        values = dict(zip(keys, (str(kv.value) for kv in status.values), strict=True))
        reports.append(
            DiagnosticReport(
                name=str(status.name),
                level=DiagnosticLevel(level),
                message=str(status.message),
                values=values,
                hardware_id=str(status.hardware_id),
            )
        )
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return DiagnosticsData(t=t, reports=tuple(reports))


# ----------------------------------------------------------------------------------------
# Clock


def clock_to_msg(msgs: MessageNamespace, t: float) -> Any:
    """Build a ``rosgraph_msgs/Clock`` at ``t`` s."""
    return msgs.Clock(clock=time_to_msg(msgs, t))


def clock_from_msg(msg: Any) -> float:
    """Return the time of a Clock message, s."""
    return time_from_msg(msg.clock, 'clock')


# ----------------------------------------------------------------------------------------
# Stamps


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
