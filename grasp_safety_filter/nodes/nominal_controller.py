"""The nominal controller's message-level endpoint: state in, ``/hand/effort_nominal`` out.

Pure Python, shared by the rclpy node (:mod:`~grasp_safety_filter.nodes.nominal_controller_node`)
and the ROS-free runner. A tick::

    /hand/joint_states + object state, one stamp t
        ──▶ GraspModel.state ──▶ reference sample r(t) ──▶ NominalController.compute
        ──▶ /hand/effort_nominal stamped t (u_nom by joint name, N·m)
        ──▶ /object/reference_sample stamped t (the r(t) it tracked, as /object/odom)

With ``input.sync: exact`` a joint state and an odometry of one stamp make a tick; with
``latest`` each joint state does, the object's state estimated at its stamp
(:class:`~grasp_safety_filter.nodes.object_stream.ObjectStream`). The reference is the
paper's ``r(t)`` around the first object pose (``reference.source: paper``) or the planner's
``/object/reference`` (``topic``; stale or absent: the last pose held, WARN). Until a state
passes the start-up grasp check (:mod:`~grasp_safety_filter.nodes.grasp_watch`) it sends
``u_nom = g(q)`` and an ERROR naming what fails; the reference and the null-space posture are
taken at the first valid state. Input that does not parse gets a WARN (once a second) and no
command. The whole behaviour, for users: ``docs/ros_nodes.md``.
"""

from __future__ import annotations

