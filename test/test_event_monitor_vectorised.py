"""The vectorised constraint monitor against a per-row evaluation of the same definitions.

A plain loop over contacts, joints and bounds (the definitions in
hand_sim_node/constraint_margins.py's docstring, written out) is the oracle; random instants
with margins on both sides of every bound, margins exactly at a bound, and unknown or
separating contact forces must give the same margins, the same events in the same order, and
the same run record.
"""

import math

import numpy as np
import pytest

from hand_sim_node.constraint_margins import (
    Event,
    FAMILIES,
    FINGERTIP_WORKSPACE,
    JOINT_LIMITS,
    OBJECT_FACE,
    SEPARATION,
    SLIP,
)
from hand_sim_node.event_log import EventLog
from hand_sim_node.events import EventMonitor

WORKSPACE = (-0.6, 0.6, -2.5, -0.6)
MU = 0.9


def reference_margins(lower, upper, t, q, xi_cf, forces, half_widths, xi_co):
    """Margins row by row: (workspace rows, joint rows, beta, mu - beta, f_n, face)."""
    a_min, a_max, b_min, b_max = WORKSPACE
    workspace = [[a - a_min, a_max - a, b - b_min, b_max - b] for a, b in xi_cf]
    joints = [[q_j - lo, hi - q_j] for q_j, lo, hi in zip(q, lower, upper, strict=True)]
    beta = []
    for f_x, f_y, f_n in forces:
        if not math.isfinite(f_n):
            beta.append(math.nan)  # unknown force
        elif f_n > 0.0:
            beta.append(float(np.hypot(f_x, f_y)) / f_n)  # numpy's hypot: same rounding
        else:
            beta.append(math.inf)
    friction = [MU - b for b in beta]
    normal = [f[2] for f in forces]
    face = [
        min(h_u - abs(u), h_v - abs(v))
        for (h_u, h_v), (u, v) in zip(half_widths, xi_co, strict=True)
    ]
    return workspace, joints, beta, friction, normal, face


def reference_events(t, joint_names, contact_names, margins):
    """Violated rows, family by family: workspace and separation at <= 0, the others < 0."""
    workspace, joints, _, friction, normal, face = margins
    events = []
    for i, row in enumerate(workspace):
        for side, value in zip(('a_min', 'a_max', 'b_min', 'b_max'), row, strict=True):
            if value <= 0.0:
                events.append(Event(t, FINGERTIP_WORKSPACE, i, contact_names[i], side, value))
    for j, row in enumerate(joints):
        for side, value in zip(('lower', 'upper'), row, strict=True):
            if value < 0.0:
                events.append(Event(t, JOINT_LIMITS, j, joint_names[j], side, value))
    for i, value in enumerate(friction):
        if value < 0.0:
            events.append(Event(t, SLIP, i, contact_names[i], '', value))
    for i, value in enumerate(normal):
        if value <= 0.0:
            events.append(Event(t, SEPARATION, i, contact_names[i], '', value))
    for i, value in enumerate(face):
        if value < 0.0:
            events.append(Event(t, OBJECT_FACE, i, contact_names[i], '', value))
    return events


class ReferenceLog:
    """The run record kept row by row."""

    def __init__(self):
        self.count = dict.fromkeys(FAMILIES, 0)
        self.first_t = dict.fromkeys(FAMILIES)
        self.minimum = dict.fromkeys(FAMILIES, math.inf)
        self.max_beta = 0.0
        self.onsets = []
        self.active = set()

    def record(self, t, margins, events):
        workspace, joints, beta, friction, normal, face = margins
        rows = {
            OBJECT_FACE: face,
            FINGERTIP_WORKSPACE: [v for row in workspace for v in row],
            JOINT_LIMITS: [v for row in joints for v in row],
            SLIP: friction,
            SEPARATION: normal,
        }
        for family, values in rows.items():
            for value in values:
                if not math.isnan(value):
                    self.minimum[family] = min(self.minimum[family], value)
        for value in beta:
            if not math.isnan(value):
                self.max_beta = max(self.max_beta, value)
        for family in {event.family for event in events}:
            self.count[family] += 1
            if self.first_t[family] is None:
                self.first_t[family] = t
        keys = [(e.family, e.index, e.side) for e in events]
        self.onsets += [e for e, key in zip(events, keys, strict=True) if key not in self.active]
        self.active = set(keys)


def random_instant(rng, n, m, lower, upper, half_widths):
    """Joint angles, contact coordinates and forces around every bound, with special values."""
    a_min, a_max, b_min, b_max = WORKSPACE
    q = rng.uniform(lower - 0.1, upper + 0.1)
    xi = np.column_stack(
        (rng.uniform(a_min - 0.1, a_max + 0.1, n), rng.uniform(b_min - 0.1, b_max + 0.1, n))
    )
    forces = rng.normal(0.0, 1.0, (n, 3))
    forces[:, 2] = np.abs(forces[:, 2]) * rng.choice([1.0, -1.0], n, p=[0.8, 0.2])
    finite = np.where(np.isfinite(half_widths), half_widths, 0.05)
    xi_co = rng.uniform(-1.1, 1.1, (n, 2)) * finite
    # Exactly at a bound: a workspace margin 0 is violated, a joint or face margin 0 is not.
    if rng.random() < 0.3:
        xi[rng.integers(n), 0] = a_max
        j = rng.integers(m)
        q[j] = upper[j]
        i = rng.integers(n)
        xi_co[i, 1] = -finite[i, 1]
        xi_co[i, 0] = 0.0
    special = rng.random()
    if special < 0.15:
        forces[rng.integers(n)] = np.nan  # the dynamics could not be evaluated
    elif special < 0.25:
        forces[rng.integers(n), 2] = 0.0  # touching without force
    elif special < 0.3:
        forces[rng.integers(n), 2] = np.inf
    elif special < 0.35:
        forces[rng.integers(n), 0] = np.inf
    return q, xi, forces, xi_co


