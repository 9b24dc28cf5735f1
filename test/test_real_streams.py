"""The controllers on a real hand's streams: a driver's rate and clock, a tracker's latency.

Endpoint level, in one process (:mod:`hand_streams`): joint states stamped on today's epoch
at the driver's rate, the object's pose from a tracker at its own rate, late and noisy,
joints of an arm in the joint states, ``input.sync: latest``. Also the other things a real
driver needs: integer-ns stamps end to end, no command before the first tick, commands in
ros2_control's ``Float64MultiArray`` form, and reports that name the remapped topics.
"""

from __future__ import annotations

import functools
from pathlib import Path

from hand_streams import EPOCH_NS, MSGS, run_streams, Streams, through_cdr
import numpy as np
import pytest

from grasp_safety_filter.control.hold_policy import InputPolicyConfig
from grasp_safety_filter.control.nominal import NominalConfig
from grasp_safety_filter.control.safety_filter import SafetyFilterConfig
from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.diagnostic_keys import Key, TickStatus
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.command_output import CommandConfig, CommandOutput
from grasp_safety_filter.nodes.grasp_watch import GraspCheckConfig
from grasp_safety_filter.nodes.nominal_controller import NominalControllerEndpoint
from grasp_safety_filter.nodes.object_stream import StreamConfig
from grasp_safety_filter.nodes.safety_filter import SafetyFilterEndpoint
from hand_sim_node.config import SimConfig
from hand_sim_node.plant import PlantConfig

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
LATEST = {'input.sync': 'latest'}

#: A tick's statuses when u* was computed (a QP, or u_nom that is already safe).
COMPUTED = {
    TickStatus.NOMINAL.value,
    TickStatus.SOLVED.value,
    TickStatus.RELAXED.value,
    TickStatus.DISABLED.value,
}


def node_values(node: str, **overrides: object) -> dict:
    return load_node_parameters(CONFIG, node, overrides=overrides or None)


def make_nominal(**overrides: object) -> NominalControllerEndpoint:
    values = node_values('nominal_controller_node', **overrides)
    return NominalControllerEndpoint(
        GraspModel.from_parameters(values),
        NominalConfig.from_parameters(values),
        MSGS,
        GraspCheckConfig.from_parameters(values),
        stream=StreamConfig.from_parameters(values),
    )


def make_filter(enabled: bool = True, **overrides: object) -> SafetyFilterEndpoint:
    values = node_values('safety_filter_node', **overrides)
    return SafetyFilterEndpoint(
        GraspModel.from_parameters(values),
        SafetyFilterConfig.from_parameters(values),
        InputPolicyConfig.from_parameters(values),
        MSGS,
        enabled=enabled,
        stream=StreamConfig.from_parameters(values),
        command_config=CommandConfig.from_parameters(values),
    )


def make_plant():
    values = node_values('hand_sim_node')
    model = GraspModel.from_parameters(values)
    return PlantConfig().build(model, SimConfig.from_parameters(values))


def stream_run(streams: Streams, duration: float, enabled: bool = True, tamper=None, **stream):
    overrides = {**LATEST, **stream}
    nominal = make_nominal(**overrides)
    safety_filter = make_filter(enabled, **overrides)
    return run_streams(make_plant(), nominal, safety_filter, streams, duration, tamper)


# ----------------------------------------------------------------------------------------
# Ticking on the driver's stream

STREAM_CASES = {
    # An Allegro-like driver at 333 Hz with a 30 Hz camera: tau longer for its noise.
    '333 Hz, 30 Hz pose, 33 ms, 1 mm': (
        Streams(
            period=0.003,
            tracker_period=0.033,
            latency=0.033,
            position_noise=0.001,
            orientation_noise=0.005,
            pose_message=True,
        ),
        {'input.object_message': 'pose', 'object_state.correction_time': 0.5},
    ),
    '500 Hz, 100 Hz odometry, 10 ms, 0.5 mm, arm joints': (
        Streams(period=0.002, extra_joints=('arm_joint_1', 'arm_joint_2', 'arm_joint_3')),
        {},
    ),
    '1 kHz, 100 Hz odometry, 10 ms, 0.5 mm': (Streams(period=0.001), {}),
}


