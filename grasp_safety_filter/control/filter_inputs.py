"""The safety filter's input checks: a bad u_nom or measured state is named before any QP."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from grasp_safety_filter.control.row_checks import all_finite
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.grasp_state import GraspState

#: The measured :class:`GraspState` fields (the arguments of ``GraspModel.state``); every
#: other field is a model term derived from them.
MEASURED_STATE_FIELDS: tuple[str, ...] = (
    'q',
    'dq',
    'p_object_in_palm',
    'R_object_to_palm',
    'twist_object',
)


_NO_VALUES = np.zeros(0)


def checked_torque(u_nom: object, joint_names: Sequence[str]) -> np.ndarray:
    """Return u_nom as a new float array of shape (m,), finite.

    Raises:
        ValueError: Not numbers, the wrong shape or a non-finite entry (naming its joint).
    """
    m = len(joint_names)
    try:
        u = np.array(u_nom, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f'u_nom: expected {m} numbers, got {u_nom!r}') from None
    if u.shape != (m,):
        raise ValueError(f'u_nom: expected shape ({m},), got {u.shape}')
    if not all_finite(u, _NO_VALUES):  # compiled: np.isfinite(u).all() costs ~2 µs a tick
        bad = np.flatnonzero(~np.isfinite(u))
        raise ValueError(f'u_nom: non-finite value {u[bad[0]]} for joint {joint_names[bad[0]]!r}')
    return u


def raise_if_measured_not_finite(state: GraspState) -> None:
    """Raise ValueError naming the first non-finite entry of a measured field, if any."""
    for name in MEASURED_STATE_FIELDS:
        value = getattr(state, name)
        arrays = (
            ((f'{name}.matrix', value.matrix), (f'{name}.offset', value.offset))
            if isinstance(value, AffineMap)
            else ((name, value),)
        )
        for label, array in arrays:
            bad = np.argwhere(~np.isfinite(np.asarray(array, dtype=float)))
            if bad.size:
                index = tuple(int(i) for i in bad[0])
                raise ValueError(
                    f'state.{label}: non-finite value {array[index]} at index '
                    f'{index[0] if len(index) == 1 else index}'
                )
