"""A filter step's margins and active rows: computed only when read, equal to the eager values."""

import dataclasses
from dataclasses import replace

import numpy as np
import pytest
from synthetic_state import synthetic_state, SyntheticHand

from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.filter_result import ResultAssembler
from grasp_safety_filter.control.qp_solvers import BACKENDS
from grasp_safety_filter.control.safety_filter import (
    ACTIVE_TOLERANCE,
    SafetyFilter,
)

HAND = SyntheticHand()
M = HAND.n_joints
TICKS = 25
CONFIGS = {
    'paper': PAPER_CONFIG,
    'torque_rate': replace(PAPER_CONFIG, torque_rate_enabled=True, torque_rate_max_step=0.5),
}


class Calls:
    """Counts the calls of the margin writer and the box writer of every ResultAssembler."""

    def __init__(self, monkeypatch):
        self.margins = 0
        self.box = 0
        write_margins = ResultAssembler._write_margins
        write_box = ResultAssembler._write_box

        def counted_margins(assembler, *args):
            self.margins += 1
            return write_margins(assembler, *args)

        def counted_box(assembler, *args):
            self.box += 1
            return write_box(assembler, *args)

        monkeypatch.setattr(ResultAssembler, '_write_margins', counted_margins)
        monkeypatch.setattr(ResultAssembler, '_write_box', counted_box)


def ticks(seed):
    """Return states and nominal torques of a run: calm ticks and ones the rows clip."""
    rng = np.random.default_rng(seed)
    return [
        (synthetic_state(rng, HAND), rng.normal(scale=(0.5, 5.0, 50.0)[i % 3], size=M))
        for i in range(TICKS)
    ]


def eager_values(filter_, state, u, rows, previous):
    """Margins and active rows at u from the tick's rows and the families, read now."""
    margins = {}
    for family in filter_.families:
        if family is filter_.torque_rate:
            h = np.zeros(2 * M)
            if previous is not None:
                step = filter_.config.torque_rate_max_step
                h[0::2] = u - (previous - step)
                h[1::2] = (previous + step) - u
        else:
            h = family.values(state, u).h
        margins.update(zip(family.names, h.tolist(), strict=True))
    box = filter_.actuator_limits.values(None, u)
    margins.update(zip(box.names, box.h.tolist(), strict=True))
    slack = [*(rows.A @ u - rows.lower).tolist(), *box.h.tolist()]
    names = (*rows.names, *box.names)
    active = tuple(n for n, s in zip(names, slack, strict=True) if s <= ACTIVE_TOLERANCE)
    return margins, active


@pytest.mark.parametrize('solver', sorted(BACKENDS))
@pytest.mark.parametrize('name', sorted(CONFIGS))
def test_margins_and_active_rows_are_computed_on_read_and_equal_the_eager_values(
    monkeypatch, name, solver
):
    config = dataclasses.replace(CONFIGS[name], solver=solver)
    calls = Calls(monkeypatch)
    unread = SafetyFilter.from_config(HAND, config)
    read = SafetyFilter.from_config(HAND, config)
    run = ticks(17)
    late = [unread.solve(state, u_nom) for state, u_nom in run]
    assert (calls.margins, calls.box) == (0, 0)  # a whole run with nothing read

    previous = None
    statuses = set()
    for (state, u_nom), later in zip(run, late, strict=True):
        rows = read.constraint_rows(state)  # the rows solve() writes (u_prev not yet moved)
        now = read.solve(state, u_nom)
        before = (calls.margins, calls.box)
        margins, active = now.margins, now.active
        assert (calls.margins, calls.box) == (before[0] + 1, before[1] + 2)
        assert now.margins is margins and now.active is active  # kept, not recomputed
        assert (calls.margins, calls.box) == (before[0] + 1, before[1] + 2)
        # Read at once, read after the whole run, recomputed independently: the same.
        assert np.array_equal(later.u, now.u)
        assert later.margins.names == margins.names
        assert later.margins.array.tobytes() == margins.array.tobytes()
        assert later.active == active
        expected_margins, expected_active = eager_values(read, state, now.u, rows, previous)
        for row, h in expected_margins.items():
            if row.startswith('torque_rate/'):  # an independent formula: to rounding
                assert margins[row] == pytest.approx(h, rel=0, abs=1e-12), row
            else:  # the families' own values: exactly
                assert margins[row] == h, row
        assert tuple(margins) == tuple(expected_margins)
        assert active == expected_active
        statuses.add(now.status)
        previous = now.u if now.status not in ('fallback_last_good', 'fallback_nominal') else None
    assert {'solved', 'relaxed'} <= statuses, statuses  # optimal and relaxed u* both seen
