"""The simulator's hardware mode at endpoint level (no ROS): a hand's driver and a tracker.

:class:`hand_sim_node.hardware.HardwareEndpoint` is called as the node calls it: ``tick`` at
the driver's period on a steady clock (with jitter, late calls), stamps from another clock of
today's epoch, commands in between. What is measured: a state every period with or without
commands, the plant frozen until the first command, zero-order hold, the command timeout and
its safe torque (against Pinocchio's g(q) computed here), an arm's joints, commands as
``Float64MultiArray`` in a permuted order, invalid commands refused (and fuzzed), the
tracker's rate, latency and noise statistics, the ground truth, catch-up after late calls,
on the rigid plant and on MuJoCo.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
import re

import numpy as np
import pinocchio as pin
import pytest
from rosbags.typesys import get_typestore, Stores
from test_endpoint_fuzz import mutate

from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import Pose, ReferenceSample
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.messages import DiagnosticLevel
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.io.sim_diagnostic_keys import HardwareKey, SimKey
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.outgoing import Outgoing
from hand_sim_node.config import SimConfig
from hand_sim_node.hardware import HardwareEndpoint, MAX_CATCH_UP_PERIODS
from hand_sim_node.hardware_config import HardwareConfig
from hand_sim_node.plant import PlantConfig
from hand_sim_node.start_up import GraphSnapshot, SIMULATOR_TOPICS, start_blockers

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = m.MessageNamespace.from_typestore(TYPESTORE)

#: The stamp clock's origin: today's epoch, integer ns (a float in s resolves it to ~0.24 us).
EPOCH_NS = 1_764_900_000_123_456_789
#: The steady clock's origin, ns (any).
STEADY_NS = 7_000_000_000


@pytest.fixture(scope='module')
def params():
    return load_node_parameters(CONFIG, 'hand_sim_node', overrides={'lockstep': False})


@pytest.fixture(scope='module')
def model(params):
    return GraspModel.from_parameters(params)


@pytest.fixture(scope='module')
def hold(params, model):
    """Return the nominal controller's torque at the initial grasp, N·m (a real command)."""
    sim = make(params, model)
    state = sim.plant.observe()
    values = load_node_parameters(CONFIG, 'nominal_controller_node')
    reference = ReferenceSample(Pose(state.p_object_in_palm, state.R_object_to_palm).euler)
    return (
        NominalController(NominalConfig.from_parameters(values))
        .compute(sim.plant.grasp_state(), reference)
        .u
    )


@pytest.fixture(scope='module')
def push(hold):
    """Return the holding torque plus 0.1 N·m on every joint: a command that moves the grasp."""
    return hold + 0.1


def make(params, model, overrides=None, plant='rigid', **sim) -> HardwareEndpoint:
    """Return an endpoint of the paper's scenario with ``hardware.*``, ``tracker.*`` overrides."""
    values = {**params, **(overrides or {}), **{k: v for k, v in sim.items() if k == 'time_step'}}
    sim_config = dataclasses.replace(SimConfig.from_parameters(values), **sim)
    return HardwareEndpoint(
        model,
        sim_config,
        HardwareConfig.from_parameters(values),
        MSGS,
        plant_config=PlantConfig(plant),
    )


class Clock:
    """Drives an endpoint as the node's timer does; logs every message with its call."""

    def __init__(self, sim: HardwareEndpoint) -> None:
        self.sim = sim
        self.k = 0
        self.log: list[tuple[int, Outgoing]] = [(0, o) for o in sim.start(STEADY_NS, EPOCH_NS)]

    def now(self, k: int, offset: int = 0) -> int:
        return STEADY_NS + k * self.sim.period_ns + offset

    def tick(self, n: int = 1, offset: int = 0) -> list[Outgoing]:
        """Call ``tick`` at the next ``n`` periods (``offset`` ns off each); return the last."""
        out: list[Outgoing] = []
        for _ in range(n):
            self.k += 1
            now = self.now(self.k, offset)
            out = self.sim.tick(now, EPOCH_NS + now - STEADY_NS)
            self.log += [(self.k, o) for o in out]
        return out

    def command(self, msg) -> list[Outgoing]:
        now = self.now(self.k, 1)
        out = self.sim.on_command(msg, now, EPOCH_NS + now - STEADY_NS)
        self.log += [(self.k, o) for o in out]
        return out

    def messages(self, topic: str, since: int = 0) -> list:
        return [o.msg for k, o in self.log if o.topic == topic and k >= since]


