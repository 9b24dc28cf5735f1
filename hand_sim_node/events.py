"""Grasp constraint events: margins at one instant, violations, and their run-long record.

Five families are watched, each with a margin ``h`` in its own units (``h < 0``: violated):

- ``fingertip_workspace``: per contact, ``(a - a_min, a_max - a, b - b_min, b_max - b)``, rad,
  against the contact's own box.
  The workspace is the open box ``a_min < a < a_max, b_min < b < b_max``, so ``h <= 0`` is
  a violation (the contact point has left the fingertip surface's parameterised patch).
- ``joint_limits``: per joint, ``(q - q_min, q_max - q)``, rad; ``h < 0`` is a violation.
- ``slip``: per contact, the friction margin ``mu_i - beta_i`` (the contact's own mu) with
  ``beta_i = ||f_t,i|| / f_n,i`` (``beta_i = inf`` when ``f_n,i <= 0``); ``h < 0`` is a
  violation. A soft finger (torsional friction ``mu_t,i``, m) also slips by spinning:
  its margin is ``mu_i - max(beta_i, mu_i |tau_i| / (mu_t,i f_n,i))``, negative exactly
  when ``||f_t,i|| > mu_i f_n,i`` or ``|tau_i| > mu_t,i f_n,i`` (``tau_i``: its torsion
  about the normal, N·m).
- ``separation``: per contact, the normal force ``f_n,i``, N; ``f_n,i <= 0`` is a violation.
- ``object_face``: per contact on a box face ``|u| <= h_u, |v| <= h_v``, how far the contact
  point is inside the face's edges, ``min(h_u - |u|, h_v - |v|)``, m; ``h < 0`` is a
  violation (the contact point has rolled off its face). ``inf`` on a sphere object (no
  edge), NaN where the object coordinates or the faces are unknown (flags nothing).

All margins of one instant live in one flat array, family after family (workspace (n, 4),
joints (m, 2), slip (n,), separation (n,), object face (n,), each row-major); the
per-family arrays are views of it. Violations, events and the run's record are evaluated
on that array with one numpy call per quantity, whatever the number of contacts and joints.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.nodes.scenario import object_face_half_widths
from hand_sim_node.margin_kernel import flat_margins

FINGERTIP_WORKSPACE = 'fingertip_workspace'
JOINT_LIMITS = 'joint_limits'
SLIP = 'slip'
SEPARATION = 'separation'
OBJECT_FACE = 'object_face'
FAMILIES: tuple[str, ...] = (FINGERTIP_WORKSPACE, JOINT_LIMITS, SLIP, SEPARATION, OBJECT_FACE)
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
        index: Contact index (workspace, slip, separation, object face) or joint index
            (joint limits).
        name: The contact's or joint's name.
        side: Which bound: ``"a_min"``, ``"a_max"``, ``"b_min"``, ``"b_max"``, ``"lower"``,
            ``"upper"``; ``""`` for slip, separation and object face.
        margin: The violated margin (rad, rad, 1, N, m for the five families; <= 0).

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
        friction: ``mu_i - beta_i``, shape (n,) (soft fingers: with their torsion, see the
            module docstring).
        normal_force: ``f_n,i``, shape (n,), N.
        object_face: ``min(h_u - |u|, h_v - |v|)`` per contact, shape (n,), m (NaN where
            unknown; all NaN if not given).
        values: Every margin, family after family in :data:`FAMILIES` order (the five
            arrays above but ``required_friction``, flattened), shape (7n + 2m,); built
            from them if not given.
        violated_mask: ``values`` violated (``<= 0`` for workspace and separation, ``< 0``
            for the others), shape (7n + 2m,); built from ``values`` if not given.

    """

    t: float
    fingertip_workspace: np.ndarray
    joint_limits: np.ndarray
    required_friction: np.ndarray
    friction: np.ndarray
    normal_force: np.ndarray
    object_face: np.ndarray | None = None
    values: np.ndarray | None = field(default=None, repr=False)
    violated_mask: np.ndarray | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if self.object_face is None:
            object.__setattr__(self, 'object_face', np.full(self.normal_force.shape, np.nan))
        if self.values is None:
            flat = np.concatenate([np.ravel(v) for v in self.by_family().values()])
            object.__setattr__(self, 'values', flat)
        if self.violated_mask is None:
            closed = _closed_mask(
                self.fingertip_workspace.size, self.joint_limits.size, self.friction.size
            )
            object.__setattr__(self, 'violated_mask', _violated(self.values, closed))

    @property
    def family_starts(self) -> np.ndarray:
        """Index in :attr:`values` where each family's margins start, shape (5,)."""
        sizes = (
            self.fingertip_workspace.size,
            self.joint_limits.size,
            self.friction.size,
            self.normal_force.size,
        )
        return np.cumsum((0, *sizes))

    def by_family(self) -> dict[str, np.ndarray]:
        """Return the margins of each family, in :data:`FAMILIES` order (slip: mu_i - beta_i)."""
        return {
            FINGERTIP_WORKSPACE: self.fingertip_workspace,
            JOINT_LIMITS: self.joint_limits,
            SLIP: self.friction,
            SEPARATION: self.normal_force,
            OBJECT_FACE: self.object_face,
        }

    def violated(self) -> dict[str, np.ndarray]:
        """Boolean violation masks per family, shaped like the margins."""
        starts = self.family_starts
        return {
            family: self.violated_mask[start : start + values.size].reshape(values.shape)
            for (family, values), start in zip(self.by_family().items(), starts, strict=True)
        }