from collections.abc import Mapping
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
    effort_to_msg,
    MessageError,
    MessageNamespace,
    odometry_to_msg,
    reference_from_msg,
    ReferenceTrajectory,
    seconds_to_nanoseconds,
    Stamp,
)
from grasp_safety_filter.io.topics import (
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
from grasp_safety_filter.nodes.input_watchdog import InputWatchdog
from grasp_safety_filter.nodes.nominal_inputs import NominalInputs, Rejection, Tick
from grasp_safety_filter.nodes.object_stream import EXACT, StreamConfig
from grasp_safety_filter.nodes.outgoing import diagnostic_status, Outgoing, stamped
from grasp_safety_filter.nodes.publication_rate import ReportThrottle
from grasp_safety_filter.nodes.shared_parse import SharedParse

#: Name of the nominal controller's ``DiagnosticStatus``.
DIAGNOSTIC_NAME = NOMINAL_DIAGNOSTIC


class NominalControllerEndpoint:
    """Computed-torque nominal control over messages (module docstring).

    Args:
        model: The ``GraspModel`` (``joint_names``, ``state(...)``).
        nominal_config: Gains and reference choice.
        msgs: Message classes to build (rclpy or rosbags).
        grasp_check_config: ``grasp_check.gap_tolerance`` (default: the start-up check's).
        parse: The joint state and odometry parses, shared with the safety filter in
            process (:mod:`~grasp_safety_filter.nodes.shared_parse`); default: its own.
        stream: ``input.sync`` and the object's estimate (default: ``exact``).
        topic_names: The input topics as the node resolved them (remapped), by table name,
            for the texts (default: the table's; the object's: the configured one).

    Attributes:
        controller: The nominal controller core.
        reference: The reference source, built at the first tick (None before).
        last_output: The last tick's :class:`NominalOutput` (None before the first).
        grasp: The start-up grasp check.
        ticked: Whether a tick has been answered.
        rejected_count: Inputs rejected so far.

    """

    def __init__(
        self,
        model: Any,
        nominal_config: NominalConfig,
        msgs: MessageNamespace,
        grasp_check_config: GraspCheckConfig | None = None,
        parse: SharedParse | None = None,
        stream: StreamConfig = EXACT,
        topic_names: Mapping[str, str] | None = None,
    ) -> None:
        self.model = model
        self.grasp = GraspWatch(model, grasp_check_config)
        self.msgs = msgs
        self.config = nominal_config
        self.controller = NominalController(nominal_config)
        self.reference: ReferenceSource | None = None
        self.last_output: NominalOutput | None = None
        self.stream = stream
        self.topic_names = stream.topics() | dict(topic_names or {})
        self.inputs = NominalInputs(model, stream, self.topic_names, parse)
        no_tick = (
            'inputs arrive, but no joint state and object pose make a tick'
            if self.inputs.objects is not None
            else 'inputs arrive, but no joint state and odometry of one stamp'
        )
        self.input_watchdog = InputWatchdog(self.topic_names, no_tick=no_tick)
        self.ticked = False
        self.rejected_count = 0
        self._reports = ReportThrottle()
        self._joint_names = list(model.joint_names)
        self._joint_name_tuple = tuple(self._joint_names)
        self._initial_pose: Pose | None = None
        self._t0: float | None = None
        self._trajectory: ReferenceTrajectory | None = None
        self._last_tick_ns: int | None = None

    # -------------------------------------------------------------------------- inputs
    def on_joint_states(
        self, msg: Any, now: float | None = None, wall: float | None = None
    ) -> list[Outgoing]:
        """Handle ``/hand/joint_states``: a tick, or one once its odometry is in (``exact``).

        Args:
            msg: The message.
            now: The node's clock, s: the stamp of a rejection's status (None: the last
                tick's).
            wall: The steady clock at receipt, s (for :meth:`watchdog`; None: not watched).

        """
        if wall is not None:
            self.input_watchdog.received(JOINT_STATES, wall)
        return self._answer(self.inputs.joint_states(msg), now)

    def on_odom(
        self, msg: Any, now: float | None = None, wall: float | None = None
    ) -> list[Outgoing]:
        """Handle the object's pose: a sample of the tracker (``latest``), or a tick's odometry.

        Args as :meth:`on_joint_states`; ``latest`` checks the sample's age against ``now``.

        """
        if wall is not None:
            self.input_watchdog.received(OBJECT_ODOM, wall)
        return self._answer(self.inputs.object_pose(msg, now), now)

    def _answer(self, answer: Tick | Rejection | None, now: float | None) -> list[Outgoing]:
        if answer is None:
            return []
        if isinstance(answer, Rejection):
            if answer.stamp is not None and self.inputs.objects is None:
                self._last_tick_ns = answer.stamp  # a pair the model refused: a tick
            return self._rejected(answer.error, now, answer.stamp)
        return self._tick(answer.stamp, answer.state, now)

    def watchdog(self, now_wall: float, now: float) -> list[Outgoing]:
        """Before the first tick, every second: a WARN saying what the first tick waits for.

        Args:
            now_wall: The steady clock, s (that of the handlers' ``wall``).
            now: The node's clock, s: the status's stamp.

        Returns:
            Nothing once a tick has been answered, or when no report is due.

        """
        if self.ticked:
            return []
        waiting = self.input_watchdog.waiting(now_wall)
        if waiting is None:
            return []
        waited, missing, what = waiting
        text = bounded_text(f'waiting {waited:.1f} s for a first tick, no command: {what}')
        values = {'input.waiting': True, 'input.missing': ','.join(missing)}
        return [self._status(max(now, 0.0), DiagnosticLevel.WARN, text, values)]

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
            return self._rejected(error, None)
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
    def _tick(self, stamp: int, state: GraspState, now: float | None) -> list[Outgoing]:
        """u_nom of one state (and the reference sample it tracked), stamped ``stamp`` (ns)."""
        self._last_tick_ns = stamp
        self.ticked = True
        t = state.t
        try:
            if not self.grasp.started and self.grasp.check(state):
                return self._no_grasp(stamp, state)
            sample = self._reference_sample(t, state)
            output = self.controller.compute(state, sample)
        except (ValueError, np.linalg.LinAlgError) as error:
            return self._rejected(error, now, stamp)
        if not np.all(np.isfinite(output.u)):
            error = MessageError(f'u_nom is not finite: {output.u.tolist()}')
            return self._rejected(error, now, stamp)
        self.last_output = output
        outgoing = [
            stamped(EFFORT_NOMINAL, effort_to_msg(self.msgs, stamp, self._joint_names, output.u)),
            stamped(OBJECT_REFERENCE_SAMPLE, self._reference_msg(stamp, sample)),
        ]
        if output.reference_stale:
            outgoing.append(self._stale_reference_status(stamp, t))
        return outgoing

    def _reference_sample(self, t: float, state: GraspState) -> ReferenceSample:
        if self.reference is None:
            self._initial_pose = Pose(state.p_object_in_palm, state.R_object_to_palm)
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

    def _reference_msg(self, stamp: int, sample: ReferenceSample) -> Any:
        """Return the tracked sample as ``nav_msgs/Odometry``, framed as ``/object/odom``."""
        # The pose's parts without a Pose: a rotation built from Euler angles needs no check
        # here, and odometry_to_msg checks it again anyway.
        return odometry_to_msg(
            self.msgs,
            stamp,
            sample.p_in_palm,
            sample.R_to_palm,
            sample.twist,
            frame_id=self.model.palm_frame,
            child_frame_id=self.model.object_frame,
        )

    def _stale_reference_status(self, stamp: int, t: float) -> Outgoing:
        reference = self.reference
        age = reference.age(t) if isinstance(reference, TopicReference) else math.inf
        text = (
            'no /object/reference received yet: holding the initial object pose'
            if math.isinf(age)
            else f'/object/reference is {age:.3f} s old (timeout {self.config.timeout} s): '
            'holding its last pose'
        )
        values = {
            'reference.stale': True,
            'reference.age': age,
            'reference.timeout': self.config.timeout,
        }
        return self._status(stamp, DiagnosticLevel.WARN, text, values)

    def _no_grasp(self, stamp: int, state: GraspState) -> list[Outgoing]:
        """``u_nom = g(q)`` and an ERROR naming what fails: the grasp is not valid yet."""
        findings = findings_text(self.grasp.findings)
        text = bounded_text(
            'not a valid grasp (start-up check), u_nom = g(q) (gravity compensation), '
            f'reference not started: {findings}'
        )
        return [
            stamped(
                EFFORT_NOMINAL,
                effort_to_msg(self.msgs, stamp, self._joint_names, state.gravity_torque),
            ),
            self._status(stamp, DiagnosticLevel.ERROR, text, self.grasp.diagnostic_values()),
        ]

    def _rejected(
        self, error: Exception, now: float | None, stamp: int | None = None
    ) -> list[Outgoing]:
        """Return a WARN naming the rejected input, no command; at most one a second.

        Stamped ``stamp`` (ns: the tick's, when one was under way), else the node clock's
        ``now`` (s), else the last tick's stamp.
        """
        self.rejected_count += 1
        self.input_watchdog.rejected(error)
        if stamp is None and now is not None:
            stamp = seconds_to_nanoseconds(max(now, 0.0))
        elif stamp is None:
            stamp = self._last_tick_ns or 0
        since = self._reports.due('input', stamp)
        if since is None:
            return []
        text = bounded_text(f'input rejected, no command ({since} since the last report): {error}')
        values = {'input.rejected': True, 'input.rejected_count': self.rejected_count}
        return [self._status(stamp, DiagnosticLevel.WARN, text, values)]

    def _status(
        self, t: Stamp, level: DiagnosticLevel, text: str, values: Mapping[str, Any]
    ) -> Outgoing:
        """Return the nominal controller's status stamped ``t`` (integer ns, or s)."""
        return diagnostic_status(self.msgs, t, DIAGNOSTIC_NAME, level, text, values)