def of(outgoing, topic):
    return [o.msg for o in outgoing if o.topic == topic]


def reports(outgoing):
    return [
        r for msg in of(outgoing, topics.DIAGNOSTICS) for r in m.diagnostics_from_msg(msg).reports
    ]


def joint_efforts(msgs, model):
    return [m.joint_state_from_msg(msg, model.joint_names, others=True).effort for msg in msgs]


def command_msg(model, effort, stamp=0.0):
    return m.effort_to_msg(MSGS, stamp, model.joint_names, np.asarray(effort, dtype=float))


# ----------------------------------------------------------------------------------------
# The driver's periods


@pytest.mark.parametrize(
    ('rate', 'time_step', 'substeps'),
    [(1000.0, 0.001, 1), (500.0, 0.001, 2), (1000.0 / 3, 0.001, 3), (200.0, 0.0025, 2)],
)
def test_a_state_every_period_without_any_command(params, model, rate, time_step, substeps):
    sim = make(params, model, {'hardware.rate': rate}, time_step=time_step, duration=1.0)
    assert sim.substeps == substeps
    assert sim.period_ns == round(substeps * time_step * 1e9)
    clock = Clock(sim)
    rng = np.random.default_rng(1)
    stamps = [m.header_stamp_ns(of([o for _, o in clock.log], topics.JOINT_STATES)[0])]
    for k in range(1, 121):
        # The timer fires up to 0.9 periods after its instant (never before); the stamp
        # clock reads its own time.
        now = clock.now(k, int(rng.uniform(0.0, 0.9) * sim.period_ns))
        stamp = EPOCH_NS + now - STEADY_NS + int(rng.integers(0, 1000))
        out = sim.tick(now, stamp)
        (state,) = of(out, topics.JOINT_STATES)
        (truth,) = of(out, topics.OBJECT_TRUE_ODOM)
        assert m.header_stamp_ns(state) == m.header_stamp_ns(truth) == stamp
        stamps.append(stamp)
    assert all(isinstance(s, int) for s in stamps)
    assert np.all(np.diff(stamps) > 0)
    assert sim.counts.periods == 121 and sim.counts.late == sim.counts.skipped == 0
    assert sim.plant.step_index == 0  # no command: nothing integrated


def test_stamps_stay_strictly_increasing_when_the_clock_steps_back(params, model):
    sim = make(params, model)
    sim.start(STEADY_NS, EPOCH_NS)
    stamps = []
    for k, stamp in enumerate([EPOCH_NS + 10, EPOCH_NS + 5, EPOCH_NS + 5, EPOCH_NS + 20], 1):
        (state,) = of(sim.tick(STEADY_NS + k * sim.period_ns, stamp), topics.JOINT_STATES)
        stamps.append(m.header_stamp_ns(state))
    assert stamps == [EPOCH_NS + 10, EPOCH_NS + 11, EPOCH_NS + 12, EPOCH_NS + 20]


def test_late_calls_catch_up_a_few_periods_and_skip_the_rest(params, model, hold):
    # 2 steps per period; no command timeout within the test.
    sim = make(params, model, {'hardware.rate': 500.0, 'hardware.command_timeout': 10.0})
    clock = Clock(sim)
    clock.command(command_msg(model, hold))
    clock.tick()
    assert sim.plant.step_index == 2
    assert sim.tick(clock.now(1, 1000)) == []  # the same period again: nothing due
    assert sim.tick(clock.now(2, -1)) == []  # 1 ns before period 2: not due yet
    # Less than a period late: its period alone, not counted late.
    assert of(sim.tick(clock.now(2, int(0.95 * sim.period_ns))), topics.JOINT_STATES)
    assert sim.counts.late == 0 and sim.plant.step_index == 4
    out = sim.tick(clock.now(5))  # 3 periods due: one state, 3 periods integrated
    assert len(of(out, topics.JOINT_STATES)) == 1
    assert sim.plant.step_index == 10 and sim.counts.late == 2 and sim.counts.skipped == 0
    out = sim.tick(clock.now(20))  # 15 due: MAX_CATCH_UP_PERIODS integrated, the rest lost
    assert sim.plant.step_index == 10 + 2 * MAX_CATCH_UP_PERIODS
    assert sim.counts.late == 2 + MAX_CATCH_UP_PERIODS - 1
    assert sim.counts.skipped == 15 - MAX_CATCH_UP_PERIODS
    assert sim.t == pytest.approx(sim.plant.step_index * 0.001, abs=1e-12)
    # The regular status (every second) says so.
    (status,) = reports(sim.tick(clock.now(500)))
    assert status.level is DiagnosticLevel.WARN and 'late' in status.message
    assert int(status.values[HardwareKey.PERIODS_SKIPPED]) == 15 - 4 + 480 - 4
    assert int(status.values[HardwareKey.PERIODS_LATE]) == 2 + 3 + 3


