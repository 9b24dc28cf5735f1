"""The safety filter's published tick statuses, kept as columns while a bag streams.

A ``safety_filter`` status is some 25 text values; a long run publishes up to one per tick.
:class:`FilterStatusReader` keeps of each only what the summary reads (stamp, status,
tick count, the three times, relaxation), packed, plus the counts of the latest status
that carries them; :meth:`FilterStatusReader.finish` returns them as
:class:`FilterStatuses`, one per stamp (the last published of a stamp, as a re-sent tick
repeats its status), in stamp order.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
import math
from typing import Any

import numpy as np

from grasp_safety_filter.analysis.columns import Column
from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.messages import bounded_text, MessageError

#: The timing keys kept, in column order (µs; NaN where a status has none).
TIME_KEYS = (Key.SOLVE_TIME_US, Key.STEP_TIME_US, Key.TICK_TIME_US)


@dataclass(frozen=True)
class FilterStatuses:
    """The filter's tick statuses of a run, one per stamp, in stamp order (F of them).

    Attributes:
        t: Stamps, shape (F,), s.
        status: Each one's ``status`` text (:class:`~grasp_safety_filter.io.diagnostic_keys.
            TickStatus` values), length F.
        ticks: Its tick count so far (``ticks``), shape (F,); -1 where it has none.
        times_us: ``solve_time_us``, ``step_time_us``, ``tick_time_us``, shape (F, 3), µs;
            NaN where absent.
        relaxed: Whether the QP was relaxed, shape (F,).
        relaxed_families: Its comma-separated relaxed families, length F.
        enabled: Whether the filter was on (``filter.enabled``), shape (F,).
        counts: ``{status: ticks}`` of the latest status carrying counts (``count.<status>``),
            or None if none does (a bag of an older version).
    """

    t: np.ndarray = field(default_factory=lambda: np.zeros(0))
    status: tuple[str, ...] = ()
    ticks: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    times_us: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    relaxed: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    relaxed_families: tuple[str, ...] = ()
    enabled: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=bool))
    counts: dict[str, int] | None = None

    def __len__(self) -> int:
        """Return the number of statuses."""
        return len(self.t)


def _number(values: Mapping[str, str], key: str, kind: type) -> Any:
    """Return ``values[key]`` as ``kind`` (int or float).

    Raises:
        MessageError: It is not one (names the key and the text, bounded).

    """
    try:
        return kind(values[key])
    except ValueError:
        text = bounded_text(repr(values[key]), 80)
        raise MessageError(
            f"{FILTER_DIAGNOSTIC} status: '{key}' is not {kind.__name__}: {text}"
        ) from None


class FilterStatusReader:
    """Collects the filter's tick statuses from a bag in bag order (module docstring)."""

    def __init__(self) -> None:
        """Start empty."""
        # Texts repeat (a handful of statuses and family lists): kept once, as codes.
        self._texts: dict[str, int] = {}
        self._stamps = Column((), np.int64)
        self._status = Column((), np.int32)
        self._families = Column((), np.int32)
        self._ticks = Column((), np.int64)
        self._times = Column((len(TIME_KEYS),))
        self._flags = Column((2,), bool)  # relaxed, enabled
        self._counts: dict[str, int] | None = None
        self._counts_stamp: int | None = None

    def _code(self, text: str) -> int:
        return self._texts.setdefault(text, len(self._texts))

    def add(self, stamp_ns: int, values: Mapping[str, str]) -> None:
        """Add one status (its header stamp, ns, and its values).

        Raises:
            MessageError: A count or time that is not a number.

        """
        ticks = values.get(Key.TICKS)
        ticks_value = -1 if ticks is None else _number(values, Key.TICKS, int)
        times = [
            _number(values, key, float) if key in values else math.nan for key in TIME_KEYS
        ]
        self._stamps.append(stamp_ns)
        self._status.append(self._code(values.get(Key.STATUS, '')))
        self._families.append(self._code(values.get(Key.RELAXED_FAMILIES, '')))
        self._ticks.append(ticks_value)
        self._times.append(times)
        self._flags.append(
            (values.get(Key.RELAXED) == 'true', values.get(Key.FILTER_ENABLED) == 'true')
        )
        if ticks is not None and (self._counts_stamp is None or stamp_ns >= self._counts_stamp):
            self._counts_stamp = stamp_ns
            self._counts = {
                key.removeprefix(Key.COUNT_PREFIX): _number(values, key, int)
                for key in values
                if key.startswith(Key.COUNT_PREFIX)
            }

    def stamps(self) -> np.ndarray:
        """Return the stamps added so far, bag order, ns (a view)."""
        return self._stamps.array()

    def finish(self) -> FilterStatuses:
        """Return the statuses, the last of each stamp, in stamp order."""
        stamps = self._stamps.array()
        if not len(stamps):
            return FilterStatuses(counts=self._counts)
        # The last of each stamp: unique over the reversed order keeps first occurrences.
        reversed_stamps = stamps[::-1]
        unique, first = np.unique(reversed_stamps, return_index=True)
        keep = len(stamps) - 1 - first
        texts = list(self._texts)
        flags = self._flags.array()[keep]
        return FilterStatuses(
            t=unique.astype(float) * 1e-9,
            status=tuple(texts[c] for c in self._status.array()[keep]),
            ticks=self._ticks.array()[keep],
            times_us=self._times.array()[keep],
            relaxed=flags[:, 0],
            relaxed_families=tuple(texts[c] for c in self._families.array()[keep]),
            enabled=flags[:, 1],
            counts=self._counts,
        )
