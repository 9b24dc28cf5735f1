"""Model parameters given once for every contact or once per contact.

``model.friction_coefficient``, ``model.torsional_friction`` and each bound of
``model.fingertip_workspace`` take one
value (every contact) or a list of n values in contact order (``model.contact_names``):
fingertips of different materials and shapes. :func:`per_contact_values` turns either form
into one value per contact; its errors name the parameter, the contact and the value.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import math
from typing import Any

import numpy as np

from grasp_safety_filter.errors import ConfigError


class PerContactError(ConfigError):
    """A per-contact parameter has the wrong number of values or an inadmissible one."""


def value_count(value: Any) -> int:
    """Return how many values are given: 1 for a number, the length of a list."""
    if isinstance(value, str | bytes):
        return 1
    return int(np.size(value))


def element_label(parameter: str, index: int, given: int, contact_names: Sequence[str]) -> str:
    """Name one contact's value: ``"model.friction_coefficient[2] (contact finger3)"``.

    A single value (``given == 1``) is named by the parameter alone: it is every contact's.
    """
    if given == 1:
        return parameter
    return f'{parameter}[{index}] (contact {contact_names[index]})'


def per_contact_values(
    value: Any,
    contact_names: Sequence[str],
    parameter: str,
    admissible: Callable[[float], bool] = math.isfinite,
    expected: str = 'a finite number',
) -> np.ndarray:
    """One value per contact, read-only, shape (n,), from one value or a list of n.

    Args:
        value: A number, or a sequence of one number or of n numbers (contact order).
        contact_names: The n contact names, for the messages.
        parameter: The parameter's name, e.g. ``"model.friction_coefficient"``.
        admissible: Whether a (finite) value is admissible.
        expected: What an admissible value is, for the message (``"> 0"``).

    Raises:
        PerContactError: Not 1 or n numbers, or a value that is not finite or not
            admissible: ``"model.friction_coefficient[2] (contact finger3): expected > 0,
            got -0.1"``.
    """
    n = len(contact_names)
    given = value_count(value)
    try:
        array = np.array(value, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise PerContactError(
            f'{parameter}: expected a number or a list of 1 or {n} numbers (one per contact '
            f'{list(contact_names)}), got {value!r}'
        ) from None
    if array.size not in (1, n):
        raise PerContactError(
            f'{parameter}: expected 1 or {n} values (one for every contact or one per contact '
            f'{list(contact_names)}), got {array.size}'
        )
    for index, number in enumerate(array.tolist()):
        if not (math.isfinite(number) and admissible(number)):
            label = element_label(parameter, index, given, contact_names)
            raise PerContactError(f'{label}: expected {expected}, got {number!r}')
    values = np.broadcast_to(array, (n,)).copy()
    values.setflags(write=False)
    return values


def friction_coefficients(value: Any, contact_names: Sequence[str]) -> np.ndarray:
    """Each contact's Coulomb friction coefficient mu_i > 0, shape (n,) (one or n values)."""
    return per_contact_values(
        value, contact_names, 'model.friction_coefficient', lambda mu: mu > 0.0, '> 0'
    )


def torsional_friction_coefficients(
    value: Any, contact_names: Sequence[str]
) -> np.ndarray | None:
    """Each contact's torsional friction mu_t,i, m, shape (n,); None for point contacts.

    0 for every contact is the paper's point contact with friction: no torque about the
    normal is transmitted, the fingertip spins freely on the object. > 0 for every contact is
    the soft finger: ``|tau_n,i| <= mu_t,i f_n,i`` and no spin. A mix is refused: the model
    is one or the other.

    Raises:
        PerContactError: A value that is negative or not finite, or a mix of 0 and > 0.
    """
    parameter = 'model.torsional_friction'
    values = per_contact_values(value, contact_names, parameter, lambda mu: mu >= 0.0, '>= 0')
    if not values.any():
        return None
    if not values.all():
        raise PerContactError(
            f'{parameter}: expected 0 for every contact (point contacts with friction) or > 0 '
            f'for every contact (soft fingers), got {values.tolist()} for contacts '
            f'{list(contact_names)}'
        )
    return values


def compact(values: Sequence[float] | np.ndarray) -> float | list[float]:
    """One number when every contact has the same value, else the list (for documents)."""
    numbers = [float(v) for v in np.reshape(values, -1)]
    if numbers and all(v == numbers[0] for v in numbers):
        return numbers[0]
    return numbers
