"""``/safety_filter/margins``: the barrier values of the filter's constraint rows."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.errors import MessageError
from grasp_safety_filter.io.messages.fields import (
    array_field,
    checked_names,
    match_names,
)
from grasp_safety_filter.io.messages.namespace import MessageNamespace
from grasp_safety_filter.io.messages.stamps import (
    header_msg,
    Stamp,
    time_from_msg,
)


@dataclass(frozen=True)
class MarginData:
    """Barrier values of the filter's constraint rows.

    Attributes:
        t: Stamp, s.
        names: Row names.
        h: Barrier values, shape (r,) (units of each row; >= 0 is safe).
        h_dot: Their time derivatives, shape (r,); NaN where the message carries none.

    """

    t: float
    names: tuple[str, ...]
    h: np.ndarray
    h_dot: np.ndarray


def margins_to_msg(
    msgs: MessageNamespace,
    t: Stamp,
    names: Sequence[str],
    h: np.ndarray,
    h_dot: np.ndarray | None = None,
    with_names: bool = True,
) -> Any:
    """``/safety_filter/margins``: JointState with position = h, velocity = dh/dt.

    The compact form (:mod:`grasp_safety_filter.io.margin_stream`): ``with_names=False``
    leaves ``name`` empty, the rows being those of the last message that named them.
    Without ``h_dot`` the velocity is empty (8 bytes per row and message, not 16); ``h_dot``
    entries that are NaN (not defined for that row) are sent as 0.0. Effort is empty.
    """
    position = msgs.float_array(h)
    if len(names) != len(position):
        raise ValueError(f'margins: {len(names)} names for {len(position)} values')
    if h_dot is None:
        velocity = msgs.empty_float_array()
    else:
        rates = np.asarray(h_dot, dtype=np.float64).ravel()
        if rates.size != len(position):
            raise ValueError(f'margins: {rates.size} rates for {len(position)} values')
        velocity = msgs.float_array(np.where(np.isnan(rates), 0.0, rates))
    return msgs.JointState(
        header=header_msg(msgs, t, ''),
        name=[str(n) for n in names] if with_names else [],
        position=position,
        velocity=velocity,
        effort=msgs.empty_float_array(),
    )


def margins_from_msg(
    msg: Any,
    names: Sequence[str] | None = None,
    source: str = 'margins',
    row_names: Sequence[str] | None = None,
) -> MarginData:
    """Parse margins; with ``names``, match them by name and return them in that order.

    Args:
        msg: The message.
        names: Return these rows, in this order (default: the message's order).
        source: Name used in error messages.
        row_names: The rows of a message without names (compact form): the names of the
            last message that had them. Ignored when the message names its rows.

    Raises:
        MessageError: Duplicate, unknown or missing names; lengths; non-finite values; a
            message without names and no ``row_names``.

    """
    if len(msg.name) == 0 and len(msg.position) > 0:
        if row_names is None:
            raise MessageError(
                f'{source}: {len(msg.position)} values without row names, and no earlier '
                'message named the rows'
            )
        received = list(row_names)
    else:
        received = checked_names(source, msg.name, 'margin')
    order = (
        np.arange(len(received))
        if names is None
        else match_names(source, received, names, 'margin')
    )
    h = array_field(source, msg.position, 'position', received, required=True)
    h_dot = array_field(source, msg.velocity, 'velocity', received, required=False)
    if h_dot is None:
        h_dot = np.full(len(received), np.nan)
    t = time_from_msg(msg.header.stamp, f'{source}: header.stamp')
    return MarginData(t=t, names=tuple(received[i] for i in order), h=h[order], h_dot=h_dot[order])
