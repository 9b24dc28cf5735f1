"""The fingertip workspace: the box of admissible fingertip contact coordinates (a, b).

Per contact i, ``a_min,i <= a_i <= a_max,i`` and ``b_min,i <= b_i <= b_max,i`` (rad) in the
fingertip sphere's chart ``c(a, b) = R (-cos a cos b, sin a, -cos a sin b)``; the chart is
singular at ``a = ±pi/2``, so ``a`` is bounded inside ``[-pi/2, pi/2]``. Each bound is one
value for every contact or one per contact (fingertips of different shapes,
:mod:`grasp_safety_filter.model.per_contact`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.model.per_contact import element_label, per_contact_values

#: The bounds, in the order of the box's rows and of iteration over a FingertipWorkspace.
BOUNDS: tuple[str, ...] = ('a_min', 'a_max', 'b_min', 'b_max')

#: Prefix of the bounds' parameter names.
PARAMETER_PREFIX = 'model.fingertip_workspace.'

#: One bound: a float (every contact) or a tuple of one float per contact, rad.
Bound = float | tuple[float, ...]


class GraspConfigError(ConfigError):
    """The configuration does not describe a valid grasp (names the parameter and the values)."""


def _as_bound(value: Any) -> Bound:
    """Return a float for one value, a tuple of floats for one per contact."""
    if np.ndim(value) == 0:
        return float(value)
    return tuple(float(v) for v in np.reshape(value, -1))


@dataclass(frozen=True)
class FingertipWorkspace:
    """Admissible fingertip coordinates ``a_min ≤ a ≤ a_max, b_min ≤ b ≤ b_max``, rad.

    Each bound is a float (every contact) or a tuple with one value per contact
    (:meth:`for_contacts` checks the count against the contacts and names them).
    """

    a_min: Bound
    a_max: Bound
    b_min: Bound
    b_max: Bound

    def __post_init__(self) -> None:
        for name in BOUNDS:
            object.__setattr__(self, name, _as_bound(getattr(self, name)))
        sizes = {len(v) for v in self if isinstance(v, tuple)}
        if len(sizes) > 1:
            raise GraspConfigError(
                f'{PARAMETER_PREFIX}*: expected one value or the same number of values per '
                f'bound, got {[np.size(v) for v in self]} values of {list(BOUNDS)}'
            )
        n = sizes.pop() if sizes else 1
        _check_box(self.per_contact(n), self._counts(), [f'#{i}' for i in range(n)])

    @classmethod
    def for_contacts(cls, contact_names: Sequence[str], **bounds: Any) -> FingertipWorkspace:
        """Build from ``a_min=..., a_max=..., b_min=..., b_max=...``, each 1 or n values.

        Raises:
            GraspConfigError: A bound has neither 1 nor n values, or a contact's box is
                empty or reaches past ``a = ±pi/2``; the message names the parameter, the
                contact and the values.
        """
        n = len(contact_names)
        given: dict[str, Any] = {}
        for name in BOUNDS:
            try:
                values = per_contact_values(bounds[name], contact_names, PARAMETER_PREFIX + name)
            except ConfigError as error:
                raise GraspConfigError(str(error)) from None
            given[name] = float(values[0]) if np.size(bounds[name]) == 1 else values
        box = np.column_stack([np.broadcast_to(given[name], (n,)) for name in BOUNDS])
        _check_box(box, {name: np.size(given[name]) for name in BOUNDS}, contact_names)
        return cls(**given)

    def __iter__(self):  # noqa: ANN204 - tuple-like unpacking: a_min, a_max, b_min, b_max
        return iter((self.a_min, self.a_max, self.b_min, self.b_max))

    def _counts(self) -> dict[str, int]:
        return {name: int(np.size(getattr(self, name))) for name in BOUNDS}

    def per_contact(self, n: int) -> np.ndarray:
        """Each contact's ``(a_min, a_max, b_min, b_max)``, shape (n, 4), rad.

        Raises:
            GraspConfigError: A bound has one value per contact for another number of
                contacts than n.
        """
        columns = []
        for name in BOUNDS:
            value = np.asarray(getattr(self, name), dtype=float).reshape(-1)
            if value.size not in (1, n):
                raise GraspConfigError(
                    f'{PARAMETER_PREFIX}{name}: expected 1 or {n} values (one per contact), '
                    f'got {value.size}'
                )
            columns.append(np.broadcast_to(value, (n,)))
        return np.column_stack(columns)

    def margins(self, xi_cf: np.ndarray) -> np.ndarray:
        """Barrier values ``(a - a_min, a_max - a, b - b_min, b_max - b)`` per contact, (n, 4)."""
        xi = np.atleast_2d(xi_cf)
        box = self.per_contact(xi.shape[0])
        a, b = xi[:, 0], xi[:, 1]
        return np.column_stack([a - box[:, 0], box[:, 1] - a, b - box[:, 2], box[:, 3] - b])


def _check_box(box: np.ndarray, counts: dict[str, int], contact_names: Sequence[str]) -> None:
    """Raise GraspConfigError unless every contact's box (a row of ``box``) is admissible."""
    for i, (a_min, a_max, b_min, b_max) in enumerate(box.tolist()):
        if not -np.pi / 2 <= a_min < a_max <= np.pi / 2:
            raise GraspConfigError(
                f'{_pair_label("a", i, counts, contact_names)}: expected -pi/2 <= a_min < '
                f'a_max <= pi/2, got a_min={a_min}, a_max={a_max}'
            )
        if not b_min < b_max:
            raise GraspConfigError(
                f'{_pair_label("b", i, counts, contact_names)}: expected b_min < b_max, got '
                f'b_min={b_min}, b_max={b_max}'
            )


def _pair_label(coordinate: str, index: int, counts: dict[str, int], names: Sequence[str]) -> str:
    """Name the two bounds of one coordinate of one contact (of every contact if shared)."""
    low, high = f'{coordinate}_min', f'{coordinate}_max'
    label = f'{PARAMETER_PREFIX}{low}/{high}'
    return element_label(label, index, max(counts[low], counts[high]), names)
