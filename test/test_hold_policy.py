"""The input hold policy: ok -> holding -> fallback -> ok."""

from __future__ import annotations

import math

import numpy as np
import pytest

from grasp_safety_filter.control.hold_policy import (
    Fallback,
    HoldPolicy,
    InputMode,
    InputPolicyConfig,
)
from grasp_safety_filter.io.diagnostic_keys import Key
from grasp_safety_filter.io.messages import DiagnosticLevel
from grasp_safety_filter.io.schemas import NODE_SCHEMAS, SAFETY_FILTER_NODE

M = 9
SAFE = np.linspace(-1.0, 1.0, M)
GRAVITY = np.linspace(0.5, 4.5, M)


def policy(fallback: Fallback = Fallback.ZERO, **kwargs) -> HoldPolicy:
    return HoldPolicy(M, hold_timeout=0.125, fallback=fallback, **kwargs)  # binary exact


def test_accepted_input_passes_the_command_through():
    p = policy()
    u = p.accept(0.0, SAFE)
    np.testing.assert_array_equal(u, SAFE)
    assert p.mode is InputMode.OK
    assert p.diagnostic_level is DiagnosticLevel.OK
    assert p.rejected_ticks == 0


@pytest.mark.parametrize('fallback', list(Fallback))
def test_rejection_holds_the_last_safe_command_until_the_timeout_then_falls_back(fallback):
    p = policy(fallback)
    p.accept(1.0, SAFE)
    for t in (1.01, 1.0625, 1.125):  # up to and including the timeout
        np.testing.assert_array_equal(p.reject(t, 'stale', GRAVITY), SAFE)
        assert p.mode is InputMode.HOLDING
        assert p.diagnostic_level is DiagnosticLevel.WARN
    expected = np.zeros(M) if fallback is Fallback.ZERO else GRAVITY
    for t in (1.1251, 5.0):
        np.testing.assert_array_equal(p.reject(t, 'stale', GRAVITY), expected)
        assert p.mode is InputMode.FALLBACK
        assert p.diagnostic_level is DiagnosticLevel.ERROR
    assert p.rejected_ticks == 5
    assert p.last_reason == 'stale'


def test_good_input_resumes_from_fallback_and_restarts_the_hold():
    p = policy()
    p.accept(0.0, SAFE)
    p.reject(0.5, 'nan')
    assert p.mode is InputMode.FALLBACK
    resumed = 2.0 * SAFE
    np.testing.assert_array_equal(p.accept(0.6, resumed), resumed)
    assert p.mode is InputMode.OK
    np.testing.assert_array_equal(p.reject(0.65, 'missing joint'), resumed)
    assert p.mode is InputMode.HOLDING


def test_rejection_before_any_safe_command_falls_back_at_once():
    p = policy(Fallback.GRAVITY_COMPENSATION)
    np.testing.assert_array_equal(p.reject(0.0, 'no state yet', GRAVITY), GRAVITY)
    assert p.mode is InputMode.FALLBACK


def test_held_command_is_a_copy():
    p = policy()
    p.accept(0.0, SAFE)
    held = p.reject(0.01, 'x')
    held[:] = 100.0
    np.testing.assert_array_equal(p.reject(0.02, 'x'), SAFE)


def test_gravity_fallback_is_clipped_to_the_actuator_limits():
    u_max = np.full(M, 2.0)
    p = policy(Fallback.GRAVITY_COMPENSATION, u_min=-u_max, u_max=u_max)
    np.testing.assert_array_equal(p.reject(0.0, 'x', GRAVITY), np.minimum(GRAVITY, 2.0))


def test_gravity_fallback_needs_the_gravity_torque():
    p = policy(Fallback.GRAVITY_COMPENSATION)
    with pytest.raises(ValueError, match='gravity_torque'):
        p.reject(0.0, 'x')
    with pytest.raises(ValueError, match='gravity_torque'):
        p.reject(0.0, 'x', np.full(M, math.nan))


