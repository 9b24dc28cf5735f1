"""The safety filter's message-level endpoint: state and u_nom in, u* out.

Pure Python, shared by the rclpy node (:mod:`grasp_safety_filter.nodes.safety_filter_node`)
and the ROS-free runner. A tick runs when the three inputs of one stamp t are in hand and
valid::

    /hand/joint_states (t) + /object/odom (t) + /hand/effort_nominal (t)
        ──▶ GraspModel.state ──▶ SafetyFilter.solve(state, u_nom) ──▶ HoldPolicy.accept
        ──▶ /hand/effort_command stamped t (u* by joint name, N·m)
            /safety_filter/margins stamped t (barrier value h per row; row names in the
                first message, on change and once a second: io.margin_stream)
            /diagnostics: status ``safety_filter`` (below)

Inputs are parsed by joint name and checked by a :class:`StampGuard` per topic (older than
``input.max_age`` behind ``now``: stale; more than ``input.max_age`` ahead of it: future;
older than the topic's last accepted stamp: out of order; without ``now``, the clock is
the last tick's time). A rejected input yields no computed command: :meth:`HoldPolicy.reject`
gives the last safe command (``holding``, WARN) or, after ``input.hold_timeout``, the fallback
(``fallback``, ERROR: zero torque or gravity compensation ``g(q)`` at the last accepted
joint positions, clipped to the actuator limits). That command is published stamped with
the rejected message's stamp when it is readable and current (a lockstep simulator waiting
for that stamp goes on), else with ``now``; the tick of that stamp is then closed. A
complete, valid set arriving again for the last tick's stamp (a simulator that re-sent its
state) gets the same messages again, without a new solve.

Input watchdog: :meth:`SafetyFilterEndpoint.watchdog`, called periodically on a steady
clock (the node: every :data:`WATCHDOG_PERIOD` s), stands in for ticks that do not come at
all (a dead simulator, nominal controller or driver). Once no tick has been accepted for
more than ``input.hold_timeout`` s of wall-clock time, each call returns the hold policy's
fallback on ``/hand/effort_command`` and an ERROR status naming the inputs that stopped and
for how long; the first tick accepted afterwards says how long the inputs were missing.
The wall-clock times come with the inputs (``wall``); without them (the ROS-free runner)
the watchdog never acts.

With ``enabled=False`` (the paper's unfiltered run) the endpoint validates the same inputs
and publishes ``u* = u_nom`` on the same topic, with the margins at u_nom; its status is
then WARN (the grasp constraints are not enforced). :meth:`SafetyFilterEndpoint.switch`
turns the filter on or off at run time and records when.

Diagnostic values of the ``safety_filter`` status (keys and status values:
:mod:`grasp_safety_filter.io.diagnostic_keys`) on every tick: ``filter.enabled``,
``filter.switched_at`` (after a switch), ``status`` (a ``TickStatus``: ``nominal``,
``solved``, ``solved_active_set``, ``relaxed``, ``fallback_last_good``,
``fallback_nominal``, ``disabled``; ``input_held`` or ``input_fallback`` on a rejected
input and on the watchdog's statuses), ``solve_time_us`` (the QP solve: OSQP and the
active-set steps), ``step_time_us`` (the whole filter step, ``SafetyFilter.solve``: rows,
QP, margins), ``tick_time_us`` (the whole tick: model terms, filter step, messages),
``iterations``, ``relaxed``, ``relaxed_families`` (comma-separated), ``max_violation``,
``active`` (comma-separated row names), ``min_margin.<family>`` per constraint family, and
the hold policy's ``input.*`` values.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
import math
import time
from typing import Any

import numpy as np

from grasp_safety_filter.control.hold_policy import (
    Fallback,
    HoldPolicy,
    InputPolicyConfig,
)
from grasp_safety_filter.control.safety_filter import (
    FilterResult,
    SafetyFilter,
    SafetyFilterConfig,
)
from grasp_safety_filter.io.diagnostic_keys import (
    FAILED_STATUSES,
    FILTER_DIAGNOSTIC,
    INPUT_MODE_STATUS,
    InputMode,
    Key,
    min_margin,
    silent_for,
    TickStatus,
)
from grasp_safety_filter.io.margin_stream import MarginEncoder
from grasp_safety_filter.io.messages import (
    bounded_text,
    DiagnosticLevel,
    DiagnosticReport,
    diagnostics_to_msg,
    effort_from_msg,
    effort_to_msg,
    EffortData,
    FutureStampError,
    header_stamp_ns,
    joint_state_from_msg,
    JointStateData,
    MessageError,
    MessageNamespace,
    nanoseconds_to_seconds,
    ObjectStateData,
    odometry_from_msg,
    OutOfOrderError,
    seconds_to_nanoseconds,
    StaleInputError,
    StampGuard,
)
from grasp_safety_filter.io.topics import (
    DIAGNOSTICS,
    EFFORT_COMMAND,
    EFFORT_NOMINAL,
    JOINT_STATES,
    MARGINS,
    OBJECT_ODOM,
)
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.nodes.outgoing import Outgoing, stamped
from grasp_safety_filter.nodes.publication_rate import PublicationRate, PublicationRateConfig

#: Period of the input watchdog, s (steady clock). The fallback goes out and /diagnostics
#: say ERROR at most ``input.hold_timeout`` + this after the last accepted tick, and the
#: fallback is repeated at this period while the inputs stay away: 50 Hz keeps a driver
#: with a command timeout of 20 ms or more fed, and costs the 1 kHz loop one subtraction
#: per call.
WATCHDOG_PERIOD = 0.02

#: Wall-clock period of the watchdog's "waiting for a first tick" status before any tick, s.
WAITING_REPORT_PERIOD = 1.0

#: Incomplete input sets kept waiting for their other inputs (older ones are dropped).
MAX_PENDING = 64

_INPUTS = (JOINT_STATES, OBJECT_ODOM, EFFORT_NOMINAL)
_STATE_INPUTS = (JOINT_STATES, OBJECT_ODOM)


@dataclass(frozen=True)
class TickInputs:
    """The three validated inputs of one tick.

    Attributes:
        joint_states: Joint positions, velocities and efforts, model joint order.
        odometry: Object pose and twist, palm frame.
        nominal: The nominal torque u_nom, model joint order.

    """

    joint_states: JointStateData
    odometry: ObjectStateData
    nominal: EffortData


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

    Attributes:
        filter: The safety filter core.
        hold: The input hold policy.
        guard: Stale and out-of-order stamp checks, per input topic.
        margin_stream: The ``/safety_filter/margins`` stream (row names only when due).
        enabled: Whether u* is filtered (True) or u_nom passed through (False); change it
            with :meth:`switch`.
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
    ) -> None:
        self.model = model
        self.msgs = msgs
        self.enabled = bool(enabled)
        self.filter = SafetyFilter.from_config(model, filter_config)
        effort_limits = np.asarray(model.effort_limits, dtype=float)
        self.hold = HoldPolicy.from_config(
            input_policy_config, model.n_joints, -effort_limits, effort_limits
        )
        self.guard = StampGuard(input_policy_config.max_age)
        self.rate = PublicationRate(publication_rate_config)
        self.margin_stream = MarginEncoder()
        self.last_result: FilterResult | None = None
        self._joint_names = list(model.joint_names)
        self._pending: dict[int, dict[str, Any]] = {}
        # Model terms (or the model's error) of pending stamps whose state is complete.
        self._states: dict[int, tuple[GraspState | Exception, float]] = {}
        self._replay: dict[str, Any] = {}
        self._last_tick_ns: int | None = None
        self._last_outputs: list[Outgoing] = []
        self._last_positions: np.ndarray | None = None
        # Wall-clock (steady) times for the watchdog, s: last message per topic, last
        # accepted tick, and when the watchdog took over (None while ticks come).
        self._received_wall: dict[str, float] = {}
        self._accepted_wall: float | None = None
        self._watchdog_since: float | None = None
        # Before the first tick: since when the watchdog runs, and its last report (wall, s).
        self._waiting_since: float | None = None
        self._waiting_reported = 0.0
        self._switched_at: float | None = None

    # -------------------------------------------------------------------------- inputs
    def on_joint_states(
        self, msg: Any, now: float | None = None, wall: float | None = None
    ) -> list[Outgoing]:
        """Handle ``/hand/joint_states`` (see :meth:`on_effort_nominal`)."""
        return self._on_input(
            JOINT_STATES,
            msg,
            now,
            wall,
            lambda: joint_state_from_msg(msg, self._joint_names, JOINT_STATES),
        )

    def on_odom(
        self, msg: Any, now: float | None = None, wall: float | None = None
    ) -> list[Outgoing]:
        """Handle ``/object/odom`` (see :meth:`on_effort_nominal`)."""
        return self._on_input(
            OBJECT_ODOM,
            msg,
            now,
            wall,
            lambda: odometry_from_msg(
                msg, self.model.palm_frame, self.model.object_frame, source=OBJECT_ODOM
            ),
        )

    def on_effort_nominal(
        self, msg: Any, now: float | None = None, wall: float | None = None
    ) -> list[Outgoing]:
        """Handle ``/hand/effort_nominal``; tick when all inputs of its stamp are in hand.

        Args:
            msg: The message.
            now: The node's clock, s (simulation time under ``use_sim_time``). None: the
                time of the last tick, so a runner without a clock still detects stale and
                out-of-order input.
            wall: The steady clock at receipt, s (the clock :meth:`watchdog` is called
                with). None: the watchdog does not watch this input.

        Returns:
            Nothing while the tick's inputs are incomplete; on a tick, ``/hand/effort_command``,
            ``/safety_filter/margins`` and ``/diagnostics``; on a rejected input,
            ``/hand/effort_command`` (held or fallback) and ``/diagnostics``.

        """
        return self._on_input(
            EFFORT_NOMINAL,
            msg,
            now,
            wall,
            lambda: effort_from_msg(msg, self._joint_names, EFFORT_NOMINAL),
        )

    def watchdog(self, now_wall: float, now: float) -> list[Outgoing]:
        """Stand in for ticks that stopped coming: the fallback command and an ERROR.

        Call it periodically (every :data:`WATCHDOG_PERIOD` s) from a steady clock: under
        ``use_sim_time`` a dead simulator stops the node clock too.

        Args:
            now_wall: The steady clock, s (that of the handlers' ``wall``).
            now: The node's clock, s: the stamp of the fallback command (not before the
                last tick's stamp, so commands never go back in time; 1 ns later if a tick of
                that stamp has some of its inputs, so the fallback never answers a tick that
                is under way).

        Returns:
            Before the first accepted tick, every :data:`WAITING_REPORT_PERIOD` s a WARN
            status naming the inputs not received yet, and no command (there is no state to
            hold against gravity, and a hand driver should not get torques from a filter
            that has never seen its hand); nothing while the last tick is at most
            ``input.hold_timeout`` s old; else the hold policy's fallback (zero torque or
            ``g(q)`` at the last accepted joint positions, clipped to the actuator limits)
            on ``/hand/effort_command`` and an ERROR ``/diagnostics`` status naming the
            missing inputs and how long each has been silent.

        """
        if self._accepted_wall is None:
            return self._waiting_status(now_wall, now)
        elapsed = now_wall - self._accepted_wall
        if elapsed <= self.hold.hold_timeout:
            return []
        missing = [
            topic
            for topic in _INPUTS
            if self._received_wall.get(topic, -math.inf) <= self._accepted_wall
        ]
        silent = {topic: now_wall - self._received_wall.get(topic, -math.inf) for topic in _INPUTS}
        last_tick = nanoseconds_to_seconds(self._last_tick_ns or 0)
        if missing:
            what = ', '.join(f'nothing on {topic} for {silent[topic]:.3f} s' for topic in missing)
        else:
            what = 'inputs arrive, but no complete valid set of one stamp'
        reason = (
            f'no tick accepted for {elapsed:.3f} s of wall-clock time (last at t = '
            f'{last_tick:.6f} s): {what}'
        )
        gravity, note = self._fallback_gravity()
        u = self.hold.absent(elapsed, reason, gravity)
        if self._watchdog_since is None:
            self._watchdog_since = now_wall
        stamp = self._clock_stamp(now)
        if stamp in self._pending:
            # A tick of this stamp is under way (a lockstep simulator waits for its command
            # while the nominal controller is slow): the fallback must not answer it in its
            # place, so that the tick still gets its own u* when its inputs are complete.
            stamp += 1
        t = nanoseconds_to_seconds(stamp)
        values: dict[str, Any] = {
            Key.STATUS: INPUT_MODE_STATUS[self.hold.mode].value,
            Key.INPUT_WATCHDOG: True,
            Key.INPUT_MISSING: ','.join(missing),
            Key.INPUT_WALL_TIME_SINCE_ACCEPTED: elapsed,
        }
        values.update({silent_for(topic): age for topic, age in silent.items()})
        values.update(self.hold.diagnostic_values(now))
        return [
            stamped(EFFORT_COMMAND, effort_to_msg(self.msgs, t, self._joint_names, u)),
            self._status_message(
                t,
                self.hold.diagnostic_level,
                f'inputs missing, fallback command: {self.hold.fallback.value}{note}: {reason}',
                values,
            ),
        ]

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
        self._switched_at = self._now(None, now)[0]
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
    ) -> None:
        """Apply new parameters from the next tick on (None: unchanged).

        A new filter configuration rebuilds the filter (and its OSQP problems); the hold
        policy keeps its last safe command and mode.
        """
        if filter_config is not None:
            self.filter = SafetyFilter.from_config(self.model, filter_config)
        if input_policy_config is not None:
            self.guard.max_age = input_policy_config.max_age
            self.hold.hold_timeout = input_policy_config.hold_timeout
            self.hold.fallback = input_policy_config.fallback
        if enabled is not None:
            self.switch(enabled)
        if publication_rate_config is not None:
            self.rate.configure(publication_rate_config)

    # ------------------------------------------------------------------------ internals
    def _now(self, msg: Any, now: float | None) -> tuple[float, bool]:
        """Return the clock for this input, s, and whether it is one.

        ``now``, else the last tick's time; before any tick and without ``now``, the
        message's own stamp (or 0.0), which is no clock: a rejection then closes no tick.
        """
        if now is not None:
            return float(now), True
        if self._last_tick_ns is not None:
            return nanoseconds_to_seconds(self._last_tick_ns), True
        try:
            return nanoseconds_to_seconds(header_stamp_ns(msg)), False
        except (AttributeError, MessageError):
            return 0.0, False

    def _on_input(
        self, topic: str, msg: Any, now: float | None, wall: float | None, parse: Any
    ) -> list[Outgoing]:
        now_s, is_clock = self._now(msg, now)
        if wall is not None:
            self._received_wall[topic] = wall
        try:
            data = parse()
            self.guard.accept(topic, data.t, now_s)
            stamp = seconds_to_nanoseconds(data.t)
            if self._last_tick_ns is not None and stamp < self._last_tick_ns:
                raise OutOfOrderError(
                    f'{topic}: stamp {data.t:.9f} s belongs to a tick already closed (last '
                    f'tick {nanoseconds_to_seconds(self._last_tick_ns):.9f} s)'
                )
        except MessageError as error:
            return self._reject(topic, msg, error, now_s, close=is_clock)
        if stamp == self._last_tick_ns:
            # The same tick again (e.g. a simulator that re-sent its state): same answer.
            self._replay[topic] = data
            if len(self._replay) < len(_INPUTS):
                return []
            self._replay = {}
            return list(self._last_outputs)
        inputs = self._pending.setdefault(stamp, {})
        inputs[topic] = data
        if len(inputs) < len(_INPUTS):
            if topic in _STATE_INPUTS and all(name in inputs for name in _STATE_INPUTS):
                # The state is complete before u_nom, which the nominal controller computes
                # from the same state meanwhile: the model terms need not wait for it.
                self._states[stamp] = self._timed_state(inputs[JOINT_STATES], inputs[OBJECT_ODOM])
            while len(self._pending) > MAX_PENDING:
                oldest = min(self._pending)
                del self._pending[oldest]
                self._states.pop(oldest, None)
            return []
        del self._pending[stamp]
        tick = TickInputs(inputs[JOINT_STATES], inputs[OBJECT_ODOM], inputs[EFFORT_NOMINAL])
        return self._tick(stamp, tick, now_s, wall)

    def _timed_state(
        self, joint_states: JointStateData, odometry: ObjectStateData
    ) -> tuple[GraspState | Exception, float]:
        """Compute a state's model terms (or the model's refusal of it), timed in s."""
        start = time.perf_counter()
        try:
            state: GraspState | Exception = self.model.state(
                joint_states.t,
                joint_states.position,
                joint_states.velocity,
                odometry.p_object_in_palm,
                odometry.R_object_to_palm,
                odometry.twist_object,
            )
        except (ValueError, np.linalg.LinAlgError) as error:
            state = error
        return state, time.perf_counter() - start

    def _waiting_status(self, now_wall: float, now: float) -> list[Outgoing]:
        """Report the wait for a first tick: a WARN every WAITING_REPORT_PERIOD s, no command."""
        if self._waiting_since is None:
            self._waiting_since = self._waiting_reported = now_wall
            return []
        if now_wall - self._waiting_reported < WAITING_REPORT_PERIOD:
            return []
        self._waiting_reported = now_wall
        missing = [topic for topic in _INPUTS if topic not in self._received_wall]
        what = (
            f"nothing on {', '.join(missing)}"
            if missing
            else 'inputs arrive, but no complete valid set of one stamp'
        )
        return [
            self._status_message(
                max(now, 0.0),
                DiagnosticLevel.WARN,
                f'waiting {now_wall - self._waiting_since:.1f} s for a first tick: {what}',
                {Key.INPUT_WATCHDOG: True, Key.INPUT_MISSING: ','.join(missing)},
            )
        ]

    def _close(self, stamp: int) -> None:
        """Mark the tick of ``stamp`` as done: drop every older or equal pending input."""
        self._last_tick_ns = stamp
        self._replay = {}
        for old in [s for s in self._pending if s <= stamp]:
            del self._pending[old]
        for old in [s for s in self._states if s <= stamp]:
            del self._states[old]

    def _tick(
        self, stamp: int, inputs: TickInputs, now: float, wall: float | None
    ) -> list[Outgoing]:
        start = time.perf_counter()
        t = inputs.joint_states.t
        u_nom = inputs.nominal.effort
        state, model_time = self._states.pop(stamp, None) or self._timed_state(
            inputs.joint_states, inputs.odometry
        )
        start -= model_time  # the tick's time includes its model terms, whenever computed
        try:
            if isinstance(state, Exception):
                raise state
            if self.enabled:
                filter_start = time.perf_counter()
                result = self.filter.solve(state, u_nom)
                filter_time = time.perf_counter() - filter_start
                u, margins = result.u, result.margins
            else:
                result = None
                filter_time = 0.0
                u, margins = u_nom, self.filter.margins(state, u_nom)
        except (ValueError, np.linalg.LinAlgError) as error:
            return self._reject(
                'state',
                None,
                MessageError(f'the model rejected the state at t = {t:.9f} s: {error}'),
                now,
                stamp,
            )
        self.last_result = result
        u = self.hold.accept(now, u)
        # The gravity fallback's q: only a tick's accepted joint state, never one merely parsed.
        self._last_positions = np.array(inputs.joint_states.position)
        self._close(stamp)
        resumed_after = None
        if wall is not None:
            if self._watchdog_since is not None and self._accepted_wall is not None:
                resumed_after = wall - self._accepted_wall
                self._watchdog_since = None
            self._accepted_wall = wall
        outgoing = [stamped(EFFORT_COMMAND, effort_to_msg(self.msgs, t, self._joint_names, u))]
        if self.rate.margins_due(stamp):
            message = self.margin_stream.encode(self.msgs, t, margins.names, margins.array)
            outgoing.append(stamped(MARGINS, message))
        status = TickStatus.DISABLED if result is None else TickStatus.of(result.status)
        if self.rate.status_due(stamp, status, force=resumed_after is not None):
            tick_time = time.perf_counter() - start
            outgoing.append(
                self._tick_status(t, now, result, margins, filter_time, tick_time, resumed_after)
            )
        self._last_outputs = outgoing
        return list(outgoing)

    def _tick_status(
        self,
        t: float,
        now: float,
        result: FilterResult | None,
        margins: Mapping[str, float],
        step_time: float,
        tick_time: float,
        resumed_after: float | None = None,
    ) -> Outgoing:
        values: dict[str, Any] = {}
        if self._switched_at is not None:
            values[Key.FILTER_SWITCHED_AT] = self._switched_at
        if result is None:
            # Not an error, but nothing is enforced: say so at WARN on every tick.
            level, text = DiagnosticLevel.WARN, 'filter OFF: u* = u_nom, constraints not enforced'
            values[Key.STATUS] = TickStatus.DISABLED.value
            values[Key.SOLVE_TIME_US] = 0.0
            values[Key.ITERATIONS] = 0
            values[Key.RELAXED] = False
            values[Key.RELAXED_FAMILIES] = ''
            values[Key.MAX_VIOLATION] = 0.0
            values[Key.ACTIVE] = ''
        else:
            status = TickStatus.of(result.status)
            level, text = _status_level_and_text(status, result.relaxed)
            if result.relaxed_families:
                text += ': ' + ', '.join(result.relaxed_families)
            values[Key.STATUS] = status.value
            values[Key.SOLVE_TIME_US] = result.solve_time * 1e6
            values[Key.ITERATIONS] = result.iterations
            values[Key.RELAXED] = result.relaxed
            values[Key.RELAXED_FAMILIES] = ','.join(result.relaxed_families)
            values[Key.MAX_VIOLATION] = result.max_violation
            values[Key.ACTIVE] = ','.join(result.active)
        values[Key.STEP_TIME_US] = step_time * 1e6
        values[Key.TICK_TIME_US] = tick_time * 1e6
        values.update(self.rate.counter_values())
        for family, h in _min_margin_per_family(margins).items():
            values[min_margin(family)] = h
        values.update(self.hold.diagnostic_values(now))
        if resumed_after is not None:
            values[Key.INPUT_RESUMED_AFTER] = resumed_after
            text += f'; inputs back after {resumed_after:.3f} s without a tick (watchdog ended)'
            level = max(level, DiagnosticLevel.WARN)
        return self._status_message(t, level, text, values)

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
        a garbled first stamp must not close ticks that have not happened).
        """
        if stamp is None and not isinstance(
            error, StaleInputError | OutOfOrderError | FutureStampError
        ):
            stamp = self._current_stamp(msg, now)
        if stamp is None:
            # The message's own stamp is unusable: stamp the command with the clock.
            stamp = self._clock_stamp(now)
        gravity, note = self._fallback_gravity()
        u = self.hold.reject(now, f'{topic}: {error}', gravity)
        if close:
            self._close(stamp)
        t = nanoseconds_to_seconds(stamp)
        mode = self.hold.mode
        action = (
            'holding the last safe command'
            if mode is InputMode.HOLDING
            else f'fallback command: {self.hold.fallback.value}{note}'
        )
        status = INPUT_MODE_STATUS[mode]
        self.rate.status_due(stamp, status)  # counted; never a steady status: always sent
        values: dict[str, Any] = {Key.STATUS: status.value, Key.INPUT_TOPIC: topic}
        values.update(self.hold.diagnostic_values(now))
        values.update(self.rate.counter_values())
        outgoing = [
            stamped(EFFORT_COMMAND, effort_to_msg(self.msgs, t, self._joint_names, u)),
            self._status_message(
                t,
                self.hold.diagnostic_level,
                bounded_text(f'input rejected, {action}: {error}'),
                values,
            ),
        ]
        self._last_outputs = outgoing
        return list(outgoing)

    def _status_message(
        self, t: float, level: DiagnosticLevel, text: str, values: Mapping[str, Any]
    ) -> Outgoing:
        """Return the ``safety_filter`` status stamped ``t``, s: ``filter.enabled``, ``values``."""
        report = DiagnosticReport.create(
            FILTER_DIAGNOSTIC, level, text, {Key.FILTER_ENABLED: self.enabled, **values}
        )
        return stamped(DIAGNOSTICS, diagnostics_to_msg(self.msgs, t, report))

    def _clock_stamp(self, now: float) -> int:
        """Stamp from the node clock ``now`` (s), not before the last tick's stamp, ns."""
        stamp = seconds_to_nanoseconds(max(now, 0.0))
        if self._last_tick_ns is not None:
            stamp = max(stamp, self._last_tick_ns)
        return stamp

    def _fallback_gravity(self) -> tuple[np.ndarray | None, str]:
        """``g(q)`` for a gravity-compensation fallback, at the last accepted joint positions.

        Returns:
            The torque (None with the zero fallback) and a note for the status text (zero
            torque when no joint state has been accepted yet).

        """
        if self.hold.fallback is not Fallback.GRAVITY_COMPENSATION:
            return None, ''
        if self._last_positions is None:
            return np.zeros(len(self._joint_names)), ' (no joint state accepted yet: zero torque)'
        q = self._last_positions
        return self.model.hand.terms(q, np.zeros_like(q)).gravity_torque, ''

    def _current_stamp(self, msg: Any, now: float) -> int | None:
        """Return the message's stamp if readable, not before the last tick, not in the future.

        "Future" is beyond ``now + input.max_age``: a garbled stamp must not close ticks
        that have not happened yet.
        """
        try:
            stamp = header_stamp_ns(msg)
        except (AttributeError, MessageError):
            return None
        if self._last_tick_ns is not None and stamp < self._last_tick_ns:
            return None
        if nanoseconds_to_seconds(stamp) > now + self.guard.max_age:
            return None
        return stamp