# ----------------------------------------------------------------------------------------
# Release, hold, duration


@pytest.mark.parametrize('plant', ['rigid', 'mujoco'])
def test_the_plant_stands_still_until_the_first_command_then_moves(params, model, push, plant):
    sim = make(params, model, plant=plant)
    initial = sim.plant.observe()
    clock = Clock(sim)
    clock.tick(30)
    for msg in clock.messages(topics.JOINT_STATES):
        state = m.joint_state_from_msg(msg, model.joint_names)
        np.testing.assert_array_equal(state.position, initial.q)
        np.testing.assert_array_equal(state.velocity, 0.0)
        np.testing.assert_array_equal(state.effort, 0.0)
    for msg in clock.messages(topics.OBJECT_TRUE_ODOM):
        truth = m.odometry_from_msg(msg, model.palm_frame, model.object_frame)
        np.testing.assert_array_equal(truth.p_object_in_palm, initial.p_object_in_palm)
    assert sim.plant.step_index == 0 and not clock.messages(topics.CONTACTS)
    assert not sim.released
    (released,) = reports(clock.command(command_msg(model, push)))
    assert released.level is DiagnosticLevel.OK and 'released' in released.message
    clock.tick(5)
    assert sim.plant.step_index == 5 and sim.t == pytest.approx(0.005, abs=1e-12)
    assert len(clock.messages(topics.CONTACTS, since=31)) == 5
    state = sim.plant.observe()
    assert np.max(np.abs(state.q - initial.q)) > 1e-6
    assert np.max(np.abs(state.dq)) > 1e-4
    # The ground truth is the plant's state, stamped as the joint state.
    truth_msg = clock.messages(topics.OBJECT_TRUE_ODOM)[-1]
    truth = m.odometry_from_msg(truth_msg, model.palm_frame, model.object_frame)
    assert truth.stamp_ns == m.header_stamp_ns(clock.messages(topics.JOINT_STATES)[-1])
    np.testing.assert_array_equal(truth.p_object_in_palm, state.p_object_in_palm)
    np.testing.assert_allclose(truth.R_object_to_palm, state.R_object_to_palm, atol=1e-12)
    np.testing.assert_allclose(truth.twist_object, state.twist_object, atol=1e-12)
    assert np.max(np.abs(state.twist_object)) > 1e-5  # a twist that says something


def test_the_run_lasts_duration_from_the_release(params, model, hold):
    sim = make(params, model, duration=0.02)
    clock = Clock(sim)
    clock.tick(50)  # before the release: no simulated time passes
    clock.command(command_msg(model, hold))
    clock.tick(19)
    assert not sim.finished
    out = clock.tick()
    assert sim.finished and sim.stop_reason == 'duration'
    (end,) = [r for r in reports(out) if SimKey.RUN_FINISHED in r.values]
    assert end.values[SimKey.RUN_STOP_REASON] == 'duration'
    assert float(end.values[SimKey.RUN_T_END]) == pytest.approx(0.02, abs=1e-12)
    assert int(end.values[SimKey.RUN_STEPS]) == 20
    assert end.values[HardwareKey.COMMANDS_RECEIVED] == '1'
    assert clock.tick() == [] and sim.on_command(command_msg(model, hold), clock.now(99)) == []


