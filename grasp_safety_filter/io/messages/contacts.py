"""``/hand/contacts``: per-contact coordinates, forces and penetration, by contact name."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import lru_cache
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.fields import (
    array_field,
    match_names,
    shaped_array,
    time_from_msg,
    unique_names,
)
from grasp_safety_filter.io.messages.joint_states import joint_state_to_msg
from grasp_safety_filter.io.messages.namespace import MessageNamespace
from grasp_safety_filter.model.grasp_state import GraspState

CONTACT_QUANTITIES: tuple[str, ...] = (
    'a',
    'b',
    'u',
    'v',
    'psi',
    'force_x',
    'force_y',
    'force_normal',
    'required_friction',
    'penetration',
)
"""Per-contact entries of ``/hand/contacts``, in publishing order."""

# ----------------------------------------------------------------------------------------
# Contacts


@dataclass(frozen=True)
class ContactData:
    """Contact coordinates, rates and forces of n contacts, in the caller's contact order.

    Attributes:
        t: Stamp, s.
        xi_cf: Fingertip surface coordinates ``(a, b)``, shape (n, 2), rad.
        xi_co: Object surface coordinates ``(u, v)``, shape (n, 2) (m on a face).
        psi: Angle between the surfaces' first tangent axes, shape (n,), rad.
        xi_cf_dot, xi_co_dot, psi_dot: Their rates, shapes (n, 2), (n, 2), (n,).
        force: Contact force on the object in the contact frame ``(f_x, f_y, f_n)``,
            shape (n, 3), N.
        required_friction: ``|f_t| / f_n``, shape (n,); ``+inf`` when ``f_n <= 0``.
        penetration: Normal interpenetration, shape (n,), m.

    """

    t: float
    xi_cf: np.ndarray
    xi_co: np.ndarray
    psi: np.ndarray
    xi_cf_dot: np.ndarray
    xi_co_dot: np.ndarray
    psi_dot: np.ndarray
    force: np.ndarray
    required_friction: np.ndarray
    penetration: np.ndarray

    @classmethod
    def from_grasp_state(cls, state: GraspState, force: np.ndarray) -> ContactData:
        """Take the contact part of a grasp state, with the contact forces ``force`` (3n,)."""
        # A soft finger's torsion entries follow the 3n forces; they are not published here.
        n = state.n_contacts
        forces = np.asarray(force, dtype=np.float64).reshape(-1)[: 3 * n].reshape(n, 3)
        return cls(
            t=state.t,
            xi_cf=np.array(state.xi_cf),
            xi_co=np.array(state.xi_co),
            psi=np.array(state.psi),
            xi_cf_dot=np.array(state.xi_cf_dot),
            xi_co_dot=np.array(state.xi_co_dot),
            psi_dot=np.array(state.psi_dot),
            force=forces,
            required_friction=state.required_friction(forces),
            penetration=np.array(state.penetration),
        )

    def _columns(self) -> tuple[np.ndarray, np.ndarray]:
        """Values and rates, shape (n, len(CONTACT_QUANTITIES)), in publishing order."""
        n = np.asarray(self.psi).shape[0]
        zeros = np.zeros(n)
        values = np.column_stack(
            (
                self.xi_cf,
                self.xi_co,
                self.psi,
                self.force,
                self.required_friction,
                self.penetration,
            )
        )
        rates = np.column_stack(
            (self.xi_cf_dot, self.xi_co_dot, self.psi_dot, zeros, zeros, zeros, zeros, zeros)
        )
        return values, rates


def contact_entry_names(contact_names: Sequence[str]) -> list[str]:
    """Names of ``/hand/contacts`` entries: ``"<contact>/<quantity>"``, contact-major."""
    return list(_entry_names(tuple(contact_names)))


@lru_cache(maxsize=64)
def _entry_names(contact_names: tuple[str, ...]) -> tuple[str, ...]:
    """:func:`contact_entry_names` of a name tuple, built once per tuple."""
    return tuple(f'{c}/{q}' for c in contact_names for q in CONTACT_QUANTITIES)


@lru_cache(maxsize=64)
def positive_inf_allowed(entry_names: tuple[str, ...]) -> tuple[bool, ...]:
    """Per entry name, whether ``+inf`` is admissible there (``required_friction``)."""
    return tuple(name.rsplit('/', 1)[-1] == 'required_friction' for name in entry_names)


def contacts_to_msg(
    msgs: MessageNamespace, data: ContactData, contact_names: Sequence[str]
) -> Any:
    """Build ``/hand/contacts``: a JointState used as a stamped named-value list.

    Layout (public): for each contact ``c`` in order, ten entries named
    ``c/a, c/b, c/u, c/v, c/psi, c/force_x, c/force_y, c/force_normal,
    c/required_friction, c/penetration``;

    - ``position`` holds the value: ``a, b`` fingertip surface coordinates (rad), ``u, v``
      object surface coordinates (m on a face), ``psi`` (rad), ``force_*`` the contact
      force on the object in the contact frame (N), ``required_friction`` ``|f_t|/f_n``
      (``+inf`` when the contact separates), ``penetration`` (m);
    - ``velocity`` holds the rate for ``a, b, u, v, psi`` and 0.0 for the others;
    - ``effort`` is empty; ``header.frame_id`` is empty (each value is in its own frame).
    """
    names = unique_names('contacts', contact_names, 'contact')
    n = len(names)
    shapes = {
        'xi_cf': (n, 2),
        'xi_co': (n, 2),
        'psi': (n,),
        'xi_cf_dot': (n, 2),
        'xi_co_dot': (n, 2),
        'psi_dot': (n,),
        'force': (n, 3),
        'required_friction': (n,),
        'penetration': (n,),
    }
    for name, shape in shapes.items():
        shaped_array(f'contacts {name}', getattr(data, name), shape)
    values, rates = data._columns()
    return joint_state_to_msg(
        msgs, data.t, _entry_names(names), values.ravel(), rates.ravel(), None
    )


def contacts_from_msg(
    msg: Any, contact_names: Sequence[str], source: str = 'contacts'
) -> ContactData:
    """Parse a ``/hand/contacts`` message of exactly ``contact_names`` (any entry order).

    Raises:
        MessageError: Duplicate, unknown or missing entries; position or velocity lengths
            not matching the names; a non-finite value (``required_friction`` may be
            ``+inf``); a non-empty effort of the wrong length.

    """
    expected = contact_entry_names(contact_names)
    order = match_names(source, msg.name, expected, 'contact entry')
    names = list(msg.name)
    inf_ok = positive_inf_allowed(tuple(names))
    values = array_field(
        source, msg.position, 'position', names, required=True, allow_positive_inf=inf_ok
    )
    rates = array_field(source, msg.velocity, 'velocity', names, required=True)
    array_field(source, msg.effort, 'effort', names, required=False)
    n, k = len(contact_names), len(CONTACT_QUANTITIES)
    values = values[order].reshape(n, k)
    rates = rates[order].reshape(n, k)
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return ContactData(
        t=t,
        xi_cf=values[:, 0:2],
        xi_co=values[:, 2:4],
        psi=values[:, 4],
        xi_cf_dot=rates[:, 0:2],
        xi_co_dot=rates[:, 2:4],
        psi_dot=rates[:, 4],
        force=values[:, 5:8],
        required_friction=values[:, 8],
        penetration=values[:, 9],
    )
