"""Run-long record of the constraint events: counts, first times, onsets, worst margins.

:class:`EventLog` accumulates the margins of one instant after another
(:class:`~hand_sim_node.constraint_margins.ConstraintMargins`, with the events
:meth:`hand_sim_node.events.EventMonitor.events` lists for them) into the run summary's
violation counts and smallest margins.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from hand_sim_node.constraint_margins import (
    ConstraintMargins,
    Event,
    FAMILIES,
    FINGERTIP_WORKSPACE,
    JOINT_LIMITS,
    SLIP,
)


@dataclass
class FamilyRecord:
    """Run-long record of one constraint family.

    Attributes:
        count: Number of evaluated instants (steps) at which the family was violated.
        first_t: Time of the first violation, s, or None.
        min_margin: Smallest margin over the run (``inf`` before any evaluation).

    """

    count: int = 0
    first_t: float | None = None
    min_margin: float = float('inf')


@dataclass
class EventLog:
    """Accumulates constraint margins over a run: counts, first times, onsets, worst margins.

    Attributes:
        onsets: Every event at the instant it starts (a constraint that was satisfied at the
            previous evaluation, or the first evaluation), in time order.
        max_required_friction: Largest ``beta_i`` over the run (``inf`` after a separation).
        n_evaluations: Number of recorded instants.

    """

    onsets: list[Event] = field(default_factory=list)
    max_required_friction: float = 0.0
    n_evaluations: int = 0
    # Per family, in FAMILIES order: steps in violation, first time (NaN: none), worst margin.
    _counts: np.ndarray = field(default_factory=lambda: np.zeros(len(FAMILIES), dtype=np.int64))
    _first_t: np.ndarray = field(default_factory=lambda: np.full(len(FAMILIES), np.nan))
    _min_margin: np.ndarray = field(default_factory=lambda: np.full(len(FAMILIES), np.inf))
    # Flat violation mask of the previous evaluation, and where each family starts in it.
    _active: np.ndarray | None = field(default=None, repr=False)
    _starts: np.ndarray | None = field(default=None, repr=False)

    @property
    def families(self) -> dict[str, FamilyRecord]:
        """Per family, its :class:`FamilyRecord` (a snapshot)."""
        return {
            family: FamilyRecord(
                int(count), None if np.isnan(first) else float(first), float(minimum)
            )
            for family, count, first, minimum in zip(
                FAMILIES, self._counts, self._first_t, self._min_margin, strict=True
            )
        }

    def record(self, margins: ConstraintMargins, events: tuple[Event, ...]) -> None:
        """Add one instant: its margins and their events (``EventMonitor.events(margins)``).

        Raises:
            ValueError: ``events`` are not the violated entries of ``margins``.

        """
        mask = margins.violated_mask
        if np.count_nonzero(mask) != len(events):
            raise ValueError(
                f'EventLog.record: expected the {np.count_nonzero(mask)} events of the '
                f'margins, got {len(events)}'
            )
        self.n_evaluations += 1
        if self._starts is None or self._active is None or self._active.size != mask.size:
            self._starts = margins.family_starts[: len(FAMILIES)]
        starts = self._starts
        # fmin/fmax skip NaN (unknown margins); a family of unknowns leaves the record as is.
        np.fmin(self._min_margin, np.fmin.reduceat(margins.values, starts), out=self._min_margin)
        self.max_required_friction = float(
            np.fmax(self.max_required_friction, np.fmax.reduce(margins.required_friction))
        )
        previous = self._active
        self._active = mask
        if not events:
            return
        violated = np.logical_or.reduceat(mask, starts)
        self._counts += violated
        self._first_t[violated & np.isnan(self._first_t)] = margins.t
        starting = mask if previous is None or previous.shape != mask.shape else mask & ~previous
        self.onsets.extend(
            event for event, new in zip(events, starting[mask].tolist(), strict=True) if new
        )

    def violations(self) -> dict[str, dict[str, int | float | None]]:
        """``{family: {"count": steps in violation, "first_t": s or None}}`` for the summary."""
        return {
            family: {'count': record.count, 'first_t': record.first_t}
            for family, record in self.families.items()
        }

    def min_margin(self) -> dict[str, float]:
        """Smallest margin per barrier family over the run, in its own units.

        Keys ``fingertip_workspace`` (rad), ``joint_limits`` (rad) and ``friction``
        (``min(mu_i - beta_i)``, soft fingers with their torsion; ``-inf`` if a contact
        separated); ``inf`` before any record.
        """
        minimum = dict(zip(FAMILIES, self._min_margin.tolist(), strict=True))
        return {
            FINGERTIP_WORKSPACE: minimum[FINGERTIP_WORKSPACE],
            JOINT_LIMITS: minimum[JOINT_LIMITS],
            'friction': minimum[SLIP],
        }