def test_the_last_command_is_held_until_the_next(params, model, hold):
    sim = make(params, model, {'hardware.rate': 500.0})
    reference = make(params, GraspModel.from_parameters(params), {'hardware.rate': 500.0}).plant
    clock = Clock(sim)
    u1, u2 = hold, hold + 0.05
    clock.command(command_msg(model, u1))
    clock.tick(3)
    clock.command(command_msg(model, u2))
    clock.tick(2)
    efforts = joint_efforts(clock.messages(topics.JOINT_STATES, since=1), model)
    for effort, expected in zip(efforts, [u1, u1, u1, u2, u2], strict=True):
        np.testing.assert_array_equal(effort, expected)
    for u in [u1] * 6 + [u2] * 4:  # 2 steps per period
        reference.step(u)
    np.testing.assert_array_equal(sim.plant.observe().q, reference.observe().q)


def test_a_command_over_the_effort_limits_is_clipped_with_one_warning(params, model, hold):
    sim = make(params, model)
    clock = Clock(sim)
    over = hold.copy()
    over[1] = 7.5  # the URDF's limit is 5 N·m
    warning, released = reports(clock.command(command_msg(model, over)))
    assert warning.level is DiagnosticLevel.WARN and 'clipped' in warning.message
    assert warning.values['effort.clipped'] == model.joint_names[1]
    assert released.level is DiagnosticLevel.OK
    clock.tick(3)
    assert not reports([o for k, o in clock.log if k > 0])  # not repeated every period
    (effort,) = joint_efforts(clock.messages(topics.JOINT_STATES)[-1:], model)
    assert effort[1] == 5.0


# ----------------------------------------------------------------------------------------
# Command timeout


def gravity_torque(model, q):
    """g(q) by Pinocchio directly (its joint order mapped by name), N·m."""
    pin_model = model.hand.model
    data = pin_model.createData()
    q_pin = pin.neutral(pin_model)
    for name, value in zip(model.joint_names, q, strict=True):
        q_pin[pin_model.joints[pin_model.getJointId(name)].idx_q] = value
    g = pin.computeGeneralizedGravity(pin_model, data, q_pin)
    return np.array(
        [g[pin_model.joints[pin_model.getJointId(name)].idx_v] for name in model.joint_names]
    )


@pytest.mark.parametrize('kind', ['gravity_compensation', 'zero'])
def test_a_command_timeout_applies_the_safe_torque_and_reports_it(params, model, hold, kind):
    sim = make(params, model, {'hardware.command_timeout': 0.01, 'hardware.timeout_torque': kind})
    clock = Clock(sim)
    clock.tick(975)  # frozen, no command: no timeout either
    assert not [r for _, o in clock.log for r in reports([o]) if r.level != DiagnosticLevel.OK]
    clock.command(command_msg(model, hold))
    clock.tick(10)  # 10 ms - 1 ns after the command: not yet
    assert not sim.timed_out
    before = sim.plant.observe().q
    out = clock.tick()  # 11 ms - 1 ns > 10 ms
    (error,) = reports(out)
    assert error.level is DiagnosticLevel.ERROR
    assert 'no valid command for 0.011 s' in error.message and kind in error.message
    assert error.values[HardwareKey.COMMAND_TIMED_OUT] == 'true'
    expected = gravity_torque(model, before) if kind == 'gravity_compensation' else 0.0
    (effort,) = joint_efforts(of(out, topics.JOINT_STATES), model)
    np.testing.assert_allclose(effort, expected, rtol=0, atol=1e-12)
    if kind == 'gravity_compensation':
        assert np.max(np.abs(effort)) > 0.1  # N·m: a torque that holds the fingers up
        np.testing.assert_allclose(
            effort, model.hand.terms(np.array(before), np.zeros(9)).gravity_torque, atol=1e-12
        )
    # Per period, at the plant's q of its start; the regular status (1 s) is an ERROR.
    for _ in range(14):
        before = sim.plant.observe().q
        out = clock.tick()
        (effort,) = joint_efforts(of(out, topics.JOINT_STATES), model)
        expected = gravity_torque(model, before) if kind == 'gravity_compensation' else 0.0
        np.testing.assert_allclose(effort, expected, rtol=0, atol=1e-12)
    assert np.max(np.abs(sim.plant.observe().q - before)) > 0.0  # q moved: g(q) followed it
    (regular,) = reports(out)
    assert regular.level is DiagnosticLevel.ERROR
    assert 'no valid command for 0.025 s' in regular.message
    assert float(regular.values[HardwareKey.COMMAND_AGE]) == pytest.approx(0.025, abs=1e-6)
    # Commands again: an OK status, the command applied from the next period.
    (resumed,) = reports(clock.command(command_msg(model, hold)))
    assert resumed.level is DiagnosticLevel.OK and 'resumed after 0.025 s' in resumed.message
    assert not sim.timed_out and sim.counts.timeouts == 1
    (effort,) = joint_efforts(of(clock.tick(), topics.JOINT_STATES), model)
    np.testing.assert_array_equal(effort, hold)


