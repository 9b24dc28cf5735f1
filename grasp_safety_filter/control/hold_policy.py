"""What the safety filter commands when a tick's input is rejected.

The filter never computes a command from bad input (non-finite values, wrong lengths or
names, stale or out-of-order stamps: see :mod:`grasp_safety_filter.io.messages`). On such
a tick it follows this policy:

1. ``"ok"``: input accepted; the filter's command is sent and remembered as the last safe
   command.
2. ``"holding"``: input rejected, and at most ``input.hold_timeout`` s have passed since
   the last safe command: that command is sent again. It was safe for a state at most
   ``hold_timeout`` old, and a grasp usually survives a short hold better than a change
   of torque.
3. ``"fallback"``: input rejected for longer (or before any command was accepted): the
   configured fallback is sent, ``"zero"`` torque or ``"gravity_compensation"``
   ``u = g(q)`` (the node supplies ``g`` at the last accepted joint positions), clipped
   to the actuator limits when they are given.

The first accepted tick returns to ``"ok"``. The mode, the last rejection reason and the
rejection count go to ``/diagnostics`` (WARN while holding, ERROR in fallback; the keys are
:class:`grasp_safety_filter.io.diagnostic_keys.Key`).

A state that is not a grasp is rejected input too (``nodes/grasp_watch.py``): before any
state has passed the start-up grasp check there is no safe command, so the fallback goes
out at once; a contact lost at run time (gap or penetration above
``grasp_check.gap_tolerance``) gets the last safe command for ``hold_timeout``, which rides
out a bad tracker frame without a jump of torque, then the fallback, which neither squeezes
nor moves the hand (a hand that really lost the object must not keep pushing after it).
Both count as rejected ticks; the first grasp that passes returns to ``"ok"``.

Input that does not arrive at all is the same case on another clock: the filter's input
watchdog calls :meth:`HoldPolicy.absent` with the wall-clock time since the last accepted
tick (under ``use_sim_time`` a dead simulator also stops the node clock).

Parameters read (safety_filter_node): ``input.max_age`` (s, for the stamp guard),
``input.hold_timeout`` (s) and ``input.fallback`` (``"zero"`` or
``"gravity_compensation"``).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from enum import Enum
import math
from typing import Any

import numpy as np

from grasp_safety_filter.io.diagnostic_keys import InputMode, Key
from grasp_safety_filter.io.messages import bounded_text, DiagnosticLevel

MAX_AGE_PARAMETER = 'input.max_age'
HOLD_TIMEOUT_PARAMETER = 'input.hold_timeout'
FALLBACK_PARAMETER = 'input.fallback'


class Fallback(Enum):
    """Command after the hold timeout."""

    ZERO = 'zero'
    GRAVITY_COMPENSATION = 'gravity_compensation'


def _positive_seconds(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not value > 0:
        raise ValueError(f"parameter '{name}': expected a number > 0 s, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"parameter '{name}': expected a finite number of s, got {value!r}")
    return float(value)


def _fallback(value: Fallback | str) -> Fallback:
    try:
        return Fallback(value)
    except ValueError:
        raise ValueError(
            f"parameter '{FALLBACK_PARAMETER}': expected one of "
            f'{[f.value for f in Fallback]}, got {value!r}'
        ) from None


@dataclass(frozen=True)
class InputPolicyConfig:
    """The ``input.*`` parameters.

    Attributes:
        max_age: Largest admissible input age, s (> 0).
        hold_timeout: How long the last safe command is held, s (> 0).
        fallback: Command after the hold timeout.

    """

    max_age: float
    hold_timeout: float
    fallback: Fallback

    def __post_init__(self) -> None:
        object.__setattr__(self, 'max_age', _positive_seconds(MAX_AGE_PARAMETER, self.max_age))
        object.__setattr__(
            self, 'hold_timeout', _positive_seconds(HOLD_TIMEOUT_PARAMETER, self.hold_timeout)
        )
        object.__setattr__(self, 'fallback', _fallback(self.fallback))

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any]) -> InputPolicyConfig:
        """Read ``input.max_age``, ``input.hold_timeout``, ``input.fallback`` from a node's values.

        Raises:
            KeyError: A parameter is missing (the message names it).
            ValueError: A value is out of range.

        """
        missing = [
            name
            for name in (MAX_AGE_PARAMETER, HOLD_TIMEOUT_PARAMETER, FALLBACK_PARAMETER)
            if name not in values
        ]
        if missing:
            raise KeyError(f'missing parameters {missing}')
        return cls(
            max_age=values[MAX_AGE_PARAMETER],
            hold_timeout=values[HOLD_TIMEOUT_PARAMETER],
            fallback=values[FALLBACK_PARAMETER],
        )


def _limits(name: str, value: np.ndarray | None, n_joints: int) -> np.ndarray | None:
    if value is None:
        return None
    array = np.array(value, dtype=np.float64)
    if array.shape != (n_joints,) or np.isnan(array).any():
        raise ValueError(f'{name}: expected {n_joints} numbers, got {value!r}')
    return array


class HoldPolicy:
    """The input hold policy (module docstring) as a state machine over ticks.

    Call exactly one of :meth:`accept` (good input, with the filter's command) or
    :meth:`reject` (bad input, with the reason) per tick; both return the command to send.
    :meth:`absent` answers a check that found no tick at all (the input watchdog).
    """

    def __init__(
        self,
        n_joints: int,
        hold_timeout: float,
        fallback: Fallback | str,
        u_min: np.ndarray | None = None,
        u_max: np.ndarray | None = None,
    ) -> None:
        """Create the policy in mode ``"ok"`` with no safe command yet.

        Args:
            n_joints: Number of joints m.
            hold_timeout: How long the last safe command is held, s (> 0).
            fallback: Command after the hold timeout.
            u_min: Lower actuator limits, shape (m,), N·m; the fallback is clipped to them.
            u_max: Upper actuator limits, shape (m,), N·m.

        """
        if isinstance(n_joints, bool) or not isinstance(n_joints, int) or n_joints < 1:
            raise ValueError(f'n_joints: expected an integer >= 1, got {n_joints!r}')
        self.n_joints = n_joints
        self.hold_timeout = _positive_seconds(HOLD_TIMEOUT_PARAMETER, hold_timeout)
        self.fallback = _fallback(fallback)
        self.u_min = _limits('u_min', u_min, n_joints)
        self.u_max = _limits('u_max', u_max, n_joints)
        if self.u_min is not None and self.u_max is not None and (self.u_min > self.u_max).any():
            raise ValueError(f'u_min must not exceed u_max, got {self.u_min} and {self.u_max}')
        self._mode = InputMode.OK
        self._last_command: np.ndarray | None = None
        self._last_good_time: float | None = None
        self._last_reason = ''
        self._rejected_ticks = 0

    @classmethod
    def from_config(
        cls,
        config: InputPolicyConfig,
        n_joints: int,
        u_min: np.ndarray | None = None,
        u_max: np.ndarray | None = None,
    ) -> HoldPolicy:
        """Build the policy from the ``input.*`` parameters."""
        return cls(n_joints, config.hold_timeout, config.fallback, u_min, u_max)

    @property
    def mode(self) -> InputMode:
        """Mode of the last tick."""
        return self._mode

    @property
    def last_reason(self) -> str:
        """Why the last rejected input was rejected (empty if none was).

        At most :data:`~grasp_safety_filter.io.messages.MAX_REPORT_TEXT` characters: it
        goes with every later status.
        """
        return self._last_reason

    @property
    def rejected_ticks(self) -> int:
        """Number of rejected ticks so far."""
        return self._rejected_ticks

    @property
    def diagnostic_level(self) -> DiagnosticLevel:
        """OK while the input is accepted, WARN while holding, ERROR in fallback."""
        return {
            InputMode.OK: DiagnosticLevel.OK,
            InputMode.HOLDING: DiagnosticLevel.WARN,
            InputMode.FALLBACK: DiagnosticLevel.ERROR,
        }[self._mode]

    def accept(self, t: float, command: np.ndarray) -> np.ndarray:
        """Record a tick with good input and its safe command; return that command.

        Args:
            t: Tick time, s.
            command: The filter's command u*, shape (m,), N·m, finite.

        """
        u = self._command('command', command)
        self._mode = InputMode.OK
        self._last_command = u
        self._last_good_time = float(t)
        return u.copy()

    def reject(
        self, t: float, reason: str, gravity_torque: np.ndarray | None = None
    ) -> np.ndarray:
        """Record a tick with rejected input; return the held or fallback command.

        Args:
            t: Tick time, s (the node's clock, not the rejected message's stamp).
            reason: Why the input was rejected (reported on /diagnostics).
            gravity_torque: ``g(q)`` at the last accepted joint positions, shape (m,), N·m;
                required when the fallback is gravity compensation.

        """
        self._rejected_ticks += 1
        since = math.inf if self._last_good_time is None else t - self._last_good_time
        return self._answer(since, reason, gravity_torque)

    def absent(
        self, elapsed: float, reason: str, gravity_torque: np.ndarray | None = None
    ) -> np.ndarray:
        """Record that no tick came for ``elapsed`` s; return the held or fallback command.

        Not a rejected tick (:attr:`rejected_ticks` is unchanged): the input watchdog's
        answer when nothing arrives.

        Args:
            elapsed: Time since the last accepted tick, s, on the caller's clock (the
                watchdog's wall clock); ``inf`` if there was none.
            reason: Which input is missing and since when (reported on /diagnostics).
            gravity_torque: As for :meth:`reject`.

        """
        return self._answer(float(elapsed), reason, gravity_torque)

    def _answer(
        self, since_accepted: float, reason: str, gravity_torque: np.ndarray | None
    ) -> np.ndarray:
        """Hold the last safe command up to ``hold_timeout`` s after it, else fall back."""
        self._last_reason = bounded_text(str(reason))
        if self._last_command is not None and since_accepted <= self.hold_timeout:
            self._mode = InputMode.HOLDING
            return self._last_command.copy()
        self._mode = InputMode.FALLBACK
        if self.fallback is Fallback.ZERO:
            u = np.zeros(self.n_joints)
        else:
            if gravity_torque is None:
                raise ValueError(
                    f"gravity_torque: required for fallback '{self.fallback.value}', got None"
                )
            u = self._command('gravity_torque', gravity_torque)
        return np.clip(
            u,
            -np.inf if self.u_min is None else self.u_min,
            np.inf if self.u_max is None else self.u_max,
        )

    def diagnostic_values(self, t: float) -> dict[str, Any]:
        """Key/values for /diagnostics at time ``t``, s."""
        since = math.inf if self._last_good_time is None else t - self._last_good_time
        return {
            Key.INPUT_MODE: self._mode.value,
            Key.INPUT_FALLBACK: self.fallback.value,
            Key.INPUT_REJECTED_TICKS: self._rejected_ticks,
            Key.INPUT_LAST_REJECTION: self._last_reason,
            Key.INPUT_TIME_SINCE_ACCEPTED: since,
        }

    def _command(self, name: str, value: np.ndarray) -> np.ndarray:
        u = np.array(value, dtype=np.float64)
        if u.shape != (self.n_joints,) or not np.isfinite(u).all():
            raise ValueError(f'{name}: expected {self.n_joints} finite numbers, got {value!r}')
        return u
