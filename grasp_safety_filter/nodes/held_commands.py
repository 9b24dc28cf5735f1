"""The safety filter's answers without a QP: a held or fallback u*, and the status saying why.

Three cases reach the hold policy (:mod:`grasp_safety_filter.control.hold_policy`) instead
of the QP: a rejected input (``input_held``, ``input_fallback``), a state that is not a
grasp (``grasp_invalid``, ``grasp_held``, ``grasp_fallback``:
:mod:`grasp_safety_filter.nodes.grasp_watch`) and inputs that stopped (the input watchdog's
``input_fallback``). :class:`HeldCommands` asks the policy for the command (the last safe
u*, or after ``input.hold_timeout`` the fallback: zero torque or ``g(q)`` at the last
accepted joint positions, clipped to the actuator limits) and builds the command message
and its ``safety_filter`` status; the endpoint decides the stamp and closes the tick.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np

from grasp_safety_filter.control.hold_policy import Fallback, HoldPolicy
from grasp_safety_filter.io.diagnostic_keys import (
    INPUT_MODE_STATUS,
    InputMode,
    Key,
    silent_for,
    TickStatus,
)
from grasp_safety_filter.io.messages import (
    bounded_text,
    DiagnosticLevel,
    MessageNamespace,
    Stamp,
)
from grasp_safety_filter.nodes.command_output import CommandOutput
from grasp_safety_filter.nodes.grasp_watch import findings_text, GraspWatch
from grasp_safety_filter.nodes.input_watchdog import Silence
from grasp_safety_filter.nodes.outgoing import Outgoing
from grasp_safety_filter.nodes.publication_rate import PublicationRate, ReportThrottle

#: Builds the ``safety_filter`` status: stamp (integer ns, or s), level, summary, values.
StatusBuilder = Callable[[Stamp, DiagnosticLevel, str, dict[str, Any]], Outgoing]


class HeldCommands:
    """The hold policy's commands and their statuses (module docstring).

    Args:
        model: The ``GraspModel`` (joint names, ``hand.terms`` for ``g(q)``).
        hold: The hold policy.
        msgs: Message classes to build.
        command: Builds the command messages.
        rate: The publication rate (counts every status).
        status: Builds the ``safety_filter`` status.

    Attributes:
        last_positions: The joint positions of the last answered tick, rad (None before):
            the gravity fallback's q.
        ignored_count: Inputs rejected without a command (:meth:`ignored`) so far.

    """

    def __init__(
        self,
        model: Any,
        hold: HoldPolicy,
        msgs: MessageNamespace,
        command: CommandOutput,
        rate: PublicationRate,
        status: StatusBuilder,
    ) -> None:
        self.model = model
        self.hold = hold
        self.msgs = msgs
        self.command = command
        self.rate = rate
        self.status = status
        self.last_positions: np.ndarray | None = None
        self.ignored_count = 0
        self._reports = ReportThrottle()
        self._joint_names = list(model.joint_names)

    def gravity(self) -> tuple[np.ndarray | None, str]:
        """``g(q)`` for a gravity-compensation fallback, at the last accepted joint positions.

        Returns:
            The torque (None with the zero fallback) and a note for the status text (zero
            torque when no joint state has been accepted yet).

        """
        if self.hold.fallback is not Fallback.GRAVITY_COMPENSATION:
            return None, ''
        if self.last_positions is None:
            return np.zeros(len(self._joint_names)), ' (no joint state accepted yet: zero torque)'
        q = self.last_positions
        return self.model.hand.terms(q, np.zeros_like(q)).gravity_torque, ''

    def _action(self, note: str) -> str:
        if self.hold.mode is InputMode.HOLDING:
            return 'holding the last safe command'
        return f'fallback command: {self.hold.fallback.value}{note}'

    def ignored(self, topic: str, error: Exception, stamp: int) -> list[Outgoing]:
        """Report an input rejected where no command answers it (WARN), at most once a second.

        Before the filter's first tick (a driver that holds its position until commanded must
        not get a torque from a filter that has not computed one yet) and for a tracker
        sample (the ticks go on with the object's estimate). A stream rejected at the
        driver's rate is reported once a second of stamps per topic, with the count since the
        last report (:class:`~grasp_safety_filter.nodes.publication_rate.ReportThrottle`).
        """
        self.ignored_count += 1
        since = self._reports.due(topic, stamp)
        if since is None:
            return []
        values: dict[str, Any] = {
            Key.STATUS: TickStatus.INPUT_IGNORED.value,
            Key.INPUT_TOPIC: topic,
            Key.INPUT_IGNORED: self.ignored_count,
        }
        text = bounded_text(
            f'input rejected, no command sent ({since} on {topic} since the last report): '
            f'{error}'
        )
        return [self.status(stamp, DiagnosticLevel.WARN, text, values)]

    def rejected(self, topic: str, error: Exception, stamp: int, now: float) -> list[Outgoing]:
        """Answer a rejected input of ``topic`` at ``stamp`` (integer ns): held or fallback."""
        gravity, note = self.gravity()
        u = self.hold.reject(now, f'{topic}: {error}', gravity)
        status = INPUT_MODE_STATUS[self.hold.mode]
        self.rate.status_due(stamp, status)  # counted; never a steady status: always sent
        values: dict[str, Any] = {Key.STATUS: status.value, Key.INPUT_TOPIC: topic}
        values.update(self.hold.diagnostic_values(now))
        values.update(self.rate.counter_values())
        text = bounded_text(f'input rejected, {self._action(note)}: {error}')
        return [
            *self.command.messages(stamp, u),
            self.status(stamp, self.hold.diagnostic_level, text, values),
        ]

    def grasp_lost(self, grasp: GraspWatch, stamp: int, now: float) -> list[Outgoing]:
        """Answer a state that is not a grasp: always ERROR, naming each finding.

        Before any valid grasp the policy has no safe command: the fallback
        (``grasp_invalid``); after one, the last safe u* for ``input.hold_timeout``
        (``grasp_held``), then the fallback (``grasp_fallback``).
        """
        findings = findings_text(grasp.findings)
        gravity, note = self.gravity()
        u = self.hold.reject(now, f'grasp check: {findings}', gravity)
        if not grasp.started:
            status, what = TickStatus.GRASP_INVALID, 'not a valid grasp (start-up check)'
        elif self.hold.mode is InputMode.HOLDING:
            status, what = TickStatus.GRASP_HELD, 'contact lost'
        else:
            status, what = TickStatus.GRASP_FALLBACK, 'contact lost'
        self.rate.status_due(stamp, status)  # counted; never a steady status: always sent
        values: dict[str, Any] = {Key.STATUS: status.value, **grasp.diagnostic_values()}
        values.update(self.hold.diagnostic_values(now))
        values.update(self.rate.counter_values())
        text = bounded_text(f'{what}, {self._action(note)}: {findings}')
        return [
            *self.command.messages(stamp, u),
            self.status(stamp, DiagnosticLevel.ERROR, text, values),
        ]

    def absent(
        self, silence: Silence, last_tick: float, stamp: int, now: float
    ) -> list[Outgoing]:
        """Answer for the input watchdog: the fallback (at ``stamp``, ns) and an ERROR."""
        reason = (
            f'no tick accepted for {silence.elapsed:.3f} s of wall-clock time (last at t = '
            f'{last_tick:.6f} s): {silence.describe()}'
        )
        gravity, note = self.gravity()
        u = self.hold.absent(silence.elapsed, reason, gravity)
        values: dict[str, Any] = {
            Key.STATUS: INPUT_MODE_STATUS[self.hold.mode].value,
            Key.INPUT_WATCHDOG: True,
            Key.INPUT_MISSING: ','.join(silence.missing),
            Key.INPUT_WALL_TIME_SINCE_ACCEPTED: silence.elapsed,
        }
        values.update({silent_for(topic): age for topic, age in silence.silent.items()})
        values.update(self.hold.diagnostic_values(now))
        text = f'inputs missing, fallback command: {self.hold.fallback.value}{note}: {reason}'
        return [
            *self.command.messages(stamp, u),
            self.status(stamp, self.hold.diagnostic_level, text, values),
        ]

    def waiting(self, waited: float, missing: list[str], what: str, now: float) -> Outgoing:
        """Return the watchdog's WARN before any tick (no command): how long, for what."""
        return self.status(
            max(now, 0.0),
            DiagnosticLevel.WARN,
            f'waiting {waited:.1f} s for a first tick: {what}',
            {Key.INPUT_WATCHDOG: True, Key.INPUT_MISSING: ','.join(missing)},
        )