# ----------------------------------------------------------------------------------------
# The joint states and the command forms


@pytest.mark.parametrize('extra', [0, 1, 7])
def test_an_arms_joints_come_first_in_the_joint_states(params, model, extra):
    sim = make(params, model, {'hardware.extra_joints': extra})
    (msg,) = of(sim.start(STEADY_NS, EPOCH_NS), topics.JOINT_STATES)
    arm = [f'arm_joint_{k}' for k in range(1, extra + 1)]
    assert list(msg.name) == arm + model.joint_names
    np.testing.assert_array_equal(msg.position[:extra], np.linspace(-0.3, 0.3, extra))
    np.testing.assert_array_equal(msg.velocity[:extra], 0.0)
    state = m.joint_state_from_msg(msg, model.joint_names, others=True)
    np.testing.assert_array_equal(state.position, sim.plant.observe().q)


@pytest.mark.parametrize('order', ['model', 'permuted'])
def test_float64_multi_array_commands_go_to_their_joints(params, model, order):
    names = list(model.joint_names)
    perm = np.random.default_rng(5).permutation(len(names)) if order == 'permuted' else None
    joints = ['model.joint_names'] if perm is None else [names[i] for i in perm]
    overrides = {
        'hardware.command_message': 'float64_multi_array',
        'hardware.command_joints': joints,
    }
    sim = make(params, model, overrides)
    u = 0.1 * np.arange(1, len(names) + 1)  # a distinct torque per joint, N·m
    index = np.arange(len(names)) if perm is None else perm
    clock = Clock(sim)
    assert sim.commands.topic == topics.EFFORT_CONTROLLER_COMMANDS
    clock.command(m.effort_array_to_msg(MSGS, index, u))  # data[i] = u[index[i]]
    (effort,) = joint_efforts(of(clock.tick(), topics.JOINT_STATES), model)
    np.testing.assert_array_equal(effort, u)


def _replace_name(model, u):
    names = ['elbow', *model.joint_names[1:]]
    return m.effort_to_msg(MSGS, 0.0, names, u)


@pytest.mark.parametrize(
    ('form', 'build', 'problem'),
    [
        ('joint_state', lambda model, u: command_msg(model, np.r_[np.nan, u[1:]]), 'is nan'),
        (
            'joint_state',
            lambda model, u: m.effort_to_msg(MSGS, 0.0, model.joint_names[:-1], u[:-1]),
            'missing joint names',
        ),
        ('joint_state', _replace_name, "unknown joint names ['elbow']"),
        (
            'float64_multi_array',
            lambda model, u: m.effort_array_to_msg(MSGS, np.arange(8), u[:8]),
            "'data' has 8 entries",
        ),
        (
            'float64_multi_array',
            lambda model, u: m.effort_array_to_msg(MSGS, np.arange(9), np.r_[u[:8], np.inf]),
            'is inf',
        ),
    ],
)
def test_an_invalid_command_is_refused_and_the_last_valid_one_kept(
    params, model, hold, form, build, problem
):
    sim = make(params, model, {'hardware.command_message': form})
    clock = Clock(sim)
    valid = (
        command_msg(model, hold)
        if form == 'joint_state'
        else m.effort_array_to_msg(MSGS, np.arange(9), hold)
    )
    clock.command(valid)
    clock.tick(2)
    (warning,) = reports(clock.command(build(model, hold + 1.0)))
    assert warning.level is DiagnosticLevel.WARN
    assert warning.message.startswith('command refused') and problem in warning.message
    assert sim.counts.refused == 1 and sim.counts.received == 1
    for effort in joint_efforts(of(clock.tick(3), topics.JOINT_STATES), model):
        np.testing.assert_array_equal(effort, hold)


