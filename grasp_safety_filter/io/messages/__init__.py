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

Stamps are ``builtin_interfaces`` ``(sec, nanosec)`` in messages, integer ns in every
parsed sample (``stamp_ns``, with ``t`` in float s for the model) and in whatever answers
it: a builder given an ``int`` stamps it exactly (a wall-clock stamp of today needs 61
bits; a float in s resolves it to about 0.24 us only). A builder given a float time in s
rounds it to the nearest nanosecond, so any simulation time ``ns / 1e9`` (below 2**23 s
= 97 days, where a float still resolves nanoseconds) round-trips exactly. Rotations
round-trip through unit quaternions (``x, y, z, w`` order in messages) to within a few ulp,
not bit for bit.

One module per message family; this package re-exports their public names.
"""

from __future__ import annotations

from grasp_safety_filter.io.messages.contacts import (  # noqa: F401
    contact_entry_names,
    CONTACT_QUANTITIES,
    contact_quantities,
    ContactData,
    contacts_from_msg,
    contacts_to_msg,
)
from grasp_safety_filter.io.messages.diagnostics import (  # noqa: F401
    DiagnosticLevel,
    DiagnosticReport,
    diagnostics_from_msg,
    diagnostics_to_msg,
    format_diagnostic_value,
)
from grasp_safety_filter.io.messages.effort_arrays import (  # noqa: F401
    effort_array_from_msg,
    effort_array_to_msg,
    joint_order,
)
from grasp_safety_filter.io.messages.errors import (  # noqa: F401
    bounded_text,
    FutureStampError,
    MAX_REPORT_TEXT,
    MessageError,
    name_list,
    NAMES_SHOWN,
    OutOfOrderError,
    StaleInputError,
)
from grasp_safety_filter.io.messages.fields import (  # noqa: F401
    match_names,
    matrix_from_quaternion_xyzw,
    quaternion_xyzw_from_matrix,
)
from grasp_safety_filter.io.messages.joint_states import (  # noqa: F401
    effort_from_msg,
    effort_to_msg,
    effort_values,
    EffortData,
    joint_state_from_msg,
    joint_state_to_msg,
    JointStateData,
)
from grasp_safety_filter.io.messages.margins import (  # noqa: F401
    MarginData,
    margins_from_msg,
    margins_to_msg,
)
from grasp_safety_filter.io.messages.namespace import (  # noqa: F401
    byte_value,
    MESSAGE_TYPES,
    MessageNamespace,
    rclpy_message_class,
)
from grasp_safety_filter.io.messages.odometry import (  # noqa: F401
    ObjectStateData,
    odometry_from_msg,
    odometry_to_msg,
    pose_stamped_from_msg,
    pose_stamped_to_msg,
)
from grasp_safety_filter.io.messages.reference import (  # noqa: F401
    MAX_REFERENCE_POINTS,
    ObjectReference,
    reference_from_msg,
    reference_to_msg,
    ReferenceTrajectory,
)
from grasp_safety_filter.io.messages.stamps import (  # noqa: F401
    clock_from_msg,
    clock_to_msg,
    header_stamp_ns,
    NANOSECONDS_PER_SECOND,
    nanoseconds_to_seconds,
    seconds_to_nanoseconds,
    Stamp,
    stamp_nanoseconds,
    StampGuard,
    time_from_msg,
    time_msg_to_nanoseconds,
    time_to_msg,
)
