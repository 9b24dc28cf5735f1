"""The topic table: every topic of the ROS graph, its type, publisher and QoS.

One table serves both the rclpy nodes (which build an ``rclpy.qos.QoSProfile`` from
:class:`TopicQos`) and the bag writer (which records the same profile as the topic's
``offered_qos_profiles`` in ``metadata.yaml``), so a bag written by the ROS-free runner
and one recorded by ``ros2 bag record`` from the ROS graph describe their topics alike.

QoS choices:

- State, contacts, commands, margins: reliable, volatile, keep last 10. In lockstep mode
  the simulator waits for the command stamped with its state's stamp, so no sample may be
  dropped (reliable); a late joiner has no use for old samples (volatile); 10 absorbs a
  short scheduling hiccup without unbounded memory.
- ``/object/reference``: the same stream profile. Planners stream references (the
  controller holds the last pose once they stop, see
  :class:`grasp_safety_filter.control.reference.TopicReference`), and a volatile
  subscription matches every reliable publisher, volatile or transient local; requesting
  transient local would silently drop planners that publish volatile, the
  ``ros2 topic pub`` default.
- ``/object/reference_sample``: the stream profile; it is recorded for the analysis
  (object tracking error) and no node subscribes to it, so the lockstep never waits on it.
- ``/diagnostics``: the ROS default profile (reliable, volatile, keep last 10), which
  ``diagnostic_aggregator`` and ``rqt_robot_monitor`` subscribe with.
- ``/clock``: best effort, volatile, keep last 1, as rclcpp's ``ClockQoS`` and the
  subscription rclpy's time source creates: only the newest time matters.
- ``/grasp/markers``: reliable, volatile, keep last 1: a viewer draws the newest scene only.
- ``/grasp/scenario``: reliable, transient local, keep last 1 (a latched topic). It is
  published once at start-up; a late joiner (``ros2 bag record`` started after the
  simulator, an analysis tool) still receives it.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

from rosbags.interfaces import (
    Qos,
    QosDurability,
    QosHistory,
    QosLiveliness,
    QosReliability,
    QosTime,
)

from grasp_safety_filter.io.schemas import (
    GRASP_MARKERS_NODE,
    HAND_SIM_NODE,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)

Reliability = Literal['reliable', 'best_effort']
Durability = Literal['volatile', 'transient_local']

# Topic names, for code that publishes or subscribes one topic.
JOINT_STATES = '/hand/joint_states'
OBJECT_ODOM = '/object/odom'
OBJECT_POSE = '/object/pose'
OBJECT_TRUE_ODOM = '/object/true_odom'
CONTACTS = '/hand/contacts'
OBJECT_REFERENCE = '/object/reference'
OBJECT_REFERENCE_SAMPLE = '/object/reference_sample'
EFFORT_NOMINAL = '/hand/effort_nominal'
EFFORT_COMMAND = '/hand/effort_command'
EFFORT_CONTROLLER_COMMANDS = '/effort_controller/commands'
DIAGNOSTICS = '/diagnostics'
MARGINS = '/safety_filter/margins'
CLOCK = '/clock'
SCENARIO = '/grasp/scenario'
MARKERS = '/grasp/markers'

# The planner is whatever the user connects to /object/reference.
PLANNER = 'planner'
# The object tracker is whatever publishes the object's pose (a camera, motion capture).
TRACKER = 'tracker'


@dataclass(frozen=True)
class TopicQos:
    """A keep-last QoS profile in plain values.

    The names match rclpy's policy enums after ``upper()``
    (``ReliabilityPolicy.RELIABLE``, ``DurabilityPolicy.TRANSIENT_LOCAL``) and rosbags'
    QoS enums alike: :meth:`to_rclpy` gives the nodes' profile, :meth:`to_rosbags` the
    bag's. Deadline, lifespan and liveliness are left at the ROS defaults (unset,
    automatic).

    Attributes:
        reliability: ``"reliable"`` or ``"best_effort"``.
        durability: ``"volatile"`` or ``"transient_local"``.
        depth: History depth (keep last), >= 1.

    """

    reliability: Reliability
    durability: Durability
    depth: int

    def __post_init__(self) -> None:
        if self.reliability not in ('reliable', 'best_effort'):
            raise ValueError(
                f"QoS reliability: expected 'reliable' or 'best_effort', got {self.reliability!r}"
            )
        if self.durability not in ('volatile', 'transient_local'):
            raise ValueError(
                f"QoS durability: expected 'volatile' or 'transient_local', got "
                f'{self.durability!r}'
            )
        if isinstance(self.depth, bool) or not isinstance(self.depth, int) or self.depth < 1:
            raise ValueError(f'QoS depth: expected an integer >= 1, got {self.depth!r}')

    @property
    def text(self) -> str:
        """Return the profile in words, e.g. ``"reliable, volatile, keep last 10"``."""
        return f'{self.reliability}, {self.durability}, keep last {self.depth}'

    def to_rclpy(self) -> Any:
        """Return this profile as an ``rclpy.qos.QoSProfile`` (needs a ROS 2 install)."""
        from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy

        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=self.depth,
            reliability=ReliabilityPolicy[self.reliability.upper()],
            durability=DurabilityPolicy[self.durability.upper()],
        )

    def to_rosbags(self) -> Qos:
        """Return this profile as a rosbags ``Qos`` (an ``offered_qos_profiles`` entry)."""
        unset = QosTime(sec=0, nsec=0)
        return Qos(
            history=QosHistory.KEEP_LAST,
            depth=self.depth,
            reliability=QosReliability[self.reliability.upper()],
            durability=QosDurability[self.durability.upper()],
            deadline=unset,
            lifespan=unset,
            liveliness=QosLiveliness.AUTOMATIC,
            liveliness_lease_duration=unset,
            avoid_ros_namespace_conventions=False,
        )


STREAM_QOS = TopicQos(reliability='reliable', durability='volatile', depth=10)
DIAGNOSTICS_QOS = TopicQos(reliability='reliable', durability='volatile', depth=10)
CLOCK_QOS = TopicQos(reliability='best_effort', durability='volatile', depth=1)
LATCHED_QOS = TopicQos(reliability='reliable', durability='transient_local', depth=1)
NEWEST_QOS = TopicQos(reliability='reliable', durability='volatile', depth=1)


@dataclass(frozen=True)
class TopicSpec:
    """One topic of the graph.

    Attributes:
        name: Absolute topic name.
        msgtype: ROS 2 message type, ``"pkg/msg/Type"``.
        publishers: Nodes that publish it.
        qos: The QoS profile publishers offer and subscribers request.
        description: What it carries, with frames and units.

    """

    name: str
    msgtype: str
    publishers: tuple[str, ...]
    qos: TopicQos
    description: str


# fmt: off
TOPICS: tuple[TopicSpec, ...] = (
    TopicSpec(
        SCENARIO, 'std_msgs/msg/String', (HAND_SIM_NODE,), LATCHED_QOS,
        'JSON, once at start-up: joint names and limits, contact names, friction coefficient '
        '(and torsional friction of soft fingers), fingertip workspace, time step, duration, '
        'integrator (layout: nodes.scenario).',
    ),
    TopicSpec(
        JOINT_STATES, 'sensor_msgs/msg/JointState', (HAND_SIM_NODE,), STREAM_QOS,
        'Hand joints by name: position (rad), velocity (rad/s), applied effort (N·m); in '
        'hardware mode at hardware.rate, stamped with the wall clock, after '
        'hardware.extra_joints arm joints.',
    ),
    TopicSpec(
        OBJECT_ODOM, 'nav_msgs/msg/Odometry', (HAND_SIM_NODE,), STREAM_QOS,
        'Object pose in the palm frame; twist in the object frame (REP 105). From the '
        "simulator (lockstep: exact, on every tick) or a tracker (input.sync 'latest'; the "
        "simulator's hardware mode emulates one: tracker.message 'odometry').",
    ),
    TopicSpec(
        OBJECT_POSE, 'geometry_msgs/msg/PoseStamped', (TRACKER, HAND_SIM_NODE), STREAM_QOS,
        'Object pose in the palm frame, stamped with its capture time, no twist: a tracker '
        "read with input.object_message 'pose' (the simulator's hardware mode emulates one: "
        "tracker.message 'pose').",
    ),
    TopicSpec(
        OBJECT_TRUE_ODOM, 'nav_msgs/msg/Odometry', (HAND_SIM_NODE,), STREAM_QOS,
        "Hardware mode only: the plant's exact object pose in the palm frame and twist in the "
        'object frame, stamped as each joint state: ground truth for bags and for the '
        "controllers' object estimate (no node subscribes to it).",
    ),
    TopicSpec(
        CONTACTS, 'sensor_msgs/msg/JointState', (HAND_SIM_NODE,), STREAM_QOS,
        'Contact coordinates, rates, forces, required friction, penetration and, for soft '
        "fingers, torsion as '<contact>/<quantity>' entries (layout: "
        'messages.contacts_to_msg).',
    ),
    TopicSpec(
        OBJECT_REFERENCE, 'trajectory_msgs/msg/MultiDOFJointTrajectory', (PLANNER,), STREAM_QOS,
        "Desired object pose, twist and acceleration in the palm frame, joint 'object'.",
    ),
    TopicSpec(
        OBJECT_REFERENCE_SAMPLE, 'nav_msgs/msg/Odometry', (NOMINAL_CONTROLLER_NODE,), STREAM_QOS,
        'The reference sample the nominal controller tracked on its tick, stamped as the '
        'tick: desired object pose in the palm frame, desired twist in the desired object '
        'frame (for tracking error; nothing waits on it).',
    ),
    TopicSpec(
        EFFORT_NOMINAL, 'sensor_msgs/msg/JointState', (NOMINAL_CONTROLLER_NODE,), STREAM_QOS,
        'Nominal joint torques by name, effort only (N·m).',
    ),
    TopicSpec(
        EFFORT_COMMAND, 'sensor_msgs/msg/JointState', (SAFETY_FILTER_NODE,), STREAM_QOS,
        'Filtered joint torques u* by name, effort only (N·m).',
    ),
    TopicSpec(
        EFFORT_CONTROLLER_COMMANDS, 'std_msgs/msg/Float64MultiArray', (SAFETY_FILTER_NODE,),
        STREAM_QOS,
        "u* as ros2_control's effort_controllers/JointGroupEffortController takes it on "
        '<controller>/commands: N·m in command.joints order, unstamped (command.message '
        "'float64_multi_array'; u* is on /hand/effort_command as well).",
    ),
    TopicSpec(
        DIAGNOSTICS, 'diagnostic_msgs/msg/DiagnosticArray', (SAFETY_FILTER_NODE, HAND_SIM_NODE),
        DIAGNOSTICS_QOS,
        'QP status, solve time, relaxation, smallest margins, input hold mode; '
        'simulator lockstep timeouts; hardware mode: command timeouts, refused commands, '
        'late driver periods.',
    ),
    TopicSpec(
        MARGINS, 'sensor_msgs/msg/JointState', (SAFETY_FILTER_NODE,), STREAM_QOS,
        'Barrier values h per row (position; velocity dh/dt when known, else empty). The '
        'row names only in the first message, on a change and at least once a second; the '
        'others have no names: their rows are those last named (layout: margin_stream).',
    ),
    TopicSpec(
        MARKERS, 'visualization_msgs/msg/MarkerArray', (GRASP_MARKERS_NODE,), NEWEST_QOS,
        'The grasp in the palm frame for RViz or Foxglove (fixed frame: the palm): links, '
        'fingertips, object, contact points, normals, forces, friction cones coloured by '
        "beta/mu, the safety filter's active rows (layout: view.markers).",
    ),
    TopicSpec(
        CLOCK, 'rosgraph_msgs/msg/Clock', (HAND_SIM_NODE,), CLOCK_QOS,
        'Simulation time, published when use_sim_time is set.',
    ),
)
# fmt: on


def topic_spec(name: str) -> TopicSpec:
    """Return the table entry of topic ``name``.

    Raises:
        KeyError: ``name`` is not in :data:`TOPICS` (the message lists the known topics).

    """
    for spec in TOPICS:
        if spec.name == name:
            return spec
    raise KeyError(f'unknown topic {name!r}; known topics: {[s.name for s in TOPICS]}')
