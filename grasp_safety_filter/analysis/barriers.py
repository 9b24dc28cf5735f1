"""The filter's own barrier values over a run, from its compact ``/safety_filter/margins``.

The simulator's constraint families (:mod:`hand_sim_node.events`) judge the run; these are
what the filter saw: the smallest barrier value ``h`` of each of its row families
(``no_slip``, ``joint_limit``, ``fingertip_workspace``, ``actuator``: the first component
of the row names), in the rows' own units.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from grasp_safety_filter.io.margin_stream import MarginDecoder
from grasp_safety_filter.io.messages import MessageError


class BarrierReader:
    """Reads a margins stream in bag order and keeps each family's smallest ``h``.

    Attributes:
        messages: Margins messages read.
        malformed: Margins messages that could not be parsed (left out: the margins are
            the filter's report, the run's verdict does not depend on them).
        decoder: The stream's decoder (``skipped``: nameless messages before any names).

    """

    def __init__(self) -> None:
        """Start with no message read."""
        self.decoder = MarginDecoder()
        self.messages = 0
        self.malformed = 0
        self._min_h: dict[str, float] = {}
        self._groups: tuple[tuple[str, ...], dict[str, np.ndarray]] | None = None

    def _families(self, names: tuple[str, ...]) -> dict[str, np.ndarray]:
        """Row indices of each family of ``names`` (computed once per set of names)."""
        if self._groups is None or self._groups[0] != names:
            families: dict[str, list[int]] = {}
            for i, name in enumerate(names):
                families.setdefault(name.split('/', 1)[0], []).append(i)
            self._groups = (names, {f: np.array(rows) for f, rows in families.items()})
        return self._groups[1]

    def add(self, msg: Any, source: str) -> None:
        """Read one message (a malformed one is counted, not raised)."""
        try:
            data = self.decoder.decode(msg, source)
        except MessageError:
            self.malformed += 1
            return
        if data is None:
            return
        self.messages += 1
        for family, rows in self._families(data.names).items():
            smallest = float(data.h[rows].min()) if len(rows) else math.inf
            self._min_h[family] = min(self._min_h.get(family, math.inf), smallest)

    def summary(self) -> dict[str, Any]:
        """Return ``{"messages", "unreadable", "min_h": {family: h}}`` for ``summary.json``.

        ``unreadable``: nameless messages before any named the rows, and malformed ones.
        """
        return {
            'messages': self.messages,
            'unreadable': self.decoder.skipped + self.malformed,
            'min_h': dict(sorted(self._min_h.items())),
        }
