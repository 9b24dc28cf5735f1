"""The safety filter's message-level endpoint: state and u_nom in, u* out.

Pure Python, shared by the rclpy node (:mod:`~grasp_safety_filter.nodes.safety_filter_node`)
and the ROS-free runner. A tick::

    /hand/joint_states + object state + /hand/effort_nominal, one stamp t
        ──▶ GraspModel.state ──▶ SafetyFilter.solve(state, u_nom) ──▶ HoldPolicy.accept
        ──▶ /hand/effort_command stamped t (u* by joint name, N·m), and when due
            /safety_filter/margins and the ``safety_filter`` status on /diagnostics

With ``input.sync: exact`` (the lockstep simulator) a tick runs when the three inputs of one
stamp are in hand and valid (:mod:`~grasp_safety_filter.nodes.tick_inputs`); with ``latest``
(a real hand's driver and tracker) each joint state is a tick, the object's state estimated at
its stamp (:mod:`~grasp_safety_filter.nodes.latest_inputs`).

Input that fails its checks (joints by name, NaN, size, stale, future, out of order) gets no
computed command: the hold policy's (:mod:`~grasp_safety_filter.nodes.held_commands`), and
none at all before the first tick. The input watchdog
(:mod:`~grasp_safety_filter.nodes.input_watchdog`) sends the fallback once no tick has been
answered for ``input.hold_timeout`` s of wall time. The grasp check
(:mod:`~grasp_safety_filter.nodes.grasp_watch`) keeps the QP off states that are not the grasp.
With ``enabled=False`` (the paper's unfiltered run) u* = u_nom, validated alike, status WARN.
The whole behaviour, for users: ``docs/ros_nodes.md``.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
import time
from typing import Any

import numpy as np

from grasp_safety_filter.control.hold_policy import HoldPolicy, InputPolicyConfig
from grasp_safety_filter.control.safety_filter import (
    FilterResult,
    Margins,
    SafetyFilter,
    SafetyFilterConfig,
)
from grasp_safety_filter.io.messages import (
    DiagnosticLevel,
    FutureStampError,
    MessageError,
    MessageNamespace,
    nanoseconds_to_seconds,
    OutOfOrderError,
    StaleInputError,
    Stamp,
)
from grasp_safety_filter.io.topics import EFFORT_NOMINAL, JOINT_STATES, OBJECT_ODOM
from grasp_safety_filter.nodes.command_output import CommandConfig, CommandOutput
from grasp_safety_filter.nodes.filter_status import status_message, TickContext
from grasp_safety_filter.nodes.grasp_watch import GraspCheckConfig, GraspWatch, LogLine
from grasp_safety_filter.nodes.held_commands import HeldCommands
from grasp_safety_filter.nodes.input_watchdog import InputWatchdog, NOMINAL_HINT
from grasp_safety_filter.nodes.latest_inputs import tick_assembler
from grasp_safety_filter.nodes.object_stream import EXACT, StreamConfig
from grasp_safety_filter.nodes.outgoing import Outgoing
from grasp_safety_filter.nodes.publication_rate import PublicationRate, PublicationRateConfig
from grasp_safety_filter.nodes.shared_parse import SharedParse
from grasp_safety_filter.nodes.startup_log import StartupLog
from grasp_safety_filter.nodes.tick_answer import TickAnswer
from grasp_safety_filter.nodes.tick_inputs import REPLAY, TickInputs


class SafetyFilterEndpoint:
    """The CBF-QP safety filter over messages (module docstring).

    Args:
        model: The ``GraspModel`` (joint and contact names, limits, ``state(...)``).
        filter_config: Constraint families, class-K functions, relaxation and OSQP settings.
        input_policy_config: ``input.max_age``, ``input.hold_timeout``, ``input.fallback``.
        msgs: Message classes to build (rclpy or rosbags).
        enabled: Filter on; off passes u_nom through (still validated).
        publication_rate_config: How often steady statuses and the margins go out
            (default: every tick).
        grasp_check_config: ``grasp_check.gap_tolerance`` (default: the start-up check's).
        parse: The joint state and odometry parses, shared with the nominal controller in
            process (:mod:`~grasp_safety_filter.nodes.shared_parse`); default: its own.
        wall_clock: The clock of the handlers' ``wall`` (``time.monotonic``), read when a
            tick is answered (:class:`~grasp_safety_filter.nodes.input_watchdog.InputWatchdog`).
        stream: ``input.sync`` and the object's estimate (default: ``exact``).
        command_config: ``command.*``: u* also in ros2_control's form (default: JointState).
        topic_names: The input topics as the node resolved them (remapped), by table name,
            for the texts (default: the table's; the object's: the configured one).

    Attributes:
        filter: The safety filter core; hold: the input hold policy.
        inputs: The input checks and the pending inputs of the ticks to come.
        enabled: u* filtered (True) or u_nom passed through (False): :meth:`switch`.
        last_result: The last tick's :class:`FilterResult` (None when disabled or before).

    """

    def __init__(
        self,
        model: Any,
        filter_config: SafetyFilterConfig,
        input_policy_config: InputPolicyConfig,
        msgs: MessageNamespace,
        enabled: bool = True,
        publication_rate_config: PublicationRateConfig | None = None,
        grasp_check_config: GraspCheckConfig | None = None,
        parse: SharedParse | None = None,
        wall_clock: Callable[[], float] | None = None,
        stream: StreamConfig = EXACT,
        command_config: CommandConfig | None = None,
        topic_names: Mapping[str, str] | None = None,
    ) -> None:
        self.model = model
        self.msgs = msgs
        self.enabled = bool(enabled)
        self.filter = SafetyFilter.from_config(model, filter_config)
        effort_limits = np.asarray(model.effort_limits, dtype=float)
        self.hold = HoldPolicy.from_config(
            input_policy_config, model.n_joints, -effort_limits, effort_limits
        )
        self.stream = stream
        self.topic_names = stream.topics(EFFORT_NOMINAL) | dict(topic_names or {})
        self.inputs = tick_assembler(
            stream, input_policy_config.max_age, model, parse, self.topic_names
        )
        self.rate = PublicationRate(publication_rate_config)
        self.grasp = GraspWatch(model, grasp_check_config)
        self.last_result: FilterResult | None = None
        self.command = CommandOutput(msgs, model.joint_names, command_config)
        self.answer = TickAnswer(msgs, self.command, self.rate, self._status_message)
        self._last_outputs: list[Outgoing] = []
        self.held = HeldCommands(
            model, self.hold, msgs, self.command, self.rate, self._status_message
        )
        self.input_watchdog = InputWatchdog(
            self.topic_names, {EFFORT_NOMINAL: NOMINAL_HINT}, wall_clock
        )
        self.ticked = False
        self._switched_at: float | None = None
        self._advice = StartupLog(model)

    # -------------------------------------------------------------------------- inputs
    def on_joint_states(
        self, msg: Any, now: float | None = None, wall: float | None = None
    ) -> list[Outgoing]:
        """Handle ``/hand/joint_states`` (see :meth:`on_effort_nominal`)."""
        return self._on_input(JOINT_STATES, msg, now, wall)

    def on_odom(
        self, msg: Any, now: float | None = None, wall: float | None = None
    ) -> list[Outgoing]:
        """Handle ``/object/odom`` (see :meth:`on_effort_nominal`)."""
        return self._on_input(OBJECT_ODOM, msg, now, wall)

    def on_effort_nominal(
        self, msg: Any, now: float | None = None, wall: float | None = None
    ) -> list[Outgoing]:
        """Handle ``/hand/effort_nominal``; return the messages to send (none: no tick yet).

        Args:
            msg: The message.
            now: The node's clock, s (simulation time under ``use_sim_time``). None: the
                last tick's time (a runner without a clock still detects stale input).
            wall: The steady clock at receipt, s (:meth:`watchdog`'s). None: not watched.

        """
        return self._on_input(EFFORT_NOMINAL, msg, now, wall)

    def watchdog(self, now_wall: float, now: float) -> list[Outgoing]:
        """Stand in for ticks that stopped coming: the fallback command and an ERROR.

        Called every :data:`~grasp_safety_filter.nodes.input_watchdog.WATCHDOG_PERIOD` s on
        a steady clock (under ``use_sim_time`` a dead simulator stops the node clock too).
        Before the first tick: a WARN saying what it waits for, every second, and no command
        (a driver must not get torques from a filter that has never seen its hand).
        Afterwards, once the last tick is ``input.hold_timeout`` s old: the fallback and an
        ERROR naming the silent inputs.

        Args:
            now_wall: The steady clock, s (that of the handlers' ``wall``).
            now: The node's clock, s: the fallback's stamp
                (:meth:`~grasp_safety_filter.nodes.tick_inputs.TickAssembler.fallback_stamp`).

        """
        if not self.input_watchdog.started:
            waiting = self.input_watchdog.waiting(now_wall)
            return [] if waiting is None else [self.held.waiting(*waiting, now)]
        silence = self.input_watchdog.silence(now_wall, self.hold.hold_timeout)
        if silence is None:
            return []
        last_tick = nanoseconds_to_seconds(self.inputs.last_tick_ns or 0)
        return self.held.absent(silence, last_tick, self.inputs.fallback_stamp(now), now)

    def switch(self, enabled: bool, now: float | None = None) -> str | None:
        """Switch the filter on or off from the next tick; say so (None if unchanged).

        Args:
            enabled: Filter on (True) or pass u_nom through (False).
            now: The node's clock, s, recorded as ``filter.switched_at``. None: the last
                tick's time.

        Returns:
            A line for the log (the node logs it at WARN when off, INFO when on).

        """
        enabled = bool(enabled)
        if enabled == self.enabled:
            return None
        self.enabled = enabled
        self._switched_at = self.inputs.now(None, now)[0]
        if enabled:
            return f'safety filter switched ON at t = {self._switched_at:.6f} s (node clock)'
        return (
            f'safety filter switched OFF at t = {self._switched_at:.6f} s (node clock): '
            'u* = u_nom, the grasp constraints are NOT enforced'
        )

    def update_config(
        self,
        filter_config: SafetyFilterConfig | None = None,
        input_policy_config: InputPolicyConfig | None = None,
        enabled: bool | None = None,
        publication_rate_config: PublicationRateConfig | None = None,
        grasp_check_config: GraspCheckConfig | None = None,
    ) -> None:
        """Apply new parameters from the next tick on (None: unchanged).

        A new filter configuration rebuilds the filter (and its OSQP problems); the hold
        policy keeps its last safe command and mode.
        """
        if filter_config is not None:
            self.filter = SafetyFilter.from_config(self.model, filter_config)
            self._advice.again()
        if input_policy_config is not None:
            self.inputs.guard.max_age = input_policy_config.max_age
            self.hold.hold_timeout = input_policy_config.hold_timeout
            self.hold.fallback = input_policy_config.fallback
        if enabled is not None:
            self.switch(enabled)
        if publication_rate_config is not None:
            self.rate.configure(publication_rate_config)
        if grasp_check_config is not None:
            self.grasp.config = grasp_check_config

    # ------------------------------------------------------------------------ internals
    def _on_input(
        self, topic: str, msg: Any, now: float | None, wall: float | None
    ) -> list[Outgoing]:
        now_s, is_clock = self.inputs.now(msg, now)
        if wall is not None:
            self.input_watchdog.received(topic, wall)
        try:
            data = self.inputs.parse(topic, msg)
            stamp = self.inputs.check(topic, data, now_s)
        except MessageError as error:
            if self.inputs.dropped(topic, error):
                return []
            return self._reject(topic, msg, error, now_s, close=is_clock)
        try:
            tick = self.inputs.add(topic, stamp, data)
        except MessageError as error:  # another input of its tick (input.sync latest)
            return self._reject(topic, msg, error, now_s, stamp=stamp)
        if tick is None:
            return []
        if tick == REPLAY:
            # The same tick again (e.g. a simulator that re-sent its state): same answer,
            # and the inputs did not stop (else the watchdog could answer the resent state
            # with the fallback right after its answer).
            if wall is not None:
                self.input_watchdog.answered_again(wall)
            return list(self._last_outputs)
        return self._tick(tick.joint_states.stamp_ns, tick, now_s, wall)

    def _tick(
        self, stamp: int, inputs: TickInputs, now: float, wall: float | None
    ) -> list[Outgoing]:
        start = time.perf_counter()
        t = inputs.joint_states.t
        self.ticked = True  # a state the model rejects is answered as a rejected input
        u_nom = inputs.nominal.effort
        state, model_time = self.inputs.state(stamp, inputs)
        start -= model_time  # the tick's time includes its model terms, whenever computed
        disabled_margins: Margins | None = None  # filter off: the margins at u_nom
        try:
            if isinstance(state, Exception):
                raise state
            if self.grasp.check(state):
                # No QP on a state that is not a grasp: the hold policy's answer, an ERROR.
                self._answered(stamp, inputs, wall)
                return self._remember(self.held.grasp_lost(self.grasp, stamp, now))
            if self.enabled:
                filter_start = time.perf_counter()
                result = self.filter.solve(state, u_nom)
                filter_time = time.perf_counter() - filter_start
                u = result.u
            else:
                result = None
                filter_time = 0.0
                u = u_nom
                # Computed here: a state the model rejects is rejected on this tick.
                disabled_margins = self.filter.margins(state, u_nom)
        except (ValueError, np.linalg.LinAlgError) as error:
            return self._reject(
                'state',
                None,
                MessageError(f'the model rejected the state at t = {t:.9f} s: {error}'),
                now,
                stamp,
            )
        self.last_result = result
        self._advice.first_state(state)
        u = self.hold.accept(now, u)
        resumed_after = self._answered(stamp, inputs, wall)
        # Every message is stamped t, whose ns is the tick's stamp.
        outgoing = self.answer.messages(
            stamp,
            u,
            result,
            disabled_margins,
            filter_time,
            start,
            lambda: TickContext(
                self._switched_at,
                self.rate.counter_values(),
                self.hold.diagnostic_values(now),
                resumed_after,
            ),
            resumed=resumed_after is not None,
        )
        return self._remember(outgoing)

    def _answered(self, stamp: int, inputs: TickInputs, wall: float | None) -> float | None:
        """Close a tick answered (by the QP, or the hold policy when the grasp is lost).

        Its joint state becomes the gravity fallback's q (an accepted measurement, never one
        merely parsed; with the grasp lost, of a hand that does not hold the object as the
        model assumes), and the input watchdog counts it as answered (the inputs do arrive).

        Returns:
            The wall-clock time without a tick if the watchdog had taken over, s; else None.

        """
        self.held.last_positions = np.array(inputs.joint_states.position)
        self.inputs.close(stamp)
        return None if wall is None else self.input_watchdog.accepted(wall)

    def _remember(self, outgoing: list[Outgoing]) -> list[Outgoing]:
        """Keep a tick's answer (sent again for a replay of the tick); return a copy."""
        self._last_outputs = outgoing
        return list(outgoing)

    def take_log(self) -> list[LogLine]:
        """Return and forget the log lines: the grasp check's changes, the start-up advice."""
        return self.grasp.take_log() + self._advice.take(self.filter)

    def _reject(
        self,
        topic: str,
        msg: Any,
        error: Exception,
        now: float,
        stamp: int | None = None,
        close: bool = True,
    ) -> list[Outgoing]:
        """Held or fallback command for a rejected input, and the status saying why.

        ``close``: the tick of the command's stamp is closed (not when ``now`` is no clock:
        a garbled first stamp must not close ticks that have not happened). Before the first
        tick, and for a tracker sample with ``input.sync: latest``, no command: a status.
        With ``latest`` a tick is closed only at a message's own stamp, never at the clock's
        (the states queued behind a stall are still to be answered), and a stale or
        out-of-order u_nom is the late answer to a state already gone: dropped
        (:meth:`~grasp_safety_filter.nodes.tick_inputs.TickAssembler.dropped`).
        """
        stale = isinstance(error, StaleInputError | OutOfOrderError | FutureStampError)
        name = self.topic_names.get(topic, topic)
        if stamp is None and not stale:
            stamp = self.inputs.current_stamp(msg, now)
        if stamp is None:
            # The message's own stamp is unusable: stamp the command with the clock.
            stamp = self.inputs.clock_stamp(now)
            close = close and not self.stream.latest
        self.input_watchdog.rejected(error)
        if self.stream.latest and topic == OBJECT_ODOM:
            return self.held.ignored(name, error, stamp)  # the ticks go on with the estimate
        if not self.ticked:
            if close:
                self.inputs.close(stamp)
            return self.held.ignored(name, error, stamp)
        outgoing = self.held.rejected(name, error, stamp, now)
        if close:
            self.inputs.close(stamp)
        return self._remember(outgoing)

    def _status_message(
        self, t: Stamp, level: DiagnosticLevel, text: str, values: dict[str, Any]
    ) -> Outgoing:
        """Return the ``safety_filter`` status stamped ``t``: ``filter.enabled``, ``values``."""
        return status_message(self.msgs, t, self.enabled, level, text, values)
