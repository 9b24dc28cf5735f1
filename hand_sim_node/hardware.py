"""The simulator's hardware mode: a hand's driver and an object tracker on the wall clock.

With ``lockstep: false`` ``hand_sim_node`` behaves as a real hand's driver plus an object
tracker do (DESIGN.md §9), so that a ROS stack can be tried on the rigid plant or on MuJoCo
before the real hand. Pure Python, as the lockstep endpoint
(:mod:`hand_sim_node.endpoint`): the node (:mod:`hand_sim_node.node`) calls
:meth:`HardwareEndpoint.tick` from a steady-clock timer at ``hardware.rate`` and
:meth:`HardwareEndpoint.on_command` for each command, and publishes what they return.

- **Driver periods.** The period ``1 / hardware.rate`` is a whole number of ``time_step``
  (``1 / (rate time_step)`` integration steps of the plant). Period ``k`` is due at
  ``start + k period`` of the steady clock, where the timer (created at ``start``, never
  early) fires; a call integrates the periods due with the command held: one when it comes
  less than a period late. A later call catches up the periods it missed, at most
  :data:`MAX_CATCH_UP_PERIODS` in all: more are skipped (never integrated: simulated time
  falls behind the wall clock). Periods integrated late (their state not published) and
  skipped are counted and reported in the ``hand_sim`` status
  (:mod:`hand_sim_node.hardware_status`).
- **Published every period**, whether or not a command came, each stamped with the node's
  clock (system time, integer ns, read once per state; strictly increasing): the tracker's
  samples due (:mod:`hand_sim_node.tracker`), ``/hand/joint_states`` and
  ``/object/true_odom`` (:mod:`hand_sim_node.state_messages`); once released,
  ``/hand/contacts`` with the contact data of the call's last integration step. No ``/clock``.
- **Release.** Until the first valid command the plant stands still: the object is held
  where it is and the hand too (a real grasp starts with its forces built up); the state is
  published all the same. The first command releases it; ``duration`` counts simulated
  time from then on, and the run ends there (or on the plant's stop), with the lockstep
  mode's end-of-run status.
- **Commands** (:mod:`hand_sim_node.hardware_commands`): held from period to period
  (zero-order hold), clipped to the URDF's effort limits (a WARN once per command over
  them). An invalid command is refused with a WARN naming the problem; the last valid one
  stays applied. Stamps are not checked.
- **Command timeout.** Once ``hardware.command_timeout`` s of wall time pass without a
  valid command, the plant gets ``hardware.timeout_torque`` (``gravity_compensation``:
  g(q) of our model at the plant's q, per period; ``zero``) and ``/diagnostics`` an ERROR,
  repeated in each regular status (naming how long), until a command comes (an OK status).
"""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages import (
    DiagnosticLevel,
    DiagnosticReport,
    diagnostics_to_msg,
    format_diagnostic_value,
    MessageError,
    MessageNamespace,
    NANOSECONDS_PER_SECOND,
    seconds_to_nanoseconds,
)
from grasp_safety_filter.io.topics import (
    CONTACTS,
    DIAGNOSTICS,
    JOINT_STATES,
    OBJECT_TRUE_ODOM,
    SCENARIO,
)
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.outgoing import Outgoing
from hand_sim_node.config import SimConfig
from hand_sim_node.hardware_commands import CommandReader, SafeTorque
from hand_sim_node.hardware_config import HardwareConfig
from hand_sim_node.hardware_status import (
    driver_values,
    DriverCounts,
    regular_text,
    STATUS_PERIOD_NS,
    timed_out_text,
)
from hand_sim_node.plant import PlantConfig
from hand_sim_node.plant_endpoint import PlantEndpoint
from hand_sim_node.sim_status import clip_to_limits, sim_report
from hand_sim_node.state_messages import StateMessages
from hand_sim_node.tracker import TrackerEmulator

#: Most driver periods one timer call integrates; a later call skips the rest.
MAX_CATCH_UP_PERIODS = 4


