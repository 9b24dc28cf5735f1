"""The simulator's ``/diagnostics`` status, defined once: its name and keys.

``hand_sim_node`` (:class:`hand_sim_node.endpoint.HandSimEndpoint`) writes them and
:mod:`grasp_safety_filter.analysis` reads them back from a bag, both through the names and
functions below.

A plant with real contacts (MuJoCo) adds its contact events (:class:`PlantEvents`) to a
``hand_sim`` status at each onset (a contact lost, the object dropped) and to the end-of-run
status: every such status carries the record so far, so the last one read is the run's.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
import math
from typing import Any

#: Name of the simulator's ``DiagnosticStatus``.
SIM_DIAGNOSTIC = 'hand_sim'


class SimKey:
    """Keys of the ``hand_sim`` status's values (units in the comments)."""

    RUN_FINISHED = 'run.finished'
    """``true`` on the end-of-run status."""
    RUN_STOP_REASON = 'run.stop_reason'
    """Why the run ended: ``duration`` or the plant's stop reason."""
    RUN_T_END = 'run.t_end'
    """Simulated time the run reached, s."""
    RUN_STEPS = 'run.steps'
    """Steps integrated."""
    PLANT = 'plant'
    """The plant that measured the contact events (``mujoco``); absent for the rigid plant."""
    CONTACT_LOST_PREFIX = 'contact.lost.'
    """Followed by a contact name: when it was first lost (no touch, no force), s."""
    SLIP_DISTANCE_PREFIX = 'contact.slip_distance.'
    """Followed by a contact name: its slip distance since the start, m."""
    OBJECT_DROPPED = 'object.dropped'
    """When the object dropped (no fingertip touching it), s."""


class HardwareKey:
    """Keys of the ``hand_sim`` status's values in hardware mode (units in the comments).

    :mod:`hand_sim_node.hardware_status` writes them.
    """

    MODE = 'mode'
    """``hardware``."""
    T = 't'
    """Simulated time since the release (the first command), s."""
    RELEASED = 'released'
    """Whether the first command has released the plant (before it, it stands still)."""
    COMMANDS_RECEIVED = 'commands.received'
    """Valid commands received."""
    COMMANDS_REFUSED = 'commands.refused'
    """Invalid commands refused."""
    COMMAND_AGE = 'command.age'
    """Wall-clock time since the last valid command, s (absent before the first)."""
    COMMAND_TIMED_OUT = 'command.timed_out'
    """Whether the plant gets the timeout torque now."""
    TIMEOUT_TORQUE = 'command.timeout_torque'
    """The torque applied while timed out: ``gravity_compensation`` or ``zero``."""
    COMMAND_TIMEOUT = 'command.timeout'
    """``hardware.command_timeout``, s."""
    TIMEOUTS = 'command.timeouts'
    """Times the commands timed out since the start."""
    PERIODS = 'periods.published'
    """Driver periods whose state was published."""
    PERIODS_LATE = 'periods.late'
    """Driver periods integrated late (caught up in a later timer call) since the start."""
    PERIODS_SKIPPED = 'periods.skipped'
    """Driver periods beyond the catch-up limit, never integrated (simulated time lost)."""
    TRACKER_SAMPLES = 'tracker.samples'
    """Tracker samples published."""


@dataclass(frozen=True)
class PlantEvents:
    """A plant's real contact events over a run (so far).

    Attributes:
        plant: The plant (``"mujoco"``).
        contact_lost: Contact name -> when it was first lost, s (only those lost).
        object_dropped: When the object dropped, s, or None.
        slip_distance: Contact name -> slip distance since the start, m (every contact).
    """

    plant: str
    contact_lost: Mapping[str, float] = field(default_factory=dict)
    object_dropped: float | None = None
    slip_distance: Mapping[str, float] = field(default_factory=dict)

    def to_values(self) -> dict[str, Any]:
        """Return the status values (:class:`SimKey`) of this record."""
        values: dict[str, Any] = {SimKey.PLANT: self.plant}
        for name, t in self.contact_lost.items():
            values[SimKey.CONTACT_LOST_PREFIX + name] = float(t)
        if self.object_dropped is not None:
            values[SimKey.OBJECT_DROPPED] = float(self.object_dropped)
        for name, distance in self.slip_distance.items():
            values[SimKey.SLIP_DISTANCE_PREFIX + name] = float(distance)
        return values

    @classmethod
    def from_values(
        cls, values: Mapping[str, str], contact_names: Sequence[str]
    ) -> PlantEvents | None:
        """Read a status's record back (None: the status carries none).

        Keys of contacts not in ``contact_names`` and values that are not finite numbers are
        ignored (a bag of another scenario, a damaged value).
        """
        plant = values.get(SimKey.PLANT)
        if plant is None:
            return None

        def number(key: str) -> float | None:
            try:
                value = float(values[key])
            except (KeyError, ValueError):
                return None
            return value if math.isfinite(value) else None

        lost = {
            name: t
            for name in contact_names
            if (t := number(SimKey.CONTACT_LOST_PREFIX + name)) is not None
        }
        slip = {
            name: d
            for name in contact_names
            if (d := number(SimKey.SLIP_DISTANCE_PREFIX + name)) is not None
        }
        return cls(str(plant), lost, number(SimKey.OBJECT_DROPPED), slip)