@pytest.mark.parametrize('sec', [-(2**31), -1, 0, 2**31 - 1])
def test_a_joint_state_command_is_taken_whatever_its_stamp(params, model, hold, sec):
    sim = make(params, model)
    clock = Clock(sim)
    msg = command_msg(model, hold)
    msg.header.stamp.sec = sec
    assert [r.level for r in reports(clock.command(msg))] == [DiagnosticLevel.OK]
    (effort,) = joint_efforts(of(clock.tick(), topics.JOINT_STATES), model)
    np.testing.assert_array_equal(effort, hold)


def test_commands_before_the_start_are_ignored_with_a_warning(params, model, hold):
    sim = make(params, model)
    (warning,) = reports(sim.on_command(command_msg(model, hold), STEADY_NS))
    assert warning.level is DiagnosticLevel.WARN and 'before the start' in warning.message
    assert not sim.released


def valid_effort(form: str, msg, names: list[str]) -> np.ndarray | None:
    """Oracle: a command's torques in model order (N·m), or None if a driver must refuse it."""
    if form == 'float64_multi_array':
        data = np.asarray(msg.data, dtype=float)
        return data if data.shape == (len(names),) and np.all(np.isfinite(data)) else None
    received = list(msg.name)
    if sorted(received) != sorted(names):
        return None
    for field in ('position', 'velocity'):
        values = np.asarray(getattr(msg, field), dtype=float)
        if values.size not in (0, len(received)) or not np.all(np.isfinite(values)):
            return None
    effort = np.asarray(msg.effort, dtype=float)
    if effort.shape != (len(received),) or not np.all(np.isfinite(effort)):
        return None
    return effort[[received.index(name) for name in names]]


@pytest.mark.parametrize('form', ['joint_state', 'float64_multi_array'])
def test_no_mutated_command_crashes_the_driver_or_reaches_the_hand(params, model, hold, form):
    overrides = {'hardware.command_message': form, 'hardware.command_timeout': 10.0}
    sim = make(params, model, overrides)
    rng = np.random.default_rng(11)
    names = list(model.joint_names)
    valid = (
        command_msg(model, hold)
        if form == 'joint_state'
        else m.effort_array_to_msg(MSGS, np.arange(9), hold)
    )
    clock = Clock(sim)
    clock.command(valid)
    limits = np.asarray(model.effort_limits)
    applied, sent, refused = hold, 0, 0
    for _ in range(200):
        bad = mutate(rng, valid, names)
        if bad is None:  # a value the wire cannot carry
            continue
        sent += 1
        expected = valid_effort(form, bad, names)
        out = clock.command(bad)
        if expected is None:
            refused += 1
            assert any('refused' in r.message for r in reports(out))
        else:
            applied = np.clip(expected, -limits, limits)
        assert sim.counts.refused == refused
        (effort,) = joint_efforts(of(clock.tick(), topics.JOINT_STATES), model)
        np.testing.assert_array_equal(effort, applied)
    assert sent > 100 and 0.1 * sent < refused < 0.9 * sent, (sent, refused)


# ----------------------------------------------------------------------------------------
# The tracker


