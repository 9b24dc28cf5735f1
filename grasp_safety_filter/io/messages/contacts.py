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
    unique_names,
)
from grasp_safety_filter.io.messages.joint_states import joint_state_to_msg
from grasp_safety_filter.io.messages.namespace import MessageNamespace
from grasp_safety_filter.io.messages.stamps import (
    time_from_msg,
)
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

TORSION = 'torsion'
"""A soft finger's extra entry, after those of :data:`CONTACT_QUANTITIES`."""


def contact_quantities(torsion: bool) -> tuple[str, ...]:
    """Per-contact entries: :data:`CONTACT_QUANTITIES`, then ``torsion`` for soft fingers."""
    return (*CONTACT_QUANTITIES, TORSION) if torsion else CONTACT_QUANTITIES

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
        torsion: Soft fingers: torque the fingertip exerts on the object about each
            contact normal, shape (n,), N·m; None for point contacts.

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
    torsion: np.ndarray | None = None

    @classmethod
    def from_grasp_state(cls, state: GraspState, force: np.ndarray) -> ContactData:
        """Take the contact part of a grasp state, with the contact wrench ``force``.

        ``force``: the 3n contact forces, or a soft finger's 4n entries (the forces, then
        the n torsions).

        Raises:
            ValueError: ``force`` has neither 3n nor 4n entries.
        """
        n = state.n_contacts
        wrench = np.asarray(force, dtype=np.float64).reshape(-1)
        if wrench.size not in (3 * n, 4 * n):
            raise ValueError(
                f'contacts: expected a contact wrench of {3 * n} entries ({n} contacts) or '
                f'{4 * n} (soft fingers), got {wrench.size}'
            )
        forces = wrench[: 3 * n].reshape(n, 3)
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
            torsion=np.array(wrench[3 * n :]) if wrench.size == 4 * n else None,
        )

    def _columns(self) -> tuple[np.ndarray, np.ndarray]:
        """Values and rates, shape (n, len(contact_quantities(...))), in publishing order."""
        n = np.asarray(self.psi).shape[0]
        zeros = np.zeros(n)
        # Soft fingers: one more column, the torsion, whose rate is not published (0).
        torsion_value = () if self.torsion is None else (self.torsion,)
        torsion_rate = () if self.torsion is None else (zeros,)
        values = np.column_stack(
            (
                self.xi_cf,
                self.xi_co,
                self.psi,
                self.force,
                self.required_friction,
                self.penetration,
                *torsion_value,
            )
        )
        rates = np.column_stack(
            (
                self.xi_cf_dot,
                self.xi_co_dot,
                self.psi_dot,
                zeros,
                zeros,
                zeros,
                zeros,
                zeros,
                *torsion_rate,
            )
        )
        return values, rates


def contact_entry_names(contact_names: Sequence[str], torsion: bool = False) -> list[str]:
    """Names of ``/hand/contacts`` entries: ``"<contact>/<quantity>"``, contact-major.

    ``torsion``: soft fingers (each contact's ``torsion`` entry after its ten others).
    """
    return list(_entry_names(tuple(contact_names), torsion))


@lru_cache(maxsize=64)
def _entry_names(contact_names: tuple[str, ...], torsion: bool = False) -> tuple[str, ...]:
    """:func:`contact_entry_names` of a name tuple, built once per tuple."""
    return tuple(f'{c}/{q}' for c in contact_names for q in contact_quantities(torsion))


@lru_cache(maxsize=64)
def _has_torsion(entry_names: tuple[str, ...]) -> bool:
    """Whether any received entry is a torsion (the soft-finger layout)."""
    suffix = f'/{TORSION}'
    return any(name.endswith(suffix) for name in entry_names)


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
    c/required_friction, c/penetration``, and with soft fingers (``data.torsion`` not None)
    an eleventh, ``c/torsion``;

    - ``position`` holds the value: ``a, b`` fingertip surface coordinates (rad), ``u, v``
      object surface coordinates (m on a face), ``psi`` (rad), ``force_*`` the contact
      force on the object in the contact frame (N), ``required_friction`` ``|f_t|/f_n``
      (``+inf`` when the contact separates), ``penetration`` (m), ``torsion`` the torque
      the fingertip exerts on the object about the contact normal (N·m);
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
    torsion = data.torsion is not None
    if torsion:
        shapes['torsion'] = (n,)
    for name, shape in shapes.items():
        shaped_array(f'contacts {name}', getattr(data, name), shape)
    values, rates = data._columns()
    return joint_state_to_msg(
        msgs, data.t, _entry_names(names, torsion), values.ravel(), rates.ravel(), None
    )


def contacts_from_msg(
    msg: Any,
    contact_names: Sequence[str],
    source: str = 'contacts',
    torsion: bool | None = None,
) -> ContactData:
    """Parse a ``/hand/contacts`` message of exactly ``contact_names`` (any entry order).

    Args:
        msg: The message.
        contact_names: The contacts it must carry.
        source: The topic, for the errors.
        torsion: Whether every contact must have a ``torsion`` entry (soft fingers); None:
            the soft-finger layout if any entry is a torsion, else the point-contact one.

    Raises:
        MessageError: Duplicate, unknown or missing entries (so also a torsion for some
            contacts only); position or velocity lengths not matching the names; a
            non-finite value (``required_friction`` may be ``+inf``); a non-empty effort
            of the wrong length.

    """
    names = list(msg.name)
    if torsion is None:
        torsion = _has_torsion(tuple(map(str, names)))
    expected = contact_entry_names(contact_names, torsion)
    order = match_names(source, names, expected, 'contact entry')
    inf_ok = positive_inf_allowed(tuple(names))
    values = array_field(
        source, msg.position, 'position', names, required=True, allow_positive_inf=inf_ok
    )
    rates = array_field(source, msg.velocity, 'velocity', names, required=True)
    array_field(source, msg.effort, 'effort', names, required=False)
    n, k = len(contact_names), len(contact_quantities(torsion))
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
        torsion=values[:, 10] if torsion else None,
    )
