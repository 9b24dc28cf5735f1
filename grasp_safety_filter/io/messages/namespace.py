"""The two families of message classes (rclpy, rosbags) and how their fields hold values."""

from __future__ import annotations

from dataclasses import dataclass
import importlib
from typing import Any

import numpy as np

MESSAGE_TYPES: dict[str, str] = {
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
    'PoseStamped': 'geometry_msgs/msg/PoseStamped',
    'Float64MultiArray': 'std_msgs/msg/Float64MultiArray',
    'MultiArrayLayout': 'std_msgs/msg/MultiArrayLayout',
    'MultiDOFJointTrajectory': 'trajectory_msgs/msg/MultiDOFJointTrajectory',
    'MultiDOFJointTrajectoryPoint': 'trajectory_msgs/msg/MultiDOFJointTrajectoryPoint',
    'DiagnosticArray': 'diagnostic_msgs/msg/DiagnosticArray',
    'DiagnosticStatus': 'diagnostic_msgs/msg/DiagnosticStatus',
    'KeyValue': 'diagnostic_msgs/msg/KeyValue',
    'Clock': 'rosgraph_msgs/msg/Clock',
    'String': 'std_msgs/msg/String',
    'ColorRGBA': 'std_msgs/msg/ColorRGBA',
    'CompressedImage': 'sensor_msgs/msg/CompressedImage',
    'Marker': 'visualization_msgs/msg/Marker',
    'MarkerArray': 'visualization_msgs/msg/MarkerArray',
    'MeshFile': 'visualization_msgs/msg/MeshFile',
}


@dataclass(frozen=True)
class MessageNamespace:
    """The message classes to build, and how their fields hold values.

    Build one with :meth:`from_typestore` (rosbags) or :meth:`from_rclpy` (nodes).

    Attributes:
        Time, Duration, Header, Point, Quaternion, Vector3, Pose, Twist, Transform,
        PoseWithCovariance, TwistWithCovariance, JointState, Odometry, PoseStamped,
        Float64MultiArray, MultiArrayLayout,
        MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint, DiagnosticArray,
        DiagnosticStatus, KeyValue, Clock, String, ColorRGBA, CompressedImage, Marker,
        MarkerArray, MeshFile: The message classes.
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
    PoseStamped: Any
    Float64MultiArray: Any
    MultiArrayLayout: Any
    MultiDOFJointTrajectory: Any
    MultiDOFJointTrajectoryPoint: Any
    DiagnosticArray: Any
    DiagnosticStatus: Any
    KeyValue: Any
    Clock: Any
    String: Any
    ColorRGBA: Any
    CompressedImage: Any
    Marker: Any
    MarkerArray: Any
    MeshFile: Any
    sequences_as_lists: bool
    byte_as_bytes: bool

    @classmethod
    def from_typestore(cls, typestore: Any = None) -> MessageNamespace:
        """Classes of a rosbags typestore (default: ``Stores.ROS2_JAZZY``)."""
        if typestore is None:
            from rosbags.typesys import get_typestore, Stores

            typestore = get_typestore(Stores.ROS2_JAZZY)
        classes = {name: typestore.types[msgtype] for name, msgtype in MESSAGE_TYPES.items()}
        return cls(**classes, sequences_as_lists=False, byte_as_bytes=False)

    @classmethod
    def from_rclpy(cls) -> MessageNamespace:
        """Classes of the installed ROS 2 Python message packages (needs a ROS 2 install)."""
        classes = {name: rclpy_message_class(msgtype) for name, msgtype in MESSAGE_TYPES.items()}
        return cls(**classes, sequences_as_lists=True, byte_as_bytes=True)

    def float_array(self, values: np.ndarray) -> Any:
        """Return a float array in the form this namespace's sequence fields take (a copy)."""
        array = np.array(values, dtype=np.float64)
        if array.ndim != 1:
            array = array.ravel()
        return array.tolist() if self.sequences_as_lists else array

    def empty_float_array(self) -> Any:
        """Return an empty float array in the form this namespace's sequence fields take."""
        return [] if self.sequences_as_lists else np.empty(0)

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