@pytest.mark.parametrize(
    ('driver_rate', 'tracker_rate', 'latency'),
    [(1000.0, 100.0, 0.01), (1000.0, 30.0, 0.0125), (500.0, 240.0, 0.035), (500.0, 500.0, 0.0)],
)
def test_tracker_samples_at_its_rate_each_published_latency_after_capture(
    params, model, driver_rate, tracker_rate, latency
):
    overrides = {
        'hardware.rate': driver_rate,
        'tracker.rate': tracker_rate,
        'tracker.latency': latency,
    }
    sim = make(params, model, overrides)
    clock = Clock(sim)
    seconds = 2.0
    clock.tick(round(seconds * driver_rate))
    period_ns = sim.period_ns
    published = [(k, o) for k, o in clock.log if o.topic == topics.OBJECT_ODOM]
    # Samples at its rate: one per 1/rate s (the last ones still in the queue).
    assert abs(len(published) + sim.tracker.pending - tracker_rate * seconds) <= 1
    assert sim.tracker.published == len(published)
    captures = [o.stamp_ns for _, o in published]
    spacing = np.diff(captures)
    assert np.all(np.abs(spacing - 1e9 / tracker_rate) <= period_ns)
    # Each one published at the first driver period at or after capture + latency.
    state_stamps = {k: o.stamp_ns for k, o in clock.log if o.topic == topics.JOINT_STATES}
    delays = np.array([state_stamps[k] - o.stamp_ns for k, o in published])
    assert np.all(delays >= round(latency * 1e9))
    assert np.all(delays < round(latency * 1e9) + period_ns)
    # ... stamped with its capture time, a state's stamp.
    assert set(captures) <= set(state_stamps.values())


@pytest.mark.parametrize(
    ('position_noise', 'orientation_noise'), [(0.0005, 0.005), (0.002, 0.0), (0.0, 0.02)]
)
def test_tracker_noise_has_the_configured_standard_deviation(
    params, model, position_noise, orientation_noise
):
    overrides = {
        'tracker.rate': 1000.0,
        'tracker.latency': 0.0,
        'tracker.position_noise': position_noise,
        'tracker.orientation_noise': orientation_noise,
        'tracker.seed': 3,
    }
    sim = make(params, model, overrides)
    truth = sim.plant.observe()  # frozen: no command
    clock = Clock(sim)
    clock.tick(2000)
    samples = [
        m.odometry_from_msg(msg, model.palm_frame, model.object_frame)
        for msg in clock.messages(topics.OBJECT_ODOM)
    ]
    n = len(samples)
    assert n == 2001
    dp = np.array([s.p_object_in_palm - truth.p_object_in_palm for s in samples])
    dr = np.array([pin.log3(s.R_object_to_palm @ truth.R_object_to_palm.T) for s in samples])
    # The sample standard deviation of n normal draws is within 4 of its standard errors,
    # sigma / sqrt(2 (n - 1)), of sigma; the mean within 4 sigma / sqrt(n) of 0.
    for errors, sigma in ((dp, position_noise), (dr, orientation_noise)):
        if sigma == 0.0:
            np.testing.assert_allclose(errors, 0.0, atol=1e-9)
            continue
        std = errors.std(axis=0, ddof=1)
        assert np.all(np.abs(std / sigma - 1.0) < 4.0 / np.sqrt(2 * (n - 1))), std
        assert np.all(np.abs(errors.mean(axis=0)) < 4.0 * sigma / np.sqrt(n))
        # Independent axes.
        correlation = np.corrcoef(errors.T)[np.triu_indices(3, 1)]
        assert np.all(np.abs(correlation) < 4.0 / np.sqrt(n))


def test_tracker_noise_is_reproduced_by_its_seed(params, model):
    def first_positions(seed):
        sim = make(params, model, {'tracker.seed': seed, 'tracker.latency': 0.0})
        clock = Clock(sim)
        clock.tick(50)
        samples = clock.messages(topics.OBJECT_ODOM)
        return [m.odometry_from_msg(msg, model.palm_frame).p_object_in_palm for msg in samples]

    a, b, c = first_positions(3), first_positions(3), first_positions(4)
    np.testing.assert_array_equal(a, b)
    assert np.min(np.abs(np.array(a) - np.array(c))) > 0.0


