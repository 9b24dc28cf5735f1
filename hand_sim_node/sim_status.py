"""The simulator's ``hand_sim`` diagnostic statuses, built from the values they report.

:class:`~hand_sim_node.endpoint.HandSimEndpoint` publishes these on ``/diagnostics`` (see its
module docstring for when): a rejected or early command, a missing command, a command over
the effort limits (with the clipped torque the plant applies), a contact lost or the object
dropped, and the end of the run. Each is a :func:`sim_report`, a :class:`DiagnosticReport`
named ``SIM_DIAGNOSTIC`` (the hardware mode's too: :mod:`hand_sim_node.hardware_status`);
none keeps state.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages import (
    bounded_text,
    DiagnosticLevel,
    DiagnosticReport,
    header_stamp_ns,
    MessageError,
    name_list,
    nanoseconds_to_seconds,
)
from grasp_safety_filter.io.sim_diagnostic_keys import SIM_DIAGNOSTIC, SimKey
from hand_sim_node.simulator import NUMERICAL_FAILURE

#: ``run.stop_reason`` of a run that reached its duration.
DURATION = 'duration'


def sim_report(level: DiagnosticLevel, text: str, values: Mapping[str, Any]) -> DiagnosticReport:
    """Return a ``hand_sim`` status (its text bounded to a diagnostic's length)."""
    return DiagnosticReport.create(SIM_DIAGNOSTIC, level, bounded_text(text), values)


def command_warning(text: str, msg: Any, t: float) -> DiagnosticReport:
    """WARN about a command that is not applied, with its stamp if readable.

    Args:
        text: What is wrong with it.
        msg: The command message.
        t: Simulation time of the current state, s.

    """
    values: dict[str, Any] = {'t': t}
    try:
        values['command_stamp'] = nanoseconds_to_seconds(header_stamp_ns(msg))
    except (AttributeError, MessageError):
        values['command_stamp'] = 'unreadable'
    return sim_report(DiagnosticLevel.WARN, text, values)


def command_timeout_report(t: float, waited: float, command_timeout: float) -> DiagnosticReport:
    """WARN that no command stamped ``t`` (s) came within ``command_timeout`` (waited, s)."""
    return sim_report(
        DiagnosticLevel.WARN,
        f'no command stamped {t:.9f} s after {waited:.3f} s (command_timeout '
        f'{command_timeout} s); publishing the state again',
        {'t': t, 'waited': waited, 'command_timeout': command_timeout},
    )


def contact_event_report(
    onsets: Sequence[str], t: float, event_values: Mapping[str, Any]
) -> DiagnosticReport:
    """WARN at ``t`` (s) that a contact was lost or the object dropped (``onsets``).

    ``event_values``: the plant's contact event record so far, as status values.
    """
    return sim_report(DiagnosticLevel.WARN, '; '.join(onsets), {'t': t, **event_values})


def clip_to_limits(
    effort: np.ndarray, effort_limits: np.ndarray, joint_names: Sequence[str], t: float
) -> tuple[np.ndarray, DiagnosticReport | None]:
    """Clip a command to the URDF effort limits, as a driver does; WARN if it was over.

    Args:
        effort: The commanded torque, N·m, shape (m,).
        effort_limits: The joints' effort limits, N·m, shape (m,).
        joint_names: The m joint names.
        t: Simulation time of the current state, s.

    Returns:
        The applied torque, N·m, and the ``hand_sim`` WARN status naming the joints over
        their limit and by how much (None if none was).

    """
    limits = np.asarray(effort_limits, dtype=float)
    effort = np.asarray(effort, dtype=float)
    applied = np.clip(effort, -limits, limits)
    over = np.flatnonzero(applied != effort)
    if over.size == 0:
        return applied, None
    excess = np.abs(effort - applied)
    names = [joint_names[i] for i in over]
    worst = int(over[np.argmax(excess[over])])
    text = (
        f'command over the effort limits of {len(names)} joints {name_list(names)}: '
        f'clipped (largest excess {excess[worst]:.6g} N·m on {joint_names[worst]!r}, '
        f'limit {limits[worst]:.6g} N·m)'
    )
    values: dict[str, Any] = {
        't': t,
        'effort.clipped': ','.join(names),
        'effort.max_excess': float(excess[worst]),
    }
    values.update({f'effort.excess.{joint_names[i]}': float(excess[i]) for i in over})
    return applied, sim_report(DiagnosticLevel.WARN, text, values)


def end_of_run_report(
    reason: str | None, t: float, steps: int, event_values: Mapping[str, Any] | None
) -> DiagnosticReport:
    """Report why the run ended (``reason``), at ``t`` (s), after ``steps``: the last status.

    OK at :data:`DURATION`, ERROR on a numerical failure, WARN on any other stop.
    ``event_values``: a plant with real contacts' event record (None: a rigid plant).
    """
    if reason == DURATION:
        level, text = DiagnosticLevel.OK, f'run complete at t = {t:.9f} s'
    else:
        level = DiagnosticLevel.ERROR if reason == NUMERICAL_FAILURE else DiagnosticLevel.WARN
        text = f'run stopped at t = {t:.9f} s: {reason}'
    values: dict[str, Any] = {
        SimKey.RUN_FINISHED: True,
        SimKey.RUN_STOP_REASON: reason,
        SimKey.RUN_T_END: t,
        SimKey.RUN_STEPS: steps,
    }
    if event_values is not None:
        values.update(event_values)
    return sim_report(level, text, values)
