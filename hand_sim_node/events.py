"""Grasp constraint events: the monitor that judges a grasp state against the five families.

:class:`EventMonitor` holds the joint limits, fingertip workspaces, friction coefficients and
object faces of a grasp and evaluates, at one instant, every constraint margin (the families
and their flat layout: :mod:`hand_sim_node.constraint_margins`) and the events of the violated
ones; :class:`~hand_sim_node.event_log.EventLog` keeps their run-long record.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.nodes.scenario import object_face_half_widths
from hand_sim_node.constraint_margins import (
    closed_mask,
    ConstraintMargins,
    Event,
    FINGERTIP_WORKSPACE,
    JOINT_LIMITS,
    JOINT_SIDES,
    OBJECT_FACE,
    SEPARATION,
    SLIP,
    WORKSPACE_SIDES,
)
from hand_sim_node.margin_kernel import flat_margins


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
        self._closed = closed_mask(4 * n, 2 * m, n)
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