_STATUS_TEXT: dict[TickStatus, str] = {
    TickStatus.NOMINAL: 'u* = u_nom: every constraint holds',
    TickStatus.SOLVED: 'QP solved',
    TickStatus.SOLVED_ACTIVE_SET: 'QP solved (active-set steps)',
    TickStatus.RELAXED: 'QP infeasible, relaxed',
    TickStatus.FALLBACK_LAST_GOOD: 'no QP solution: last good u*',
    TickStatus.FALLBACK_NOMINAL: 'no QP solution: u_nom clipped to the actuator limits',
}


def _status_level_and_text(status: TickStatus, relaxed: bool) -> tuple[DiagnosticLevel, str]:
    """Level and summary of a filter status: ERROR without a QP answer, WARN if relaxed."""
    if status in FAILED_STATUSES:
        level = DiagnosticLevel.ERROR
    elif relaxed:
        level = DiagnosticLevel.WARN
    else:
        level = DiagnosticLevel.OK
    return level, _STATUS_TEXT.get(status, f'QP {status.value}')


def _min_margin_per_family(margins: Mapping[str, float]) -> dict[str, float]:
    """Smallest barrier value per family (the first component of the row names)."""
    smallest: dict[str, float] = {}
    for name, h in margins.items():
        family = name.split('/', 1)[0]
        smallest[family] = min(smallest.get(family, math.inf), h)
    return smallest