@pytest.mark.parametrize('case', list(STREAM_CASES))
def test_the_filter_computes_u_star_for_every_joint_state_of_a_real_hands_streams(case):
    streams, stream = STREAM_CASES[case]
    run = stream_run(streams, 1.0, **stream)
    assert run.stop_reason is None
    # One command per joint state from the first on, stamped exactly as it (integer ns of
    # today's epoch: through float seconds most would be off by up to 0.12 us).
    stamps = [m.header_stamp_ns(msg) for msg in run.commands]
    first = run.states.index(stamps[0])
    assert stamps == run.states[first:]
    assert first * streams.period < streams.latency + 3 * streams.tracker_period
    nominal_stamps = [m.header_stamp_ns(msg) for msg in run.nominal]
    assert nominal_stamps == run.states[run.states.index(nominal_stamps[0]) :]
    ticks = [s for s in run.tick_statuses() if s != TickStatus.INPUT_IGNORED.value]
    assert len(ticks) == len(stamps)
    computed = sum(s in COMPUTED for s in ticks)
    assert computed / len(ticks) >= 0.99, sorted(set(ticks))


@pytest.mark.parametrize(('enabled', 'stop'), [(True, None), (False, 'fingertip_workspace')])
def test_the_papers_outcome_on_real_streams(enabled, stop):
    """Run the paper's runs with a 500 Hz driver and a 100 Hz tracker: filtered holds."""
    run = stream_run(Streams(period=0.002), 2.0, enabled=enabled)
    assert run.stop_reason == stop
    if stop is not None:  # the paper's nominal run leaves the workspace at 1.2 s
        t_end = (run.states[-1] - run.states[0]) / 1e9
        assert 1.0 < t_end < 1.6


# ----------------------------------------------------------------------------------------
# Which u_nom a tick takes


@functools.cache
def _initial_grasp() -> tuple[GraspModel, np.ndarray, np.ndarray, np.ndarray]:
    """Return the paper's model, and its initial q (rad), object position (m) and R."""
    values = node_values('hand_sim_node')
    config = SimConfig.from_parameters(values)
    x, y, z, w = config.initial_object_orientation
    R = m.matrix_from_quaternion_xyzw(np.array([x, y, z, w]))
    q = np.asarray(config.initial_joint_positions)
    return GraspModel.from_parameters(values), q, np.asarray(config.initial_object_position), R


def static_messages(k: int, offset_ns: int = 0):
    """Return the initial grasp at rest as sample k of a 1 kHz driver (joints, odometry)."""
    model, q, p, R = _initial_grasp()
    stamp = EPOCH_NS + k * 1_000_000 + offset_ns
    joints = m.joint_state_to_msg(MSGS, stamp, model.joint_names, q, np.zeros_like(q), None)
    odometry = m.odometry_to_msg(MSGS, stamp, p, R, np.zeros(6))
    return model, through_cdr(joints), through_cdr(odometry)


def nominal_msg(model, stamp: int, effort=None):
    u = np.zeros(model.n_joints) if effort is None else effort
    return through_cdr(m.effort_to_msg(MSGS, stamp, model.joint_names, u))


def command_stamps(outgoing) -> list[int]:
    return [o.stamp_ns for o in outgoing if o.topic == topics.EFFORT_COMMAND]


def now_of(k: int) -> float:
    return (EPOCH_NS + k * 1_000_000) / 1e9


def test_a_tick_waits_for_the_u_nom_stamped_as_its_state_and_drops_a_late_one():
    safety_filter = make_filter(**LATEST)
    model, joints0, odometry = static_messages(0)
    assert safety_filter.on_odom(odometry, now=now_of(0)) == []
    assert safety_filter.on_joint_states(joints0, now=now_of(0)) == []  # waits for its u_nom
    out = safety_filter.on_effort_nominal(nominal_msg(model, EPOCH_NS), now=now_of(0))
    assert command_stamps(out) == [EPOCH_NS]
    assert safety_filter.inputs.nominal_answers
    # Two states wait; the second's u_nom comes first: it is answered, the first's dropped.
    _, joints1, _ = static_messages(1)
    _, joints2, _ = static_messages(2)
    assert safety_filter.on_joint_states(joints1, now=now_of(1)) == []
    assert safety_filter.on_joint_states(joints2, now=now_of(2)) == []
    stamp1, stamp2 = EPOCH_NS + 1_000_000, EPOCH_NS + 2_000_000
    out = safety_filter.on_effort_nominal(nominal_msg(model, stamp2), now=now_of(2))
    assert command_stamps(out) == [stamp2]
    assert safety_filter.on_effort_nominal(nominal_msg(model, stamp1), now=now_of(2)) == []
    assert safety_filter.inputs.late_nominal == 1


