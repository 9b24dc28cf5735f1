"""The hardware mode's ``hand_sim`` statuses: what the emulated driver reports on ``/diagnostics``.

:class:`~hand_sim_node.hardware.HardwareEndpoint` publishes a status

- every :data:`STATUS_PERIOD_NS` of wall time (as ``diagnostic_updater`` does): OK while
  it waits for the first command or applies commands, ERROR while the commands are timed
  out, WARN when driver periods were late since the last one;
- at once when the first command releases the plant (OK), when the commands time out
  (ERROR, naming how long and the torque applied), when they resume (OK), when a command is
  refused (WARN, naming the problem) or clipped to the effort limits (WARN,
  :func:`~hand_sim_node.sim_status.clip_to_limits`), and at the end of the run.

Every one carries the driver's counts (:class:`DriverCounts`) under the keys of
:class:`~grasp_safety_filter.io.sim_diagnostic_keys.HardwareKey`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from grasp_safety_filter.io.messages import DiagnosticLevel
from grasp_safety_filter.io.sim_diagnostic_keys import HardwareKey

#: Wall-clock period of the driver's regular status, ns (diagnostic_updater's 1 s).
STATUS_PERIOD_NS = 1_000_000_000

#: ``mode`` value of the hardware mode's statuses.
HARDWARE_MODE = 'hardware'


@dataclass
class DriverCounts:
    """What the emulated driver counted since the start.

    Attributes:
        periods: Driver periods whose state was published.
        late: Periods integrated late, in a later timer call than theirs.
        skipped: Periods beyond the catch-up limit, never integrated.
        received: Valid commands.
        refused: Invalid commands.
        timeouts: Times the commands timed out.
    """

    periods: int = 0
    late: int = 0
    skipped: int = 0
    received: int = 0
    refused: int = 0
    timeouts: int = 0


def driver_values(
    counts: DriverCounts,
    *,
    t: float,
    released: bool,
    command_age: float | None,
    timed_out: bool,
    timeout_torque: str,
    command_timeout: float,
    tracker_samples: int,
) -> dict[str, Any]:
    """Return a status's values: the driver's counts and command state.

    Args:
        counts: The driver's counts.
        t: Simulated time since the release, s.
        released: Whether the first command came.
        command_age: Wall-clock time since the last valid command, s (None: none yet).
        timed_out: Whether the timeout torque is applied.
        timeout_torque: ``hardware.timeout_torque``.
        command_timeout: ``hardware.command_timeout``, s.
        tracker_samples: Tracker samples published.
    """
    values: dict[str, Any] = {
        HardwareKey.MODE: HARDWARE_MODE,
        HardwareKey.T: t,
        HardwareKey.RELEASED: released,
        HardwareKey.COMMANDS_RECEIVED: counts.received,
        HardwareKey.COMMANDS_REFUSED: counts.refused,
    }
    if command_age is not None:
        values[HardwareKey.COMMAND_AGE] = command_age
    values.update(
        {
            HardwareKey.COMMAND_TIMED_OUT: timed_out,
            HardwareKey.TIMEOUT_TORQUE: timeout_torque,
            HardwareKey.COMMAND_TIMEOUT: command_timeout,
            HardwareKey.TIMEOUTS: counts.timeouts,
            HardwareKey.PERIODS: counts.periods,
            HardwareKey.PERIODS_LATE: counts.late,
            HardwareKey.PERIODS_SKIPPED: counts.skipped,
            HardwareKey.TRACKER_SAMPLES: tracker_samples,
        }
    )
    return values


def regular_text(
    released: bool,
    timed_out: bool,
    command_age: float | None,
    new_late: int,
    new_skipped: int,
    timeout_torque: str,
) -> tuple[DiagnosticLevel, str]:
    """Return the level and text of the regular status (module docstring).

    Args:
        released: Whether the first command came.
        timed_out: Whether the timeout torque is applied.
        command_age: Wall-clock time since the last valid command, s (None: none yet).
        new_late: Periods late since the last regular status.
        new_skipped: Periods skipped since the last regular status.
        timeout_torque: ``hardware.timeout_torque``.
    """
    if timed_out:
        return DiagnosticLevel.ERROR, timed_out_text(command_age or 0.0, timeout_torque)
    if new_late or new_skipped:
        return DiagnosticLevel.WARN, (
            f'driver behind the wall clock: {new_late} periods integrated late, '
            f'{new_skipped} skipped since the last status'
        )
    if not released:
        return DiagnosticLevel.OK, 'holding the grasp still until the first command'
    return DiagnosticLevel.OK, f'applying commands (last one {command_age or 0.0:.3f} s ago)'


def timed_out_text(command_age: float, timeout_torque: str) -> str:
    """Return the text of a command timeout: how long without a command, what is applied."""
    return (
        f'no valid command for {command_age:.3f} s: commands timed out, applying '
        f'{timeout_torque} torque'
    )