class HardwareEndpoint(PlantEndpoint):
    """The hardware mode's driver and tracker over a :class:`Plant` (module docstring).

    Times: ``now_ns`` is the steady clock (periods, timeouts; integer ns, any origin),
    ``stamp_ns`` the node's clock the messages are stamped with (default: ``now_ns``).

    Args: :class:`~hand_sim_node.plant_endpoint.PlantEndpoint`'s, and ``hardware``, the
    driver's and the tracker's configuration.

    Raises:
        ParameterError: ``1 / hardware.rate`` is not a whole number of ``time_step``.
        MessageError: ``hardware.command_joints`` does not name every model joint once.
    """

    def __init__(
        self,
        model: GraspModel,
        sim_config: SimConfig,
        hardware: HardwareConfig,
        msgs: MessageNamespace,
        scenario_text: str | None = None,
        plant_config: PlantConfig | None = None,
    ) -> None:
        self.hardware = hardware
        self.substeps = hardware.substeps(sim_config.time_step)
        self.period_ns = seconds_to_nanoseconds(self.substeps * sim_config.time_step)
        self.commands = CommandReader(hardware, model.joint_names)
        self.tracker = TrackerEmulator(
            hardware.tracker, msgs, model.palm_frame, model.object_frame
        )
        self._safe_torque = SafeTorque(model, hardware.timeout_torque)
        self.messages = StateMessages(
            model, msgs, OBJECT_TRUE_ODOM, hardware.extra_joint_names()
        )
        super().__init__(model, sim_config, msgs, scenario_text, plant_config)

    def _reset_run(self) -> None:
        """Forget the run so far: the plant's, the driver's and the tracker's."""
        super()._reset_run()
        self.counts = DriverCounts()
        self._command: np.ndarray | None = None
        self._last_command_ns: int | None = None
        self._timed_out = False
        self._origin_ns = 0
        self._periods_done = 0
        self._last_stamp_ns = -1
        self._status_due_ns = 0
        self._status_counts = (0, 0)
        self._now_ns = 0
        self.tracker.reset()

    # ------------------------------------------------------------------------ properties
    @property
    def topics(self) -> tuple[str, ...]:
        """The topics this endpoint publishes."""
        tracker = self.hardware.tracker.topic
        return (SCENARIO, JOINT_STATES, tracker, OBJECT_TRUE_ODOM, CONTACTS, DIAGNOSTICS)

    @property
    def released(self) -> bool:
        """Whether a first valid command released the plant."""
        return self._command is not None

    @property
    def timed_out(self) -> bool:
        """Whether the commands are timed out (the timeout torque is applied)."""
        return self._timed_out

    # ------------------------------------------------------------------------------ run
    def start(self, now_ns: int, stamp_ns: int | None = None) -> list[Outgoing]:
        """Start the driver at ``now_ns``: ``/grasp/scenario``, the first state and status."""
        self.plant.reset()
        self._reset_run()
        self._started = True
        self._origin_ns = self._status_due_ns = self._now_ns = int(now_ns)
        stamp = self._stamp(now_ns if stamp_ns is None else stamp_ns)
        scenario = Outgoing(SCENARIO, stamp, self.msgs.String(data=self.scenario_text))
        return [scenario, *self._period_messages(stamp, None)]

    def tick(self, now_ns: int, stamp_ns: int | None = None) -> list[Outgoing]:
        """Integrate the driver periods due at ``now_ns`` and publish the state (module docstring).

        Returns:
            Nothing if no period is due (or before the start, after the end); else the
            tracker samples due, the joint states, the true odometry, the contacts (once
            released), and the statuses due (timeout, contact events, regular, end of run).
        """
        if not self._started or self.finished:
            return []
        self._now_ns = now_ns = int(now_ns)
        period = self.period_ns
        k = (now_ns - self._origin_ns) // period
        due = k - self._periods_done
        if due <= 0:
            return []
        stamp = self._stamp(now_ns if stamp_ns is None else stamp_ns)
        integrate = min(due, MAX_CATCH_UP_PERIODS)
        self.counts.late += integrate - 1
        self.counts.skipped += due - integrate
        self._periods_done = k
        out = self._check_timeout(now_ns, stamp)
        contacts = None
        if self.released:
            for _ in range(integrate):
                out += self._integrate_period(stamp)
                if self.finished:
                    break
            report = self.plant.last_report
            contacts = None if report is None else self.messages.contacts(stamp, report)
        return out + self._period_messages(stamp, contacts)

    def on_command(self, msg: Any, now_ns: int, stamp_ns: int | None = None) -> list[Outgoing]:
        """Take a command: hold it from the next period on (module docstring).

        Returns:
            ``/diagnostics``: a WARN if refused or clipped; an OK on the release and when
            commands resume after a timeout; nothing otherwise.
        """
        stamp = int(now_ns if stamp_ns is None else stamp_ns)
        self._now_ns = max(self._now_ns, int(now_ns))
        if not self._started:
            return [self._status(stamp, DiagnosticLevel.WARN, 'command before the start: ignored')]
        if self.finished:
            return []
        try:
            effort = self.commands.read(msg)
        except MessageError as error:
            self.counts.refused += 1
            text = f'command refused: {error}; the last valid command stays applied'
            return [self._status(stamp, DiagnosticLevel.WARN, text)]
        applied, clipped = clip_to_limits(
            effort, self.model.effort_limits, self.model.joint_names, self.t
        )
        out = [] if clipped is None else [self._diagnostics(stamp, clipped)]
        released, previous_ns = self.released, self._last_command_ns
        self._command = applied
        self._last_command_ns = int(now_ns)
        self.counts.received += 1
        if not released:
            out.append(self._status(stamp, DiagnosticLevel.OK, 'first command: plant released'))
        elif self._timed_out:
            self._timed_out = False
            gap = (int(now_ns) - (previous_ns or 0)) / NANOSECONDS_PER_SECOND
            text = f'commands resumed after {gap:.3f} s without: applying them again'
            out.append(self._status(stamp, DiagnosticLevel.OK, text))
        return out

    # ------------------------------------------------------------------------- internals
    def _stamp(self, stamp_ns: int) -> int:
        """Return ``stamp_ns`` (ns), or 1 ns past the last stamp if it is not later."""
        self._last_stamp_ns = max(int(stamp_ns), self._last_stamp_ns + 1)
        return self._last_stamp_ns

    def _command_age(self) -> float | None:
        if self._last_command_ns is None:
            return None
        return (self._now_ns - self._last_command_ns) / NANOSECONDS_PER_SECOND

    def _check_timeout(self, now_ns: int, stamp: int) -> list[Outgoing]:
        if self._last_command_ns is None or self._timed_out:
            return []
        if now_ns - self._last_command_ns <= self.hardware.command_timeout_ns:
            return []
        self._timed_out = True
        self.counts.timeouts += 1
        text = timed_out_text(self._command_age() or 0.0, self.hardware.timeout_torque)
        return [self._status(stamp, DiagnosticLevel.ERROR, text)]

    def _integrate_period(self, stamp: int) -> list[Outgoing]:
        """Integrate one driver period with the held command or the timeout torque."""
        effort = self._safe_torque(self.plant.observe().q) if self._timed_out else self._command
        out: list[Outgoing] = []
        for _ in range(self.substeps):
            if self.finished:
                break
            self._step_plant(effort)
            event = self._contact_event_report()
            if event is not None:
                out.append(self._diagnostics(stamp, event))
        return out

    def _period_messages(self, stamp: int, contacts: Outgoing | None) -> list[Outgoing]:
        """Return the tracker samples due, the state, true odometry, contacts, statuses due."""
        state = self.plant.observe()
        out = self.tracker.on_state(self._periods_done * self.period_ns, stamp, state)
        out += self.messages.state(stamp, state, self._applied_effort)
        self.counts.periods += 1
        if contacts is not None:
            out.append(contacts)
        if self._now_ns >= self._status_due_ns:
            self._status_due_ns = self._now_ns + STATUS_PERIOD_NS
            out.append(self._regular_status(stamp))
        if self.finished and not self._reported_end:
            out.append(self._end_of_run(stamp))
        return out

    def _values(self) -> dict[str, Any]:
        return driver_values(
            self.counts,
            t=self.t,
            released=self.released,
            command_age=self._command_age(),
            timed_out=self._timed_out,
            timeout_torque=self.hardware.timeout_torque,
            command_timeout=self.hardware.command_timeout,
            tracker_samples=self.tracker.published,
        )

    def _regular_status(self, stamp: int) -> Outgoing:
        late, skipped = self._status_counts
        self._status_counts = (self.counts.late, self.counts.skipped)
        level, text = regular_text(
            self.released,
            self._timed_out,
            self._command_age(),
            self.counts.late - late,
            self.counts.skipped - skipped,
            self.hardware.timeout_torque,
        )
        return self._status(stamp, level, text)

    def _end_of_run(self, stamp: int) -> Outgoing:
        report = self._end_of_run_report()
        driver = {k: format_diagnostic_value(v) for k, v in self._values().items()}
        return self._diagnostics(
            stamp, dataclasses.replace(report, values={**driver, **report.values})
        )

    def _status(self, stamp: int, level: DiagnosticLevel, text: str) -> Outgoing:
        return self._diagnostics(stamp, sim_report(level, text, self._values()))

    def _diagnostics(self, stamp: int, report: DiagnosticReport) -> Outgoing:
        return Outgoing(DIAGNOSTICS, stamp, diagnostics_to_msg(self.msgs, stamp, report))