def test_after_a_stall_a_stale_u_nom_is_dropped_and_the_queued_states_are_answered():
    """A node that stalled 60 ms: its queued u_nom is stale; the states after it still tick."""
    safety_filter = make_filter(**LATEST)
    model, joints0, odometry = static_messages(0)
    safety_filter.on_odom(odometry, now=now_of(0))
    safety_filter.on_joint_states(joints0, now=now_of(0))
    assert command_stamps(
        safety_filter.on_effort_nominal(nominal_msg(model, EPOCH_NS), now=now_of(0))
    ) == [EPOCH_NS]
    _, joints1, _ = static_messages(1)
    assert safety_filter.on_joint_states(joints1, now=now_of(1)) == []
    late = nominal_msg(model, EPOCH_NS + 1_000_000)
    assert safety_filter.on_effort_nominal(late, now=now_of(61)) == []
    assert safety_filter.inputs.late_nominal == 1
    _, joints2, _ = static_messages(62)
    stamp2 = EPOCH_NS + 62_000_000
    assert safety_filter.on_joint_states(joints2, now=now_of(62)) == []
    out = safety_filter.on_effort_nominal(nominal_msg(model, stamp2), now=now_of(62))
    assert command_stamps(out) == [stamp2]


def test_a_u_nom_that_arrives_before_its_state_is_paired_with_it():
    safety_filter = make_filter(**LATEST)
    model, joints0, odometry = static_messages(0)
    safety_filter.on_odom(odometry, now=now_of(0))
    assert safety_filter.on_effort_nominal(nominal_msg(model, EPOCH_NS), now=now_of(0)) == []
    assert command_stamps(safety_filter.on_joint_states(joints0, now=now_of(0))) == [EPOCH_NS]


def test_a_controller_with_its_own_stamps_gives_every_tick_its_newest_u_nom():
    """A user's controller at 250 Hz, stamping with its own clock, 0.3 ms off the driver's."""
    safety_filter = make_filter(**LATEST)
    model, _, odometry = static_messages(0)
    safety_filter.on_odom(odometry, now=now_of(0))
    answered = []
    for k in range(80):
        _, joints, _ = static_messages(k)
        if k % 4 == 0 and k < 20:  # then it stops
            u = nominal_msg(model, EPOCH_NS + k * 1_000_000 - 300_000)
            answered += command_stamps(safety_filter.on_effort_nominal(u, now=now_of(k)))
        out = safety_filter.on_joint_states(joints, now=now_of(k))
        answered += command_stamps(out)
    assert not safety_filter.inputs.nominal_answers
    # From the second state on, each state is a tick (the first waited for its own u_nom).
    assert answered[1:] == [EPOCH_NS + k * 1_000_000 for k in range(1, 80)]
    # u_nom older than input.max_age (50 ms) at the tick: rejected, the safe u* held.
    report = m.diagnostics_from_msg(through_cdr(out[-1].msg)).reports[0]
    assert report.values[Key.STATUS] == TickStatus.INPUT_HELD.value
    assert 'older than the state' in report.message


# ----------------------------------------------------------------------------------------
# Input the ticks go on without


def test_no_command_goes_out_before_the_first_tick():
    """Joint states before any object pose: rejected without a command, reported once a second."""
    safety_filter = make_filter(**LATEST)
    out = []
    for k in range(1500):
        _, joints, _ = static_messages(k)
        out += safety_filter.on_joint_states(joints, now=now_of(k))
    assert [o.topic for o in out] == [topics.DIAGNOSTICS, topics.DIAGNOSTICS]
    reports = [m.diagnostics_from_msg(through_cdr(o.msg)).reports[0] for o in out]
    assert all(r.values[Key.STATUS] == TickStatus.INPUT_IGNORED.value for r in reports)
    assert 'no object pose received yet' in reports[0].message
    assert reports[1].values[Key.INPUT_IGNORED] == '1001'