def _closed_mask(n_workspace: int, n_joint: int, n_contacts: int) -> np.ndarray:
    """Entries of the flat margins whose constraint is violated at 0 (workspace, separation)."""
    return np.concatenate(
        (
            np.ones(n_workspace, dtype=bool),
            np.zeros(n_joint + n_contacts, dtype=bool),
            np.ones(n_contacts, dtype=bool),
            np.zeros(n_contacts, dtype=bool),
        )
    )


def _per_contact(value: Any, n: int, name: str, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` per contact, shape (n, *shape): one for every contact or one per contact.

    A workspace ``(a_min, a_max, b_min, b_max)`` has shape (4,), each bound a number or (n,).
    """
    try:
        parts = [np.asarray(v, dtype=float) for v in value] if shape else [value]
        columns = [np.broadcast_to(np.asarray(p, dtype=float).reshape(-1), (n,)) for p in parts]
        array = np.column_stack(columns) if shape else columns[0]
    except (TypeError, ValueError):
        raise ValueError(
            f'EventMonitor: expected {name} with one value or {n} (one per contact), got {value!r}'
        ) from None
    if array.shape != (n, *shape) or not np.all(np.isfinite(array)):
        raise ValueError(
            f'EventMonitor: expected finite {name} with one value or {n} (one per contact), got '
            f'{value!r}'
        )
    return array.copy()


def _positive_per_contact(value: Any, n: int, name: str) -> np.ndarray:
    """:func:`_per_contact` of a coefficient that must be > 0 (mu_i, mu_t,i), shape (n,)."""
    array = _per_contact(value, n, name, ())
    if not np.all(array > 0.0):
        raise ValueError(f'EventMonitor: expected {name} > 0, got {array.tolist()}')
    return array


#: ``xi_co`` and face half widths when unknown (the object-face margins are then NaN).
_NO_FACES = np.zeros((0, 2))
#: Torsions and torsional friction of point contacts (or torsions not given).
_NO_TORSION = np.zeros(0)


def _violated(values: np.ndarray, closed: np.ndarray) -> np.ndarray:
    """``values <= 0`` where ``closed``, ``values < 0`` elsewhere (NaN: not violated)."""
    return (values < 0.0) | (closed & (values == 0.0))


class EventMonitor:
    """Evaluates the five constraint families of a grasp state under a contact force.

    Args:
        joint_lower_limits: ``q_min``, shape (m,), rad.
        joint_upper_limits: ``q_max``, shape (m,), rad.
        fingertip_workspace: ``(a_min, a_max, b_min, b_max)``, rad, each one value for every
            contact or one per contact (n,).
        friction_coefficient: ``mu_i`` (> 0): one for every contact or one per contact (n,);
            contact i slips when its beta_i > mu_i.
        joint_names: m joint names.
        contact_names: n contact names.
        object_face_half_widths: Half extents ``(h_u, h_v)`` of each contact's face, (n, 2),
            m (``inf``: no edge); None if unknown (object-face margins are then NaN).
        torsional_friction: Soft fingers' ``mu_t,i`` (> 0, m): one for every contact or one
            per contact (n,); None: point contacts.

    """

    def __init__(
        self,
        joint_lower_limits: np.ndarray,
        joint_upper_limits: np.ndarray,
        fingertip_workspace: Sequence[float | Sequence[float] | np.ndarray],
        friction_coefficient: float | Sequence[float] | np.ndarray,
        joint_names: list[str] | tuple[str, ...],
        contact_names: list[str] | tuple[str, ...],
        object_face_half_widths: np.ndarray | None = None,
        torsional_friction: float | Sequence[float] | np.ndarray | None = None,
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
        n = len(contact_names)
        box = _per_contact(fingertip_workspace, n, 'fingertip_workspace', (4,))
        if not (np.all(box[:, 0] < box[:, 1]) and np.all(box[:, 2] < box[:, 3])):
            raise ValueError(
                'EventMonitor: expected fingertip_workspace (a_min < a_max, b_min < b_max), '
                f'got {box.tolist()}'
            )
        mu = _positive_per_contact(friction_coefficient, n, 'friction_coefficient')
        # Per contact (n, 2): (a_min, b_min) and (a_max, b_max); mu_i, (n,).
        self.workspace_low = box[:, [0, 2]].copy()
        self.workspace_high = box[:, [1, 3]].copy()
        self.friction_coefficient = mu
        self.torsional_friction = None
        if torsional_friction is not None:
            self.torsional_friction = _positive_per_contact(
                torsional_friction, n, 'torsional_friction'
            )
        self.joint_names = tuple(joint_names)
        self.contact_names = tuple(contact_names)
        self.object_face_half_widths = None
        if object_face_half_widths is not None:
            half = np.array(object_face_half_widths, dtype=float)
            if half.shape != (n, 2) or np.any(np.isnan(half)) or np.any(half <= 0.0):
                raise ValueError(
                    f'EventMonitor: expected object_face_half_widths of shape ({n}, 2), each '
                    f'> 0, got {half.tolist()}'
                )
            self.object_face_half_widths = half
        self._ends = tuple(int(end) for end in np.cumsum((4 * n, 2 * m, n, n, n)))
        self._closed = _closed_mask(4 * n, 2 * m, n)
        # (family, index, name, side) of every flat margin, for the events.
        self._entries = (
            [
                (FINGERTIP_WORKSPACE, i, self.contact_names[i], side)
                for i in range(n)
                for side in WORKSPACE_SIDES
            ]
            + [
                (JOINT_LIMITS, j, self.joint_names[j], side)
                for j in range(m)
                for side in JOINT_SIDES
            ]
            + [(SLIP, i, self.contact_names[i], '') for i in range(n)]
            + [(SEPARATION, i, self.contact_names[i], '') for i in range(n)]
            + [(OBJECT_FACE, i, self.contact_names[i], '') for i in range(n)]
        )

    @classmethod
    def from_model(cls, model: Any) -> EventMonitor:
        """Monitor with the limits, workspace, friction, names and faces of a model.

        Soft fingers (the model's ``torsional_friction``) are judged with their torsion.
        """
        return cls(
            joint_lower_limits=model.joint_lower_limits,
            joint_upper_limits=model.joint_upper_limits,
            fingertip_workspace=tuple(model.fingertip_workspace),
            friction_coefficient=model.friction_coefficient,
            joint_names=model.joint_names,
            contact_names=model.contact_names,
            object_face_half_widths=object_face_half_widths(model),
            torsional_friction=getattr(model, 'torsional_friction', None),
        )

    def margins(self, state: GraspState, contact_force: np.ndarray) -> ConstraintMargins:
        """Margins of every constraint at ``state`` under the contact forces ``contact_force``.

        Args:
            state: The grasp state (reads t, q, xi_cf, xi_co).
            contact_force: Stacked contact forces ``(f_x, f_y, f_n)`` per contact, contact
                frames, shape (3n,), N; or a soft finger's wrench (4n,) (see
                :meth:`margins_at`).

        """
        return self.margins_at(state.t, state.q, state.xi_cf, contact_force, state.xi_co)

    def margins_at(
        self,
        t: float,
        q: np.ndarray,
        xi_cf: np.ndarray,
        contact_force: np.ndarray,
        xi_co: np.ndarray | None = None,
    ) -> ConstraintMargins:
        """Margins from raw samples: joint angles (m,), fingertip coordinates (n, 2), forces (3n,).

        A soft finger's contact wrench (4n,) has its torsions ``tau_i`` (N·m) after the forces:
        a monitor with ``torsional_friction`` judges them in the slip margins. Given the
        forces alone (3n,), or with point contacts, slip is the force cone's.

        With the object surface coordinates ``xi_co`` (n, 2) (m on a face) and the faces'
        half extents, also the object-face margins (else NaN). The bag analysis evaluates
        recorded runs with this, so a run and its recording are judged by the same code.
        """
        a_b = np.asarray(xi_cf, dtype=float)
        wrench = np.asarray(contact_force, dtype=float).reshape(-1)
        n, m = a_b.shape[0], self.joint_lower_limits.shape[0]
        workspace_end, joint_end, slip_end, separation_end, size = self._ends
        if wrench.size not in (3 * n, 4 * n) or size != 7 * n + 2 * m:
            raise ValueError(
                f'EventMonitor.margins_at: expected {len(self.contact_names)} contacts, got '
                f'coordinates of {n} and a contact wrench of {wrench.size} entries (3 per '
                'contact, or 4 with soft fingers)'
            )
        # Slip and separation read the forces; a soft finger's torsion entries follow them.
        forces = wrench[: 3 * n].reshape(n, 3)
        mu_t = self.torsional_friction
        soft = mu_t is not None and wrench.size == 4 * n
        torsion = wrench[3 * n :] if soft else _NO_TORSION
        q = np.asarray(q, dtype=float)
        faces = self.object_face_half_widths
        no_faces = xi_co is None or faces is None
        xi_co = None if no_faces else np.asarray(xi_co, dtype=float)
        # The compiled pass reads its inputs without bounds checks.
        wrong = [
            f'{name} of shape {array.shape}, expected {shape}'
            for name, array, shape in (
                ('xi_cf', a_b, (n, 2)),
                ('q', q, (m,)),
                ('xi_co', _NO_FACES if xi_co is None else xi_co, (0, 2) if no_faces else (n, 2)),
            )
            if array.shape != shape
        ]
        if wrong:
            raise ValueError(f'EventMonitor.margins_at: got {"; ".join(wrong)}')
        values, beta, violated = flat_margins(
            a_b,
            forces,
            q,
            _NO_FACES if xi_co is None else xi_co,
            self.workspace_low,
            self.workspace_high,
            self.joint_lower_limits,
            self.joint_upper_limits,
            self.friction_coefficient,
            _NO_FACES if no_faces else faces,
            self._closed,
            torsion,
            mu_t if soft else _NO_TORSION,
        )
        return ConstraintMargins(
            t=float(t),
            fingertip_workspace=values[:workspace_end].reshape(n, 4),
            joint_limits=values[workspace_end:joint_end].reshape(m, 2),
            required_friction=beta,
            friction=values[joint_end:slip_end],
            normal_force=values[slip_end:separation_end],
            object_face=values[separation_end:],
            values=values,
            violated_mask=violated,
        )

    def events(self, margins: ConstraintMargins) -> tuple[Event, ...]:
        """Every violated constraint of ``margins``, family by family, row-major within one."""
        mask = margins.violated_mask
        if not mask.any():
            return ()
        if mask.size != len(self._entries):
            raise ValueError(
                f'EventMonitor.events: expected {len(self._entries)} margins, got {mask.size}'
            )
        t, entries = margins.t, self._entries
        return tuple(
            Event(t, *entries[k], value)
            for k, value in zip(
                np.flatnonzero(mask).tolist(), margins.values[mask].tolist(), strict=True
            )
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