@pytest.mark.parametrize('command', [np.zeros(M - 1), np.full(M, math.nan), np.full(M, math.inf)])
def test_a_bad_command_is_never_remembered_as_safe(command):
    p = policy()
    p.accept(0.0, SAFE)
    with pytest.raises(ValueError, match='command'):
        p.accept(0.01, command)
    np.testing.assert_array_equal(p.reject(0.02, 'x'), SAFE)


def test_diagnostic_values_report_mode_reason_and_age():
    p = policy()
    p.accept(1.0, SAFE)
    p.reject(1.04, '/object/odom: stale stamp')
    values = p.diagnostic_values(1.04)
    assert values['input.mode'] == 'holding'
    assert values['input.last_rejection'] == '/object/odom: stale stamp'
    assert values['input.rejected_ticks'] == 1
    assert values['input.fallback'] == 'zero'
    assert values['input.time_since_accepted'] == pytest.approx(0.04)


@pytest.mark.parametrize('fallback', list(Fallback))
def test_absent_input_holds_then_falls_back_on_the_callers_clock_without_a_rejection(fallback):
    u_max = np.full(M, 2.0)
    p = policy(fallback, u_min=-u_max, u_max=u_max)
    p.accept(7.0, SAFE)  # node clock: its time does not matter to absent()
    np.testing.assert_array_equal(p.absent(0.125, 'nothing on /hand/joint_states', GRAVITY), SAFE)
    assert p.mode is InputMode.HOLDING
    expected = np.zeros(M) if fallback is Fallback.ZERO else np.minimum(GRAVITY, 2.0)
    for elapsed in (0.1251, 3.0):
        u = p.absent(elapsed, 'nothing on /hand/joint_states for 3 s', GRAVITY)
        np.testing.assert_array_equal(u, expected)
        assert p.mode is InputMode.FALLBACK
        assert p.diagnostic_level is DiagnosticLevel.ERROR
    assert p.rejected_ticks == 0
    assert p.last_reason == 'nothing on /hand/joint_states for 3 s'
    # Before any safe command there is nothing to hold.
    fresh = policy(fallback)
    unclipped = np.zeros(M) if fallback is Fallback.ZERO else GRAVITY
    np.testing.assert_array_equal(fresh.absent(0.0, 'x', GRAVITY), unclipped)
    assert fresh.mode is InputMode.FALLBACK


def test_diagnostic_values_use_the_shared_keys():
    p = policy()
    assert set(p.diagnostic_values(0.0)) == {
        Key.INPUT_MODE,
        Key.INPUT_FALLBACK,
        Key.INPUT_REJECTED_TICKS,
        Key.INPUT_LAST_REJECTION,
        Key.INPUT_TIME_SINCE_ACCEPTED,
    }
    assert all(key.startswith('input.') for key in p.diagnostic_values(0.0))


def test_config_reads_the_safety_filter_schema_defaults():
    schema = NODE_SCHEMAS[SAFETY_FILTER_NODE]
    values = {spec.name: spec.default for spec in schema.parameters}
    config = InputPolicyConfig.from_parameters(values)
    assert config.max_age == values['input.max_age']
    assert config.hold_timeout == values['input.hold_timeout']
    assert config.fallback.value == values['input.fallback']
    p = HoldPolicy.from_config(config, M)
    assert p.hold_timeout == config.hold_timeout


@pytest.mark.parametrize(
    ('values', 'match'),
    [
        ({'input.max_age': 0.0}, 'input.max_age'),
        ({'input.hold_timeout': -1.0}, 'input.hold_timeout'),
        ({'input.hold_timeout': math.inf}, 'input.hold_timeout'),
        ({'input.fallback': 'brake'}, 'input.fallback'),
    ],
)
def test_config_rejects_bad_values_naming_the_parameter(values, match):
    good = {'input.max_age': 0.05, 'input.hold_timeout': 0.1, 'input.fallback': 'zero'}
    with pytest.raises(ValueError, match=match):
        InputPolicyConfig.from_parameters({**good, **values})


def test_config_names_missing_parameters():
    with pytest.raises(KeyError, match=r'input\.fallback'):
        InputPolicyConfig.from_parameters({'input.max_age': 0.05, 'input.hold_timeout': 0.1})
