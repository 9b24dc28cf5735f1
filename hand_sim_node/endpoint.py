"""The simulator's message-level endpoint: commands in, state, contacts and clock out.

Pure Python: the rclpy node (:mod:`hand_sim_node.node`) and the ROS-free runner call the
same methods and publish (or record) the returned :class:`Outgoing` lists, so both produce
the same stream. One tick in lockstep mode (the default)::

    state at t_k  ──/clock, /hand/joint_states, /object/odom──▶  controllers
    /hand/effort_command stamped t_k  ──▶  on_command
        ──▶ /hand/contacts stamped t_k (coordinates, rates, contact forces under u_k)
        ──▶ /clock, /hand/joint_states, /object/odom stamped t_k+1

- ``/hand/joint_states`` holds ``q`` (rad), ``dq`` (rad/s) and, as effort, the torque
  applied over the step that ended at its stamp (N·m; zero at t_0);
- ``/object/odom`` the object pose in the palm frame and its twist in the object frame
  (see :func:`grasp_safety_filter.io.messages.odometry_to_msg`);
- ``/clock`` the simulation time (when ``publish_clock`` is set).

A command is applied only if it parses (every joint by name, finite efforts) and its
stamp equals the current state's stamp; otherwise the endpoint reports it on
``/diagnostics`` (status ``hand_sim``, WARN) and does not step. As a hand driver does, it
clips an applied command to the model's effort limits (the URDF's), and says so in a WARN
``hand_sim`` status stamped t_k (``effort.clipped``: the joints; ``effort.max_excess`` and
``effort.excess.<joint>``: by how much, N·m). With ``command_delay`` the plant applies
the command stamped t_k from t_k + ``command_delay`` on (:mod:`hand_sim_node.command_delay`;
the clip status is the command's, at t_k). If no command arrives
within ``command_timeout`` s of wall time, :meth:`HandSimEndpoint.timeout` reports it and
publishes the current state again (same stamp), which recovers a command or state lost
while the graph was still connecting. The run ends after ``duration`` (the state at
``t = duration`` is published) or when the simulator stops on an event; a last
``hand_sim`` status says which (``run.stop_reason``: ``duration``, ``fingertip_workspace``,
``slip`` or ``numerical_failure``; on MuJoCo ``object_dropped``).

The plant (parameter ``plant``) is our rigid model or MuJoCo (:mod:`hand_sim_node.plant`);
both give the same topics. ``/hand/contacts`` then holds our model's contact coordinates at
MuJoCo's state and MuJoCo's contact forces in our contact frames, and a plant with real
contacts adds its events to ``hand_sim`` statuses (:class:`~grasp_safety_filter.io.
sim_diagnostic_keys.PlantEvents`): a WARN stamped t_k+1 when a contact is first lost or the
object drops, and the record so far (with the slip distance per contact) in it and in the
end-of-run status.

This endpoint is the lockstep mode's (``lockstep: true``; the runner's, whatever the
parameter says). With ``lockstep: false`` the node runs the hardware mode instead, a hand's
driver and an object tracker on the wall clock (:mod:`hand_sim_node.hardware`).

What it shares with the hardware mode (the plant's run, its end, the contact events, the
live parameters) is :class:`~hand_sim_node.plant_endpoint.PlantEndpoint`; the ``hand_sim``
statuses themselves are built in :mod:`hand_sim_node.sim_status`.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from grasp_safety_filter.io.messages import (
    clock_to_msg,
    DiagnosticReport,
    diagnostics_to_msg,
    effort_from_msg,
    MessageError,
    MessageNamespace,
    seconds_to_nanoseconds,
)
from grasp_safety_filter.io.topics import CLOCK, DIAGNOSTICS, EFFORT_COMMAND, OBJECT_ODOM, SCENARIO
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.outgoing import Outgoing, stamped
from hand_sim_node.command_delay import CommandDelay
from hand_sim_node.config import SimConfig
from hand_sim_node.plant import PlantConfig
from hand_sim_node.plant_endpoint import PlantEndpoint
from hand_sim_node.sim_status import clip_to_limits, command_timeout_report, command_warning
from hand_sim_node.simulator import Simulator
from hand_sim_node.state_messages import StateMessages


class HandSimEndpoint(PlantEndpoint):
    """The hand–object simulator behind ``/hand/effort_command`` (module docstring).

    Arguments and attributes: :class:`~hand_sim_node.plant_endpoint.PlantEndpoint`'s.
    """

    def __init__(
        self,
        model: GraspModel,
        sim_config: SimConfig,
        msgs: MessageNamespace,
        scenario_text: str | None = None,
        plant_config: PlantConfig | None = None,
    ) -> None:
        super().__init__(model, sim_config, msgs, scenario_text, plant_config)
        self._joint_names = list(model.joint_names)
        self.messages = StateMessages(model, msgs, OBJECT_ODOM)
        self._delay = CommandDelay(sim_config.command_delay_steps)
        self._waiting_since: float | None = None

    # ------------------------------------------------------------------------ properties
    @property
    def simulator(self) -> Simulator:
        """Rigid plant only: the Simulator it wraps; another plant raises AttributeError."""
        return self.plant.simulator  # type: ignore[attr-defined]

    @property
    def command_timeout(self) -> float:
        """Lockstep wait for a command before a diagnostic, s (wall time)."""
        return self.config.command_timeout

    @property
    def stamp_ns(self) -> int:
        """Stamp of the current state, integer ns."""
        return seconds_to_nanoseconds(self.t)

    @property
    def awaited_stamp_ns(self) -> int | None:
        """Stamp of the command the simulator waits for, or None if it waits for none."""
        if not self._started or self.finished:
            return None
        return self.stamp_ns

    # ------------------------------------------------------------------------------ run
    def start(self, now: float = 0.0) -> list[Outgoing]:
        """Reset the run; return ``/grasp/scenario`` and the state at t_0.

        Args:
            now: Wall-clock time, s (any origin), for the lockstep timeout.

        """
        self.plant.reset()
        self._reset_run()
        self._delay.reset()
        self._started = True
        self._waiting_since = float(now)
        scenario = Outgoing(SCENARIO, self.stamp_ns, self.msgs.String(data=self.scenario_text))
        return [scenario, *self._state_messages()]

    def on_command(self, msg: Any, now: float = 0.0) -> list[Outgoing]:
        """Handle a ``/hand/effort_command``; step when it is the awaited one.

        Args:
            msg: A ``sensor_msgs/JointState`` with one effort per joint, by name.
            now: Wall-clock time, s, for the lockstep timeout.

        Returns:
            Applied: ``/hand/contacts`` at t_k, then the state at t_k+1 (or the end-of-run
            status). Rejected: one ``/diagnostics`` message.

        """
        if not self._started:
            return self._warn('command before the simulation started: ignored', msg)
        if self.finished:
            return []  # the controllers answer the final state; nothing left to apply
        try:
            command = effort_from_msg(msg, self._joint_names, source=EFFORT_COMMAND)
            stamp_ns = seconds_to_nanoseconds(command.t)
        except MessageError as error:
            return self._warn(f'command rejected: {error}', msg)
        if stamp_ns != self.stamp_ns:
            when = 'late' if stamp_ns < self.stamp_ns else 'early'
            return self._warn(
                f'command stamped {command.t:.9f} s is {when}: waiting for the one stamped '
                f'{self.t:.9f} s; not applied',
                msg,
            )
        self._waiting_since = float(now)
        return self._step(stamp_ns, command.effort)

    def timeout(self, now: float) -> list[Outgoing]:
        """Lockstep watchdog: report a missing command and publish the state again.

        Args:
            now: Wall-clock time, s, on the clock of the ``now`` given to :meth:`start`
                and :meth:`on_command`.

        Returns:
            Nothing while the wait is shorter than ``command_timeout``; else a WARN status
            and the current state (same stamp), and the wait starts over.

        """
        awaited = self.awaited_stamp_ns
        if awaited is None or self._waiting_since is None:
            return []
        waited = float(now) - self._waiting_since
        if waited < self.command_timeout:
            return []
        self._waiting_since = float(now)
        report = command_timeout_report(self.t, waited, self.command_timeout)
        return [self._diagnostics(report), *self._state_messages()]

    # ------------------------------------------------------------------------- internals
    def _step(self, stamp_ns: int, effort: np.ndarray) -> list[Outgoing]:
        """Apply the command stamped ``stamp_ns`` (the current state's), ``effort`` in N·m."""
        applied, clipped = self._clip_to_limits(effort)
        report = self._step_plant(self._delay(applied))
        outgoing = [] if clipped is None else [clipped]
        outgoing.append(self.messages.contacts(stamp_ns, report))
        if report.state is not report.start:  # integrated (a rigid stop is not)
            outgoing += self._state_messages()
        event = self._contact_event_report()
        if event is not None:
            outgoing.append(self._diagnostics(event))
        if self.finished and not self._reported_end:
            outgoing.append(self._diagnostics(self._end_of_run_report()))
        return outgoing

    def _clip_to_limits(self, effort: np.ndarray) -> tuple[np.ndarray, Outgoing | None]:
        """Return the applied torque, N·m, and a WARN if it was clipped: :func:`clip_to_limits`."""
        limits, names = self.model.effort_limits, self._joint_names
        applied, report = clip_to_limits(effort, limits, names, self.t)
        return applied, None if report is None else self._diagnostics(report)

    def _state_messages(self) -> list[Outgoing]:
        """Return ``/clock`` (with ``publish_clock``), then the current state's messages."""
        state = self.plant.observe()
        stamp_ns = seconds_to_nanoseconds(state.t)
        messages = self.messages.state(stamp_ns, state, self._applied_effort)
        if self.config.publish_clock:
            messages.insert(0, stamped(CLOCK, clock_to_msg(self.msgs, state.t)))
        return messages

    def _warn(self, text: str, msg: Any) -> list[Outgoing]:
        return [self._diagnostics(command_warning(text, msg, self.t))]

    def _diagnostics(self, report: DiagnosticReport) -> Outgoing:
        return stamped(DIAGNOSTICS, diagnostics_to_msg(self.msgs, self.t, report))