def nan_pose(topic, msg, k):
    if topic == topics.OBJECT_ODOM and 100 <= k < 200:
        msg.pose.pose.position.x = float('nan')
    return msg


def silent_tracker_after(k_stop):
    def tamper(topic, msg, k):
        return None if topic == topics.OBJECT_ODOM and k >= k_stop else msg

    return tamper


def test_a_bad_tracker_sample_is_reported_and_the_ticks_go_on():
    run = stream_run(Streams(period=0.002), 0.6, tamper=nan_pose)
    assert run.stop_reason is None
    stamps = [m.header_stamp_ns(msg) for msg in run.commands]
    assert stamps == run.states[run.states.index(stamps[0]) :]
    ignored = [
        r
        for r in run.statuses
        if r.values.get(Key.STATUS) == 'input_ignored'
        and r.values[Key.INPUT_TOPIC] == topics.OBJECT_ODOM
    ]
    # 10 bad samples in 0.2 s: reported once a second, with how many since.
    assert len(ignored) == 1
    assert 'pose.position must be finite, got [nan' in ignored[0].message
    ticks = [s for s in run.tick_statuses() if s != TickStatus.INPUT_IGNORED.value]
    assert all(s in COMPUTED for s in ticks)


def test_a_silent_tracker_stops_the_ticks_once_its_newest_pose_is_too_old():
    run = stream_run(
        Streams(period=0.002),
        0.8,
        tamper=silent_tracker_after(100),
        **{'object_state.max_age': 0.1},
    )
    statuses = run.tick_statuses()
    held = statuses.index(TickStatus.INPUT_HELD.value)
    assert all(s in COMPUTED for s in statuses[:held] if s != TickStatus.INPUT_IGNORED.value)
    # Last sample captured at 0.19 s (k = 95) is 0.1 s old at 0.29 s; held for 0.1 s.
    assert TickStatus.INPUT_FALLBACK.value in statuses[held:]
    stale = next(r for r in run.statuses if r.values.get(Key.STATUS) == 'input_held')
    assert 'the newest object pose is' in stale.message


# ----------------------------------------------------------------------------------------
# Drivers as they are: joints of an arm, ros2_control's command form


def test_joints_the_model_does_not_have_are_ignored_and_give_the_same_u_star():
    """Exact stamps (the lockstep graph) with and without an arm's joints in the state."""
    model, joints, odometry = static_messages(0)
    with_arm = m.joint_state_to_msg(
        MSGS,
        EPOCH_NS,
        ['arm_joint_1', *reversed(joints.name), 'arm_joint_2'],
        np.r_[0.5, joints.position[::-1], -0.5],
        np.r_[0.1, joints.velocity[::-1], 0.2],
        None,
    )
    u_nom = np.linspace(-0.2, 0.3, model.n_joints)
    answers = []
    for state in (joints, through_cdr(with_arm)):
        safety_filter = make_filter()
        safety_filter.on_odom(odometry, now=now_of(0))
        safety_filter.on_joint_states(state, now=now_of(0))
        out = safety_filter.on_effort_nominal(nominal_msg(model, EPOCH_NS, u_nom), now=now_of(0))
        (command,) = [o.msg for o in out if o.topic == topics.EFFORT_COMMAND]
        answers.append(m.effort_from_msg(command, model.joint_names).effort)
    np.testing.assert_array_equal(answers[0], answers[1])


def test_u_star_goes_to_a_ros2_control_effort_controller_in_its_joint_order():
    model, joints, odometry = static_messages(0)
    order = list(reversed(model.joint_names))
    safety_filter = make_filter(
        **{'command.message': 'float64_multi_array', 'command.joints': order}
    )
    safety_filter.on_odom(odometry, now=now_of(0))
    safety_filter.on_joint_states(joints, now=now_of(0))
    u_nom = np.linspace(-0.2, 0.3, model.n_joints)
    out = safety_filter.on_effort_nominal(nominal_msg(model, EPOCH_NS, u_nom), now=now_of(0))
    by_topic = {o.topic: through_cdr(o.msg) for o in out}
    u_star = m.effort_from_msg(by_topic[topics.EFFORT_COMMAND], model.joint_names).effort
    array = by_topic[topics.EFFORT_CONTROLLER_COMMANDS]
    assert list(array.data) == list(u_star[::-1])
    assert len(array.layout.dim) == 0