@pytest.mark.parametrize(
    'n, m, seed',
    [(3, 9, 0), (3, 9, 1), (4, 16, 2), (1, 3, 3), (5, 15, 4)],
    ids=['paper-a', 'paper-b', 'four-fingers', 'one-finger', 'five-fingers'],
)
def test_vectorised_monitor_equals_the_per_row_definitions(n, m, seed):
    rng = np.random.default_rng(seed)
    lower = rng.uniform(-1.5, -0.1, m)
    upper = lower + rng.uniform(0.5, 2.0, m)
    joint_names = [f'joint_{j}' for j in range(m)]
    contact_names = [f'finger_{i}' for i in range(n)]
    # Box faces of random extents; the last contact on a sphere (no edge) when n > 1.
    half_widths = rng.uniform(0.01, 0.1, (n, 2))
    if n > 1:
        half_widths[-1] = np.inf
    monitor = EventMonitor(lower, upper, WORKSPACE, MU, joint_names, contact_names, half_widths)
    log, reference = EventLog(), ReferenceLog()
    seen = set()
    for k in range(200):
        t = 0.001 * k
        q, xi, forces, xi_co = random_instant(rng, n, m, lower, upper, half_widths)
        margins = monitor.margins_at(t, q, xi, forces.ravel(), xi_co)
        expected = reference_margins(lower, upper, t, q, xi, forces, half_widths, xi_co)
        np.testing.assert_array_equal(margins.fingertip_workspace, expected[0])
        np.testing.assert_array_equal(margins.joint_limits, expected[1])
        np.testing.assert_array_equal(margins.required_friction, expected[2])
        np.testing.assert_array_equal(margins.friction, expected[3])
        np.testing.assert_array_equal(margins.normal_force, expected[4])
        np.testing.assert_array_equal(margins.object_face, expected[5])
        events = monitor.events(margins)
        expected_events = reference_events(t, joint_names, contact_names, expected)
        assert list(events) == expected_events
        violated = margins.violated()
        for family, values in margins.by_family().items():
            assert violated[family].shape == values.shape
        assert sum(int(mask.sum()) for mask in violated.values()) == len(events)
        seen |= {event.family for event in events}
        log.record(margins, events)
        reference.record(t, expected, expected_events)
    assert seen == set(FAMILIES)  # the table exercised every family
    assert log.violations() == {
        family: {'count': reference.count[family], 'first_t': reference.first_t[family]}
        for family in FAMILIES
    }
    assert log.min_margin() == {
        FINGERTIP_WORKSPACE: reference.minimum[FINGERTIP_WORKSPACE],
        JOINT_LIMITS: reference.minimum[JOINT_LIMITS],
        'friction': reference.minimum[SLIP],
    }
    assert log.max_required_friction == reference.max_beta
    assert log.onsets == reference.onsets
    assert log.n_evaluations == 200


def test_margins_at_a_bound_unknown_forces_and_a_log_given_other_events():
    monitor = EventMonitor([-1.0, -1.0, -1.0], [1.0, 1.0, 1.0], WORKSPACE, MU, 'abc', ['f'])
    # a at a_max exactly (violated: the workspace is open), q at its upper limit (allowed),
    # an unknown force (flags neither slip nor separation).
    margins = monitor.margins_at(0.5, [1.0, 0.0, 0.0], [[0.6, -1.0]], [np.nan] * 3)
    events = monitor.events(margins)
    assert [(e.family, e.side, e.margin) for e in events] == [(FINGERTIP_WORKSPACE, 'a_max', 0.0)]
    assert np.isnan(margins.required_friction[0]) and np.isnan(margins.friction[0])
    log = EventLog()
    with pytest.raises(ValueError, match='expected the 1 events of the margins, got 0'):
        log.record(margins, ())
    log.record(margins, events)
    assert log.min_margin()['friction'] == math.inf  # unknown, not a violation
    assert log.max_required_friction == 0.0
    # Without the object coordinates or the faces, the object-face margins are unknown.
    assert np.isnan(margins.object_face[0])
    assert log.violations()[OBJECT_FACE] == {'count': 0, 'first_t': None}


def test_a_contact_off_its_face_is_an_event_and_a_sphere_has_no_edge():
    monitor = EventMonitor(
        [-1.0] * 3, [1.0] * 3, WORKSPACE, MU, 'abc', ['f', 'g'], [[0.1, 0.2], [np.inf, np.inf]]
    )
    forces = [0.0, 0.0, 1.0] * 2
    margins = monitor.margins_at(
        0.0, [0.0] * 3, [[0.0, -1.0]] * 2, forces, [[0.05, -0.2], [9.0, 9.0]]
    )
    assert monitor.events(margins) == ()  # on the edge of f's face: still on it
    assert margins.object_face.tolist() == [0.0, math.inf]
    margins = monitor.margins_at(
        0.0, [0.0] * 3, [[0.0, -1.0]] * 2, forces, [[0.05, -0.25], [9.0, 9.0]]
    )
    events = monitor.events(margins)
    assert [(e.family, e.name) for e in events] == [(OBJECT_FACE, 'f')]
    assert events[0].margin == pytest.approx(-0.05)
