"""Finite but huge states on the paper's model: the filter falls back, never raises."""

from grasp_states import P_OBJECT_PAPER, paper_model, Q_PAPER
import numpy as np
import pytest

from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.safety_filter import (
    FilterStatus,
    SafetyFilter,
)

MODEL = paper_model()
M = MODEL.n_joints
FALLBACKS = {FilterStatus.FALLBACK_LAST_GOOD, FilterStatus.FALLBACK_NOMINAL}

#: name: (q, dq, object position, object twist) changed from the paper's grasp at rest.
HUGE = {
    'dq 1e154': {'dq': np.full(M, 1e154)},
    'dq -1e200': {'dq': np.full(M, -1e200)},
    'dq 1e300 on one joint': {'dq': np.eye(M)[4] * 1e300},
    'dq max float': {'dq': np.full(M, np.finfo(float).max)},
    'object at 1e300': {'p': np.array([1e300, 0.0, 0.0])},
    'object at -1e200 on every axis': {'p': np.full(3, -1e200)},
    'object twist 1e300': {'twist': np.full(6, 1e300)},
    'object spin 1e160': {'twist': np.array([0.0, 0.0, 0.0, 0.0, 0.0, 1e160])},
    'q 1e300': {'q': np.full(M, 1e300)},
    'everything huge': {
        'q': np.full(M, 1e300),
        'dq': np.full(M, 1e300),
        'p': np.full(3, 1e300),
        'twist': np.full(6, 1e300),
    },
}


def huge_state(change: dict):
    with np.errstate(all='ignore'):  # the model's terms overflow: that is the point
        return MODEL.state(
            0.0,
            change.get('q', Q_PAPER),
            change.get('dq', np.zeros(M)),
            change.get('p', P_OBJECT_PAPER),
            np.eye(3),
            change.get('twist', np.zeros(6)),
        )


@pytest.mark.parametrize('u_scale', [0.0, 1e3])
@pytest.mark.parametrize('name', list(HUGE))
def test_a_huge_finite_state_gives_a_finite_torque_in_the_box_and_a_fallback(name, u_scale):
    filter_ = SafetyFilter.from_config(MODEL, PAPER_CONFIG)
    u_nom = np.random.default_rng(1).normal(scale=u_scale, size=M)
    with np.errstate(all='raise'):  # no warning escapes the filter either
        result = filter_.solve(huge_state(HUGE[name]), u_nom)
    assert result.status is FilterStatus.FALLBACK_NOMINAL
    assert np.array_equal(result.u, filter_.actuator_limits.clip(u_nom))
    assert np.isfinite(result.u).all()
    assert (result.u >= filter_.actuator_limits.lower).all()
    assert (result.u <= filter_.actuator_limits.upper).all()
    assert result.relaxed and result.relaxed_families


@pytest.mark.parametrize('name', list(HUGE))
def test_after_a_good_tick_a_huge_state_holds_the_last_torque(name):
    filter_ = SafetyFilter.from_config(MODEL, PAPER_CONFIG)
    good = filter_.solve(huge_state({}), np.zeros(M))
    assert good.status not in FALLBACKS
    result = filter_.solve(huge_state(HUGE[name]), np.full(M, 1e3))
    assert result.status is FilterStatus.FALLBACK_LAST_GOOD
    assert np.array_equal(result.u, good.u)
    # and the next sane tick is solved again
    assert filter_.solve(huge_state({}), np.zeros(M)).status not in FALLBACKS