@pytest.mark.parametrize(
    ('joints', 'match'),
    [
        (['finger1_joint1'], 'model joints missing'),
        (['arm_joint_1', *[f'finger{i}_joint{j}' for i in (1, 2, 3) for j in (1, 2, 3)]], 'arm'),
    ],
)
def test_a_command_joint_order_must_name_every_model_joint_once(joints, match):
    model = GraspModel.from_parameters(node_values('safety_filter_node'))
    with pytest.raises(ConfigError, match=match):
        CommandOutput(MSGS, model.joint_names, CommandConfig('float64_multi_array', tuple(joints)))


# ----------------------------------------------------------------------------------------
# Stamps, and what the nodes say while they wait


def test_stamps_stay_integer_nanoseconds_where_float_seconds_would_not():
    stamps = EPOCH_NS + np.arange(1000)
    # Through float seconds most of today's stamps do not come back (the old path).
    assert sum(m.seconds_to_nanoseconds(int(s) / 1e9) != s for s in stamps) > 900
    for stamp in stamps[:50]:
        msg = through_cdr(m.effort_to_msg(MSGS, int(stamp), ['a'], np.zeros(1)))
        assert m.effort_from_msg(msg, ['a']).stamp_ns == stamp


def test_the_nominal_controller_says_what_it_waits_for_by_the_remapped_names():
    values = node_values('nominal_controller_node', **LATEST)
    names = {topics.JOINT_STATES: '/my_hand/joint_states', topics.OBJECT_ODOM: '/tracker/odom'}
    nominal = NominalControllerEndpoint(
        GraspModel.from_parameters(values),
        NominalConfig.from_parameters(values),
        MSGS,
        stream=StreamConfig.from_parameters(values),
        topic_names=names,
    )
    assert nominal.watchdog(0.0, now=now_of(0)) == []
    (first,) = nominal.watchdog(1.0, now=now_of(1000))
    report = m.diagnostics_from_msg(through_cdr(first.msg)).reports[0]
    assert report.message == (
        'waiting 1.0 s for a first tick, no command: nothing on /my_hand/joint_states, '
        '/tracker/odom'
    )
    _, joints, _ = static_messages(1500)
    (rejected,) = nominal.on_joint_states(joints, now=now_of(1500), wall=1.5)
    assert rejected.stamp_ns == EPOCH_NS + 1_500_000_000  # the state's own stamp
    reject_report = m.diagnostics_from_msg(through_cdr(rejected.msg)).reports[0]
    assert '/tracker/odom: no object pose received yet' in reject_report.message
    (second,) = nominal.watchdog(2.0, now=now_of(2000))
    report = m.diagnostics_from_msg(through_cdr(second.msg)).reports[0]
    assert report.message.endswith('nothing on /tracker/odom')


def test_the_filter_names_the_missing_u_nom_and_where_it_comes_from():
    values = node_values('safety_filter_node', **LATEST)
    safety_filter = SafetyFilterEndpoint(
        GraspModel.from_parameters(values),
        SafetyFilterConfig.from_parameters(values),
        InputPolicyConfig.from_parameters(values),
        MSGS,
        stream=StreamConfig.from_parameters(values),
        topic_names={topics.EFFORT_NOMINAL: '/my_controller/effort'},
    )
    _, joints, odometry = static_messages(0)
    assert safety_filter.watchdog(0.0, now=now_of(0)) == []
    safety_filter.on_odom(odometry, now=now_of(0), wall=0.5)
    safety_filter.on_joint_states(joints, now=now_of(0), wall=0.5)
    (waiting,) = safety_filter.watchdog(1.0, now=now_of(1000))
    report = m.diagnostics_from_msg(through_cdr(waiting.msg)).reports[0]
    assert report.message.startswith(
        'waiting 1.0 s for a first tick: nothing on /my_controller/effort (the nominal '
        'controller publishes u_nom only for the ticks it makes of its own inputs'
    )
