"""Input parses shared by in-process subscribers: one delivered message, parsed once.

In a ROS graph each node parses what it receives. In the ROS-free runner one deserialised
message goes to the nominal controller and to the safety filter, which parse
``/hand/joint_states`` and ``/object/odom`` the same way (same parser, joint names,
frames and source name, when their models agree): with a :class:`SharedParse` given to
both, the second subscriber gets the first one's result instead of a parse of its own.
A message that does not parse is parsed (and refused) by each.

The result is remembered for the last message of each parse, by identity: whoever shares
one must not change a message between its subscribers (the runner never does). Its arrays
are made read-only, so that no subscriber can change what another one reads.
"""

from __future__ import annotations

from collections.abc import Callable, Hashable
from typing import Any, TypeVar

import numpy as np

Parsed = TypeVar('Parsed')


def parse_directly(parser: Callable[..., Parsed], msg: Any, *args: Hashable) -> Parsed:
    """Parse ``msg`` with ``parser(msg, *args)``: a subscriber that shares no parse."""
    return parser(msg, *args)


class SharedParse:
    """``parser(msg, *args)``, computed once per message and ``(parser, args)`` (module doc)."""

    def __init__(self) -> None:
        self._last: dict[tuple[Hashable, ...], tuple[Any, Any]] = {}

    def __call__(self, parser: Callable[..., Parsed], msg: Any, *args: Hashable) -> Parsed:
        """Return ``parser(msg, *args)``; the same object for the same message and arguments.

        Raises:
            Whatever ``parser`` raises (nothing is remembered then).

        """
        key = (parser, *args)
        last = self._last.get(key)
        if last is not None and last[0] is msg:
            return last[1]
        result = parser(msg, *args)
        for value in vars(result).values():  # a parse's result: a dataclass of arrays
            if isinstance(value, np.ndarray):
                value.flags.writeable = False
        # The message is kept with its result: its id cannot be reused while remembered.
        self._last[key] = (msg, result)
        return result
