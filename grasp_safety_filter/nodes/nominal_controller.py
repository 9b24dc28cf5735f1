"""The nominal controller's message-level endpoint: state in, ``/hand/effort_nominal`` out.

Pure Python, shared by the rclpy node (:mod:`grasp_safety_filter.nodes.nominal_controller_node`)
and the ROS-free runner. A tick runs when a joint state and an object odometry with the
same stamp t are in hand::

    /hand/joint_states (t) + /object/odom (t)
        ──▶ GraspModel.state ──▶ reference sample r(t) ──▶ NominalController.compute
        ──▶ /hand/effort_nominal stamped t (u_nom by joint name, N·m)
        ──▶ /object/reference_sample stamped t (the r(t) it tracked, nav_msgs/Odometry)

The reference is the paper's ``r(t)`` around the first object pose received
(``reference.source: paper``), or the planner's ``/object/reference``
(``reference.source: topic``, a ``MultiDOFJointTrajectory`` of the joint ``object``, its
points held piecewise constant; older than ``reference.timeout``, or before the first one,
the last pose is held with zero feed-forward and a WARN ``nominal_controller`` status goes
to ``/diagnostics`` on that tick).

Grasp check: until a received state passes the start-up grasp check
(:mod:`grasp_safety_filter.nodes.grasp_watch`: gap or penetration per contact within
``grasp_check.gap_tolerance``, contact on its face, inside the fingertip workspace, joints
strictly inside their limits, M_h, J_h, G), the controller does not start the planner's
motion: it publishes ``u_nom = g(q)``, gravity compensation at the measured joint positions
(the hand keeps its posture; with the filter off, no motion and no squeeze go to the hand;
the filter itself sends its fallback then), with an ERROR ``nominal_controller`` status
naming each failing contact or joint (``grasp.*`` values). The reference (paper: around
the object pose) and the null-space posture are taken at the first valid state. The change
is logged once (:meth:`NominalControllerEndpoint.take_log`). Only the first state is
checked: at run time, lost contacts are the safety filter's to report and hold.

Each tick that computes ``u_nom`` from the reference also publishes the sample it used on
``/object/reference_sample`` (desired pose in the palm frame, desired twist in the desired
object frame, as ``/object/odom``), so a bag holds the object's pose and its reference at the
same stamps (the analysis reports the tracking error). Gravity-compensation ticks before a
valid grasp track nothing and publish none.

An input that does not parse (non-finite values, wrong lengths, unknown or missing joint
names, a non-unit quaternion, a wrong frame) yields a WARN status naming the problem and no
command: the safety filter then holds its last safe command.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from grasp_safety_filter.control.nominal import NominalConfig, NominalController, NominalOutput
from grasp_safety_filter.control.reference import (
    Pose,
    ReferenceSample,
    ReferenceSource,
    TopicReference,
)
from grasp_safety_filter.io.diagnostic_keys import NOMINAL_DIAGNOSTIC
from grasp_safety_filter.io.messages import (
    bounded_text,
    DiagnosticLevel,
    DiagnosticReport,
    diagnostics_to_msg,
    effort_to_msg,
    joint_state_from_msg,
    JointStateData,
    MessageError,
    MessageNamespace,
    nanoseconds_to_seconds,
    ObjectStateData,
    odometry_from_msg,
    odometry_to_msg,
    reference_from_msg,
    ReferenceTrajectory,
    seconds_to_nanoseconds,
)
from grasp_safety_filter.io.topics import (
    DIAGNOSTICS,
    EFFORT_NOMINAL,
    JOINT_STATES,
    OBJECT_ODOM,
    OBJECT_REFERENCE,
    OBJECT_REFERENCE_SAMPLE,
)
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.nodes.grasp_watch import (
    findings_text,
    GraspCheckConfig,
    GraspWatch,
    LogLine,
)
from grasp_safety_filter.nodes.outgoing import Outgoing, stamped
from grasp_safety_filter.nodes.shared_parse import parse_directly, SharedParse

#: Name of the nominal controller's ``DiagnosticStatus``.
DIAGNOSTIC_NAME = NOMINAL_DIAGNOSTIC

#: Unpaired inputs kept waiting for their partner (older ones are dropped).
MAX_PENDING = 64


class NominalControllerEndpoint:
    """Computed-torque nominal control over messages (module docstring).

    Args:
        model: The ``GraspModel`` (``joint_names``, ``state(...)``).
        nominal_config: Gains and reference choice.
        msgs: Message classes to build (rclpy or rosbags).
        grasp_check_config: ``grasp_check.gap_tolerance`` (default: the start-up check's).
        parse: The joint state and odometry parses, shared with the safety filter in
            process (:mod:`~grasp_safety_filter.nodes.shared_parse`); default: its own.

    Attributes:
        controller: The nominal controller core.
        reference: The reference source, built at the first tick (None before).
        last_output: The last tick's :class:`NominalOutput` (None before the first).
        grasp: The start-up grasp check.

    """

    def __init__(
        self,
        model: Any,
        nominal_config: NominalConfig,
        msgs: MessageNamespace,
        grasp_check_config: GraspCheckConfig | None = None,
        parse: SharedParse | None = None,
    ) -> None:
        self.model = model
        self._parse = parse_directly if parse is None else parse
        self.grasp = GraspWatch(model, grasp_check_config)
        self.msgs = msgs
        self.config = nominal_config
        self.controller = NominalController(nominal_config)
        self.reference: ReferenceSource | None = None
        self.last_output: NominalOutput | None = None
        self._joint_names = list(model.joint_names)
        self._joint_name_tuple = tuple(self._joint_names)
        self._initial_pose: Pose | None = None
        self._t0: float | None = None
        self._trajectory: ReferenceTrajectory | None = None
        self._joint_states: dict[int, JointStateData] = {}
        self._odometry: dict[int, ObjectStateData] = {}
        self._last_tick_ns: int | None = None

    # -------------------------------------------------------------------------- inputs
    def on_joint_states(self, msg: Any) -> list[Outgoing]:
        """Handle ``/hand/joint_states``; tick if the odometry of its stamp is in hand."""
        try:
            data = self._parse(joint_state_from_msg, msg, self._joint_name_tuple, JOINT_STATES)
            stamp = seconds_to_nanoseconds(data.t)
        except MessageError as error:
            return self._rejected(error)
        self._joint_states[stamp] = data
        return self._tick_if_complete(stamp)

    def on_odom(self, msg: Any) -> list[Outgoing]:
        """Handle ``/object/odom``; tick if the joint state of its stamp is in hand."""
        try:
            data = self._parse(
                odometry_from_msg, msg, self.model.palm_frame, self.model.object_frame, OBJECT_ODOM
            )
            stamp = seconds_to_nanoseconds(data.t)
        except MessageError as error:
            return self._rejected(error)
        self._odometry[stamp] = data
        return self._tick_if_complete(stamp)

    def on_reference(self, msg: Any) -> list[Outgoing]:
        """Handle ``/object/reference``: keep it for the ticks to come (topic source only).

        Returns:
            Nothing, or a WARN status if the message is rejected (the previous reference
            stays in force).

        """
        try:
            self._trajectory = reference_from_msg(
                msg, self.model.palm_frame, source=OBJECT_REFERENCE
            )
        except MessageError as error:
            return self._rejected(error)
        return []

    def take_log(self) -> list[LogLine]:
        """Return and forget the grasp check's log lines (each change of its answer, once)."""
        return self.grasp.take_log()

    def update_config(
        self, nominal_config: NominalConfig, grasp_check_config: GraspCheckConfig | None = None
    ) -> None:
        """Apply new gains, paper reference shape, topic timeout or gap tolerance.

        From the next tick on (``grasp_check_config`` None: unchanged).

        Raises:
            ValueError: ``reference.source`` differs (it is read-only).

        """
        if nominal_config.reference_source != self.config.reference_source:
            raise ValueError(
                "parameter 'reference.source' is read-only: it stays "
                f'{self.config.reference_source!r}'
            )
        if grasp_check_config is not None:
            self.grasp.config = grasp_check_config
        self.config = nominal_config
        # New gains, same posture: re-latching it to the current q would undo the hold.
        self.controller = NominalController(nominal_config, posture=self.controller.posture)
        if self._initial_pose is not None and self._t0 is not None:
            previous = self.reference
            self.reference = nominal_config.make_reference(self._initial_pose, self._t0)
            if isinstance(previous, TopicReference) and previous.stamp is not None:
                # Keep the planner's last sample; only the timeout changes.
                self.reference.update(previous.sample(previous.stamp), previous.stamp)

    # ------------------------------------------------------------------------- the tick
    def _tick_if_complete(self, stamp: int) -> list[Outgoing]:
        if stamp not in self._joint_states or stamp not in self._odometry:
            self._prune()
            return []
        joints = self._joint_states.pop(stamp)
        odometry = self._odometry.pop(stamp)
        # Anything older than this tick can no longer be paired in order.
        for pending in (self._joint_states, self._odometry):
            for old in [s for s in pending if s < stamp]:
                del pending[old]
        self._last_tick_ns = stamp
        t = joints.t
        try:
            state = self.model.state(
                t,
                joints.position,
                joints.velocity,
                odometry.p_object_in_palm,
                odometry.R_object_to_palm,
                odometry.twist_object,
            )
            if not self.grasp.started and self.grasp.check(state):
                return self._no_grasp(state)
            sample = self._reference_sample(t, odometry)
            output = self.controller.compute(state, sample)
        except (ValueError, np.linalg.LinAlgError) as error:
            return self._rejected(error, t)
        if not np.all(np.isfinite(output.u)):
            return self._rejected(MessageError(f'u_nom is not finite: {output.u.tolist()}'), t)
        self.last_output = output
        outgoing = [
            stamped(EFFORT_NOMINAL, effort_to_msg(self.msgs, t, self._joint_names, output.u)),
            stamped(OBJECT_REFERENCE_SAMPLE, self._reference_msg(t, sample)),
        ]
        if output.reference_stale:
            outgoing.append(self._stale_reference_status(t))
        return outgoing

    def _reference_sample(self, t: float, odometry: ObjectStateData) -> ReferenceSample:
        if self.reference is None:
            self._initial_pose = Pose(odometry.p_object_in_palm, odometry.R_object_to_palm)
            self._t0 = t
            self.reference = self.config.make_reference(self._initial_pose, t)
        if isinstance(self.reference, TopicReference) and self._trajectory is not None:
            trajectory = self._trajectory
            k = trajectory.active_index(t)
            point = trajectory.points[k]
            sample = ReferenceSample.from_pose(
                Pose(point.p_object_in_palm, point.R_object_to_palm),
                point.twist_object,
                point.acceleration_object,
            )
            # A point is as fresh as the time it became active.
            self.reference.update(sample, trajectory.t + float(trajectory.time_from_start[k]))
        return self.reference.sample(t)

    def _reference_msg(self, t: float, sample: ReferenceSample) -> Any:
        """Return the tracked sample as ``nav_msgs/Odometry``, framed as ``/object/odom``."""
        # The pose's parts without a Pose: a rotation built from Euler angles needs no check
        # here, and odometry_to_msg checks it again anyway.
        return odometry_to_msg(
            self.msgs,
            t,
            sample.p_in_palm,
            sample.R_to_palm,
            sample.twist,
            frame_id=self.model.palm_frame,
            child_frame_id=self.model.object_frame,
        )

    def _stale_reference_status(self, t: float) -> Outgoing:
        reference = self.reference
        age = reference.age(t) if isinstance(reference, TopicReference) else math.inf
        text = (
            'no /object/reference received yet: holding the initial object pose'
            if math.isinf(age)
            else f'/object/reference is {age:.3f} s old (timeout {self.config.timeout} s): '
            'holding its last pose'
        )
        report = DiagnosticReport.create(
            DIAGNOSTIC_NAME,
            DiagnosticLevel.WARN,
            text,
            {
                'reference.stale': True,
                'reference.age': age,
                'reference.timeout': self.config.timeout,
            },
        )
        return stamped(DIAGNOSTICS, diagnostics_to_msg(self.msgs, t, report))

    def _no_grasp(self, state: GraspState) -> list[Outgoing]:
        """``u_nom = g(q)`` and an ERROR naming what fails: the grasp is not valid yet."""
        findings = findings_text(self.grasp.findings)
        report = DiagnosticReport.create(
            DIAGNOSTIC_NAME,
            DiagnosticLevel.ERROR,
            bounded_text(
                'not a valid grasp (start-up check), u_nom = g(q) (gravity compensation), '
                f'reference not started: {findings}'
            ),
            self.grasp.diagnostic_values(),
        )
        return [
            stamped(
                EFFORT_NOMINAL,
                effort_to_msg(self.msgs, state.t, self._joint_names, state.gravity_torque),
            ),
            stamped(DIAGNOSTICS, diagnostics_to_msg(self.msgs, state.t, report)),
        ]

    def _rejected(self, error: Exception, t: float | None = None) -> list[Outgoing]:
        if t is None:
            t = 0.0 if self._last_tick_ns is None else nanoseconds_to_seconds(self._last_tick_ns)
        report = DiagnosticReport.create(
            DIAGNOSTIC_NAME,
            DiagnosticLevel.WARN,
            bounded_text(f'input rejected, no command: {error}'),
            {'input.rejected': True},
        )
        return [stamped(DIAGNOSTICS, diagnostics_to_msg(self.msgs, t, report))]

    def _prune(self) -> None:
        for pending in (self._joint_states, self._odometry):
            while len(pending) > MAX_PENDING:
                del pending[min(pending)]