@pytest.mark.parametrize('message', ['odometry', 'pose'])
def test_tracker_publishes_odometry_with_the_true_twist_or_a_pose(params, model, push, message):
    sim = make(params, model, {'tracker.message': message, 'tracker.latency': 0.0})
    clock = Clock(sim)
    clock.command(command_msg(model, push))
    clock.tick(30)
    topic = topics.OBJECT_ODOM if message == 'odometry' else topics.OBJECT_POSE
    other = topics.OBJECT_POSE if message == 'odometry' else topics.OBJECT_ODOM
    samples = clock.messages(topic)
    assert len(samples) == 4 and not clock.messages(other)  # 100 Hz: at 0, 10, 20, 30 ms
    truth = {m.header_stamp_ns(msg): msg for msg in clock.messages(topics.OBJECT_TRUE_ODOM)}
    for msg in samples:
        assert msg.header.frame_id == model.palm_frame
        exact = truth[m.header_stamp_ns(msg)]
        if message == 'pose':
            assert msg.__msgtype__ == 'geometry_msgs/msg/PoseStamped'
            sample = m.pose_stamped_from_msg(msg, model.palm_frame)
            assert sample.twist_object is None
        else:
            assert msg.child_frame_id == model.object_frame
            sample = m.odometry_from_msg(msg, model.palm_frame, model.object_frame)
            # The true twist in the true object frame, as in the ground truth.
            for field in ('linear', 'angular'):
                got, want = getattr(msg.twist.twist, field), getattr(exact.twist.twist, field)
                np.testing.assert_allclose(
                    [got.x, got.y, got.z], [want.x, want.y, want.z], rtol=0, atol=1e-12
                )
        true = m.odometry_from_msg(exact, model.palm_frame, model.object_frame)
        error = np.linalg.norm(sample.p_object_in_palm - true.p_object_in_palm)
        assert 0.0 < error < 6 * 0.0005 * np.sqrt(3)  # noisy, by about the noise
    last_msg = clock.messages(topics.OBJECT_TRUE_ODOM)[-1]
    last = m.odometry_from_msg(last_msg, model.palm_frame, model.object_frame)
    assert np.max(np.abs(last.twist_object)) > 1e-4  # the object moves: a twist to compare


# ----------------------------------------------------------------------------------------
# Parameters


@pytest.mark.parametrize(
    ('overrides', 'problem'),
    [
        ({'hardware.rate': 500.0}, None),
        ({'hardware.rate': 1000.0 / 3}, None),
        ({'hardware.rate': 1000.0 * (1 + 5e-10)}, None),
        ({'hardware.rate': 333.0}, "'hardware.rate' and 'time_step'"),
        ({'hardware.rate': 1000.0 * (1 + 1e-8)}, "'hardware.rate' and 'time_step'"),
        ({'hardware.rate': 2000.0}, "'hardware.rate' and 'time_step'"),
        ({'hardware.rate': 200.0, 'tracker.rate': 240.0}, "'tracker.rate' and 'hardware.rate'"),
        ({'hardware.command_joints': ['finger1_joint1']}, "'hardware.command_joints'"),
    ],
)
def test_hardware_parameters_are_checked_together_at_start_up(overrides, problem):
    # The lockstep mode does not read them: accepted whatever they are.
    lockstep = load_node_parameters(CONFIG, 'hand_sim_node', overrides={**overrides})
    hardware = {**overrides, 'lockstep': False}
    if problem is None:
        values = load_node_parameters(CONFIG, 'hand_sim_node', overrides=hardware)
        assert HardwareConfig.from_parameters(values).rate == values['hardware.rate']
        return
    with pytest.raises(ParameterError, match=re.escape(problem)):
        load_node_parameters(CONFIG, 'hand_sim_node', overrides=hardware)
    with pytest.raises(ParameterError, match=re.escape(problem)):
        HardwareConfig.from_parameters(lockstep)


def test_the_driver_waits_for_no_controller_only_for_a_recorder(params, model):
    published = make(params, model, {'tracker.message': 'pose'}).topics
    assert topics.CLOCK not in published and topics.OBJECT_ODOM not in published
    assert {topics.OBJECT_POSE, topics.OBJECT_TRUE_ODOM} <= set(published)
    assert set(published) <= SIMULATOR_TOPICS
    nobody = GraphSnapshot()
    assert start_blockers(nobody, '', published, controllers=False) == []
    assert f'a publisher on {topics.EFFORT_COMMAND}' in start_blockers(nobody)  # lockstep
    (blocker,) = start_blockers(nobody, 'rosbag2_recorder', published, controllers=False)
    in_table_order = [spec.name for spec in topics.TOPICS if spec.name in published]
    assert blocker == f"recorder 'rosbag2_recorder' subscribed to {', '.join(in_table_order)}"
    recorded = GraphSnapshot(subscribers={t: frozenset({'/rosbag2_recorder'}) for t in published})
    assert start_blockers(recorded, 'rosbag2_recorder', published, controllers=False) == []
