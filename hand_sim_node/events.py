"""Grasp constraint events: margins at one instant, violations, and their run-long record.

Four families are watched, each with a margin ``h`` in its own units (``h < 0``: violated):

- ``fingertip_workspace``: per contact, ``(a - a_min, a_max - a, b - b_min, b_max - b)``, rad.
  The workspace is the open box ``a_min < a < a_max, b_min < b < b_max``, so ``h <= 0`` is
  a violation (the contact point has left the fingertip surface's parameterised patch).
- ``joint_limits``: per joint, ``(q - q_min, q_max - q)``, rad; ``h < 0`` is a violation.
- ``slip``: per contact, the friction margin ``mu - beta_i`` with
  ``beta_i = ||f_t,i|| / f_n,i`` (``beta_i = inf`` when ``f_n,i <= 0``); ``h < 0`` is a
  violation.
- ``separation``: per contact, the normal force ``f_n,i``, N; ``f_n,i <= 0`` is a violation.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grasp_safety_filter.model.grasp_state import GraspState, required_friction

FINGERTIP_WORKSPACE = 'fingertip_workspace'
JOINT_LIMITS = 'joint_limits'
SLIP = 'slip'
SEPARATION = 'separation'
FAMILIES: tuple[str, ...] = (FINGERTIP_WORKSPACE, JOINT_LIMITS, SLIP, SEPARATION)
"""Constraint families, in the order the run summary lists them."""

WORKSPACE_SIDES: tuple[str, ...] = ('a_min', 'a_max', 'b_min', 'b_max')
JOINT_SIDES: tuple[str, ...] = ('lower', 'upper')

#: Bound of each margin column of the two-sided families (slip and separation have none).
_SIDES: dict[str, tuple[str, ...]] = {
    FINGERTIP_WORKSPACE: WORKSPACE_SIDES,
    JOINT_LIMITS: JOINT_SIDES,
}


@dataclass(frozen=True)
class Event:
    """One constraint violated at one instant.

    Attributes:
        t: Time, s.
        family: One of :data:`FAMILIES`.
        index: Contact index (workspace, slip, separation) or joint index (joint limits).
        name: The contact's or joint's name.
        side: Which bound: ``"a_min"``, ``"a_max"``, ``"b_min"``, ``"b_max"``, ``"lower"``,
            ``"upper"``; ``""`` for slip and separation.
        margin: The violated margin (rad, rad, 1, N for the four families; <= 0).

    """

    t: float
    family: str
    index: int
    name: str
    side: str
    margin: float


@dataclass(frozen=True, eq=False)
class ConstraintMargins:
    """All constraint margins at one instant (negative = violated).

    Attributes:
        t: Time, s.
        fingertip_workspace: Shape (n, 4): ``a - a_min, a_max - a, b - b_min, b_max - b``, rad.
        joint_limits: Shape (m, 2): ``q - q_min, q_max - q``, rad.
        required_friction: ``beta_i``, shape (n,) (``inf`` where ``f_n,i <= 0``).
        friction: ``mu - beta_i``, shape (n,).
        normal_force: ``f_n,i``, shape (n,), N.

    """

    t: float
    fingertip_workspace: np.ndarray
    joint_limits: np.ndarray
    required_friction: np.ndarray
    friction: np.ndarray
    normal_force: np.ndarray

    def by_family(self) -> dict[str, np.ndarray]:
        """Return the margins of each family, in :data:`FAMILIES` order (slip: ``mu - beta_i``)."""
        return {
            FINGERTIP_WORKSPACE: self.fingertip_workspace,
            JOINT_LIMITS: self.joint_limits,
            SLIP: self.friction,
            SEPARATION: self.normal_force,
        }

    def violated(self) -> dict[str, np.ndarray]:
        """Boolean violation masks per family, shaped like the margins."""
        return {
            FINGERTIP_WORKSPACE: self.fingertip_workspace <= 0.0,
            JOINT_LIMITS: self.joint_limits < 0.0,
            SLIP: self.friction < 0.0,
            SEPARATION: self.normal_force <= 0.0,
        }


class EventMonitor:
    """Evaluates the four constraint families of a grasp state under a contact force.

    Args:
        joint_lower_limits: ``q_min``, shape (m,), rad.
        joint_upper_limits: ``q_max``, shape (m,), rad.
        fingertip_workspace: ``(a_min, a_max, b_min, b_max)``, rad.
        friction_coefficient: ``mu`` (> 0).
        joint_names: m joint names.
        contact_names: n contact names.

    """

    def __init__(
        self,
        joint_lower_limits: np.ndarray,
        joint_upper_limits: np.ndarray,
        fingertip_workspace: tuple[float, float, float, float],
        friction_coefficient: float,
        joint_names: list[str] | tuple[str, ...],
        contact_names: list[str] | tuple[str, ...],
    ) -> None:
        self.joint_lower_limits = np.array(joint_lower_limits, dtype=float)
        self.joint_upper_limits = np.array(joint_upper_limits, dtype=float)
        m = len(joint_names)
        if self.joint_lower_limits.shape != (m,) or self.joint_upper_limits.shape != (m,):
            raise ValueError(
                f'EventMonitor: expected joint limits of shape ({m},), got '
                f'{self.joint_lower_limits.shape} and {self.joint_upper_limits.shape}'
            )
        if np.any(self.joint_lower_limits >= self.joint_upper_limits):
            raise ValueError(
                'EventMonitor: expected joint_lower_limits < joint_upper_limits, got '
                f'{self.joint_lower_limits.tolist()} and {self.joint_upper_limits.tolist()}'
            )
        a_min, a_max, b_min, b_max = (float(v) for v in fingertip_workspace)
        if not (a_min < a_max and b_min < b_max):
            raise ValueError(
                'EventMonitor: expected fingertip_workspace (a_min < a_max, b_min < b_max), '
                f'got {tuple(fingertip_workspace)}'
            )
        if not friction_coefficient > 0.0:
            raise ValueError(
                f'EventMonitor: expected friction_coefficient > 0, got {friction_coefficient}'
            )
        self.workspace_low = np.array([a_min, b_min])
        self.workspace_high = np.array([a_max, b_max])
        self.friction_coefficient = float(friction_coefficient)
        self.joint_names = tuple(joint_names)
        self.contact_names = tuple(contact_names)

    @classmethod
    def from_model(cls, model: Any) -> EventMonitor:
        """Monitor with the limits, workspace, friction coefficient and names of a GraspModel."""
        return cls(
            joint_lower_limits=model.joint_lower_limits,
            joint_upper_limits=model.joint_upper_limits,
            fingertip_workspace=tuple(model.fingertip_workspace),
            friction_coefficient=model.friction_coefficient,
            joint_names=model.joint_names,
            contact_names=model.contact_names,
        )

    def margins(self, state: GraspState, contact_force: np.ndarray) -> ConstraintMargins:
        """Margins of every constraint at ``state`` under the contact forces ``contact_force``.

        Args:
            state: The grasp state (reads t, q, xi_cf).
            contact_force: Stacked contact forces ``(f_x, f_y, f_n)`` per contact, contact
                frames, shape (3n,), N.

        """
        return self.margins_at(state.t, state.q, state.xi_cf, contact_force)

    def margins_at(
        self, t: float, q: np.ndarray, xi_cf: np.ndarray, contact_force: np.ndarray
    ) -> ConstraintMargins:
        """Margins from raw samples: joint angles (m,), fingertip coordinates (n, 2), forces (3n,).

        The bag analysis evaluates recorded runs with this, so a run and its recording are
        judged by the same code.
        """
        a_b = np.asarray(xi_cf, dtype=float)
        forces = np.asarray(contact_force, dtype=float).reshape(-1, 3)
        workspace = np.empty((a_b.shape[0], 4))
        workspace[:, 0::2] = a_b - self.workspace_low
        workspace[:, 1::2] = self.workspace_high - a_b
        joints = np.column_stack((q - self.joint_lower_limits, self.joint_upper_limits - q))
        normal = forces[:, 2]
        beta = required_friction(forces)
        # Unknown forces (the dynamics could not be evaluated) flag nothing.
        beta[~np.isfinite(normal)] = np.nan
        return ConstraintMargins(
            t=float(t),
            fingertip_workspace=workspace,
            joint_limits=joints,
            required_friction=beta,
            friction=self.friction_coefficient - beta,
            normal_force=normal.copy(),
        )

    def events(self, margins: ConstraintMargins) -> tuple[Event, ...]:
        """Every violated constraint of ``margins``, family by family."""
        violated = margins.violated()
        if not any(mask.any() for mask in violated.values()):
            return ()
        found: list[Event] = []
        for family, values in margins.by_family().items():
            names = self.joint_names if family == JOINT_LIMITS else self.contact_names
            sides = _SIDES.get(family)
            for index in np.argwhere(violated[family]):
                row = int(index[0])
                found.append(
                    Event(
                        margins.t,
                        family,
                        row,
                        names[row],
                        sides[index[1]] if sides else '',
                        float(values[tuple(index)]),
                    )
                )
        return tuple(found)


def _finite_or_inf_min(values: np.ndarray) -> float:
    """Smallest value ignoring NaN (unknown), ``inf`` if there is none."""
    known = values[~np.isnan(values)]
    return float(known.min()) if known.size else float('inf')


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
        families: Per family, its :class:`FamilyRecord`.
        onsets: Every event at the instant it starts (a constraint that was satisfied at the
            previous evaluation, or the first evaluation), in time order.
        max_required_friction: Largest ``beta_i`` over the run (``inf`` after a separation).
        n_evaluations: Number of recorded instants.

    """

    families: dict[str, FamilyRecord] = field(
        default_factory=lambda: {family: FamilyRecord() for family in FAMILIES}
    )
    onsets: list[Event] = field(default_factory=list)
    max_required_friction: float = 0.0
    n_evaluations: int = 0
    _active: set[tuple[str, int, str]] = field(default_factory=set, repr=False)

    def record(self, margins: ConstraintMargins, events: tuple[Event, ...]) -> None:
        """Add one instant: its margins and the events found in them."""
        self.n_evaluations += 1
        for family, values in margins.by_family().items():
            record = self.families[family]
            record.min_margin = min(record.min_margin, _finite_or_inf_min(values))
        self.max_required_friction = max(
            self.max_required_friction, -_finite_or_inf_min(-margins.required_friction)
        )
        active = {(event.family, event.index, event.side) for event in events}
        for family in {event.family for event in events}:
            record = self.families[family]
            record.count += 1
            if record.first_t is None:
                record.first_t = margins.t
        self.onsets.extend(
            event
            for event in events
            if (event.family, event.index, event.side) not in self._active
        )
        self._active = active

    def violations(self) -> dict[str, dict[str, int | float | None]]:
        """``{family: {"count": steps in violation, "first_t": s or None}}`` for the summary."""
        return {
            family: {'count': record.count, 'first_t': record.first_t}
            for family, record in self.families.items()
        }

    def min_margin(self) -> dict[str, float]:
        """Smallest margin per barrier family over the run, in its own units.

        Keys ``fingertip_workspace`` (rad), ``joint_limits`` (rad) and ``friction``
        (``min(mu - beta_i)``, ``-inf`` if a contact separated); ``inf`` before any record.
        """
        return {
            FINGERTIP_WORKSPACE: self.families[FINGERTIP_WORKSPACE].min_margin,
            JOINT_LIMITS: self.families[JOINT_LIMITS].min_margin,
            'friction': self.families[SLIP].min_margin,
        }
