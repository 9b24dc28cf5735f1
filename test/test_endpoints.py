"""Node endpoints: lockstep ticks through CDR, and every kind of bad input reported and held."""

from __future__ import annotations

from collections import Counter, deque
import dataclasses
import json
import math
from pathlib import Path
import re

from counting_filter import CountingFilter
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.control.filter_result import ResultAssembler
from grasp_safety_filter.control.hold_policy import InputPolicyConfig
from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import PaperReference, Pose, ReferenceSample
from grasp_safety_filter.control.safety_filter import (
    FilterStatus,
    SafetyFilter,
    SafetyFilterConfig,
)
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.diagnostic_keys import (
    FAILED_STATUSES,
    INPUT_STATUSES,
    Key,
    silent_for,
    TickStatus,
)
from grasp_safety_filter.io.messages import DiagnosticLevel, MessageNamespace, ObjectReference
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.input_watchdog import WAITING_REPORT_PERIOD, WATCHDOG_PERIOD
from grasp_safety_filter.nodes.nominal_controller import NominalControllerEndpoint
from grasp_safety_filter.nodes.outgoing import Outgoing
from grasp_safety_filter.nodes.publication_rate import PublicationRateConfig
from grasp_safety_filter.nodes.safety_filter import SafetyFilterEndpoint
from grasp_safety_filter.nodes.scenario import scenario_from_msg, scenario_from_text, ScenarioError
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint
from hand_sim_node.simulator import Simulator

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = MessageNamespace.from_typestore(TYPESTORE)
STEPS = 4


def through_cdr(msg):
    """Serialise to CDR and back, as the middleware (or a bag) does."""
    return TYPESTORE.deserialize_cdr(
        TYPESTORE.serialize_cdr(msg, msg.__msgtype__), msg.__msgtype__
    )


@pytest.fixture(scope='module')
def params():
    return {
        node: load_node_parameters(CONFIG, node)
        for node in ('hand_sim_node', 'nominal_controller_node', 'safety_filter_node')
    }


def sim_config(params, **overrides) -> SimConfig:
    config = SimConfig.from_parameters(params['hand_sim_node'])
    return dataclasses.replace(config, duration=STEPS * config.time_step, **overrides)


def make_sim(params, **overrides) -> HandSimEndpoint:
    model = GraspModel.from_parameters(params['hand_sim_node'])
    return HandSimEndpoint(model, sim_config(params, **overrides), MSGS)


def make_nominal(params, **overrides) -> NominalControllerEndpoint:
    values = {**params['nominal_controller_node'], **overrides}
    model = GraspModel.from_parameters(values)
    return NominalControllerEndpoint(model, NominalConfig.from_parameters(values), MSGS)


def make_filter(params, enabled=True, **overrides) -> SafetyFilterEndpoint:
    values = {**params['safety_filter_node'], **overrides}
    model = GraspModel.from_parameters(values)
    return SafetyFilterEndpoint(
        model,
        SafetyFilterConfig.from_parameters(values),
        InputPolicyConfig.from_parameters(values),
        MSGS,
        enabled=enabled,
    )


class Graph:
    """The three endpoints wired as the ROS graph wires the nodes; messages pass through CDR."""

    def __init__(self, sim, nominal, safety_filter):
        self.log: list[Outgoing] = []
        self.subscribers = {
            topics.JOINT_STATES: [nominal.on_joint_states, safety_filter.on_joint_states],
            topics.OBJECT_ODOM: [nominal.on_odom, safety_filter.on_odom],
            topics.OBJECT_REFERENCE: [nominal.on_reference],
            topics.EFFORT_NOMINAL: [safety_filter.on_effort_nominal],
            topics.EFFORT_COMMAND: [sim.on_command],
        }

    def deliver(self, outgoing):
        queue = deque(outgoing)
        while queue:
            topic, stamp_ns, msg = queue.popleft()
            received = through_cdr(msg)
            self.log.append(Outgoing(topic, stamp_ns, received))
            for handler in self.subscribers.get(topic, []):
                queue.extend(handler(received))

    def messages(self, topic):
        return [o.msg for o in self.log if o.topic == topic]


def statuses(outgoing, name):
    """Return the DiagnosticStatus reports called ``name`` among the outgoing messages."""
    return [
        report
        for o in outgoing
        if o.topic == topics.DIAGNOSTICS
        for report in m.diagnostics_from_msg(through_cdr(o.msg)).reports
        if report.name == name
    ]


def efforts(msgs, joint_names):
    return [m.effort_from_msg(msg, joint_names).effort for msg in msgs]


def commands(outgoing, joint_names):
    return [
        m.effort_from_msg(through_cdr(o.msg), joint_names).effort
        for o in outgoing
        if o.topic == topics.EFFORT_COMMAND
    ]


# ----------------------------------------------------------------------------------------
# Lockstep through CDR


def test_lockstep_ticks_through_cdr_match_the_cores_wired_directly(params):
    sim, nominal, safety_filter = make_sim(params), make_nominal(params), make_filter(params)
    graph = Graph(sim, nominal, safety_filter)
    graph.deliver(sim.start())

    assert sim.finished
    assert sim.stop_reason == 'duration'
    counts = Counter(o.topic for o in graph.log)
    assert counts[topics.SCENARIO] == 1
    # States at t_0..t_N; the controllers also answer the final state, which ends the run.
    for topic in (topics.JOINT_STATES, topics.OBJECT_ODOM, topics.CLOCK, topics.EFFORT_NOMINAL):
        assert counts[topic] == STEPS + 1, topic
    assert counts[topics.EFFORT_COMMAND] == STEPS + 1
    assert counts[topics.MARGINS] == STEPS + 1
    assert counts[topics.CONTACTS] == STEPS
    for topic in counts:
        stamps = [o.stamp_ns for o in graph.log if o.topic == topic]
        assert stamps == sorted(stamps), topic
    dt_ns = m.seconds_to_nanoseconds(sim.config.time_step)
    command_stamps = [o.stamp_ns for o in graph.log if o.topic == topics.EFFORT_COMMAND]
    assert command_stamps == [k * dt_ns for k in range(STEPS + 1)]
    (end,) = statuses(graph.log, 'hand_sim')
    assert end.values['run.stop_reason'] == 'duration'
    assert int(end.values['run.steps']) == STEPS

    # The same cores wired by function calls, without messages.
    model = GraspModel.from_parameters(params['hand_sim_node'])
    plant = Simulator(model, sim_config(params))
    config = NominalConfig.from_parameters(params['nominal_controller_node'])
    controller = NominalController(config)
    core = SafetyFilter.from_config(
        model, SafetyFilterConfig.from_parameters(params['safety_filter_node'])
    )
    start = plant.state
    reference = PaperReference(
        Pose(start.p_object_in_palm, start.R_object_to_palm), config.amplitude, config.frequency
    )
    joint_names = model.joint_names
    sent = [
        m.effort_from_msg(msg, joint_names).effort for msg in graph.messages(topics.EFFORT_COMMAND)
    ]
    for k in range(STEPS):
        s = plant.state
        state = model.state(s.t, s.q, s.dq, s.p_object_in_palm, s.R_object_to_palm, s.twist_object)
        u = core.solve(state, controller.compute(state, reference.sample(s.t)).u).u
        np.testing.assert_allclose(sent[k], u, rtol=1e-7, atol=1e-8)
        plant.step(u)
    final = m.joint_state_from_msg(graph.messages(topics.JOINT_STATES)[-1], joint_names)
    np.testing.assert_allclose(final.position, plant.state.q, rtol=0, atol=1e-12)
    np.testing.assert_allclose(final.velocity, plant.state.dq, rtol=0, atol=1e-9)
    # The state's effort is the torque applied over the step that ended at its stamp.
    np.testing.assert_array_equal(final.effort, sent[STEPS - 1])


def test_filter_off_passes_the_nominal_command_through_bit_for_bit(params):
    sim, nominal = make_sim(params), make_nominal(params)
    safety_filter = make_filter(params, enabled=False)
    graph = Graph(sim, nominal, safety_filter)
    graph.deliver(sim.start())
    joint_names = sim.model.joint_names
    nominal_u = [
        m.effort_from_msg(x, joint_names).effort for x in graph.messages(topics.EFFORT_NOMINAL)
    ]
    sent = [
        m.effort_from_msg(x, joint_names).effort for x in graph.messages(topics.EFFORT_COMMAND)
    ]
    assert len(sent) == STEPS + 1
    for u, u_nom in zip(sent, nominal_u, strict=True):
        assert u.tobytes() == u_nom.tobytes()
    margins = m.margins_from_msg(graph.messages(topics.MARGINS)[0])
    assert any(name.startswith('no_slip/') for name in margins.names)
    reports = statuses(graph.log, 'safety_filter')
    assert {r.values['status'] for r in reports} == {'disabled'}
    assert {r.values['filter.enabled'] for r in reports} == {'false'}
    # Nothing is enforced while the filter is off: every tick says so at WARN.
    assert all(r.level is DiagnosticLevel.WARN for r in reports)
    assert all('OFF' in r.message for r in reports)


def test_scenario_message_describes_the_model_and_run(params):
    sim = make_sim(params)
    first, *_ = sim.start()
    assert first.topic == topics.SCENARIO
    document = scenario_from_msg(through_cdr(first.msg))
    model = sim.model
    assert document['joint_names'] == model.joint_names
    assert document['joint_lower_limits'] == model.joint_lower_limits.tolist()
    assert document['joint_upper_limits'] == model.joint_upper_limits.tolist()
    assert document['effort_limits'] == model.effort_limits.tolist()
    assert document['contact_names'] == model.contact_names
    # One mu for every contact (the paper's) stays one number in the document.
    mu = params['hand_sim_node']['model.friction_coefficient']
    assert document['friction_coefficient'] == mu
    assert model.friction_coefficient.tolist() == [document['friction_coefficient']] * 3
    assert document['fingertip_workspace'] == dataclasses.asdict(model.fingertip_workspace)
    assert document['time_step'] == sim.config.time_step
    assert document['n_steps'] == STEPS
    assert document['integrator'] == 'ode3'
    assert not [key for key in document if 'filter' in key]


@pytest.mark.parametrize(
    ('text', 'match'),
    [
        ('not json', 'invalid JSON'),
        ('[]', 'JSON object'),
        ('{"format": "other", "version": 1}', 'format'),
    ],
)
def test_scenario_parser_rejects_foreign_documents(text, match):
    with pytest.raises(ScenarioError, match=match):
        scenario_from_text(text)


def test_scenario_parser_names_a_missing_key(params):
    document = json.loads(make_sim(params).scenario_text)
    del document['time_step']
    with pytest.raises(ScenarioError, match="'time_step'"):
        scenario_from_text(json.dumps(document))


# ----------------------------------------------------------------------------------------
# The simulator endpoint


def test_simulator_rejects_bad_and_mistimed_commands_without_stepping(params):
    sim = make_sim(params)
    sim.start()
    names = sim.model.joint_names
    t0 = sim.t
    u = np.zeros(len(names))
    bad = [
        m.effort_to_msg(MSGS, t0, names, np.full(len(names), np.nan)),
        m.effort_to_msg(MSGS, t0, names[:-1], u[:-1]),
        m.effort_to_msg(MSGS, t0, [*names[:-1], 'elbow'], u),
        m.effort_to_msg(MSGS, t0 + sim.config.time_step, names, u),
    ]
    for msg in bad:
        outgoing = sim.on_command(through_cdr(msg))
        assert [o.topic for o in outgoing] == [topics.DIAGNOSTICS]
        (report,) = statuses(outgoing, 'hand_sim')
        assert report.level is DiagnosticLevel.WARN
        assert sim.t == t0
        assert sim.simulator.step_index == 0
    applied = sim.on_command(through_cdr(m.effort_to_msg(MSGS, t0, list(reversed(names)), u)))
    assert [o.topic for o in applied][:2] == [topics.CONTACTS, topics.CLOCK]
    assert sim.simulator.step_index == 1


def test_simulator_timeout_reports_and_republishes_the_same_state(params):
    sim = make_sim(params, command_timeout=0.5)
    sim.start(now=10.0)
    assert sim.timeout(now=10.4) == []
    outgoing = sim.timeout(now=10.6)
    assert [o.topic for o in outgoing] == [
        topics.DIAGNOSTICS,
        topics.CLOCK,
        topics.JOINT_STATES,
        topics.OBJECT_ODOM,
    ]
    assert {o.stamp_ns for o in outgoing} == {0}
    assert 'no command' in statuses(outgoing, 'hand_sim')[0].message
    assert sim.timeout(now=10.7) == []  # the wait started over


def test_lockstep_endpoint_steps_in_lockstep_whatever_the_lockstep_parameter(params):
    # lockstep false selects the node's hardware mode (hand_sim_node.hardware); the lockstep
    # endpoint (the runner's) waits for the command of its state's stamp all the same.
    sim = make_sim(params, lockstep=False)
    sim.start()
    names = sim.model.joint_names
    early = sim.on_command(m.effort_to_msg(MSGS, 0.001, names, np.zeros(len(names))))
    assert 'is early' in statuses(early, 'hand_sim')[0].message
    assert sim.simulator.step_index == 0
    outgoing = sim.on_command(m.effort_to_msg(MSGS, 0.0, names, np.zeros(len(names))))
    assert topics.JOINT_STATES in [o.topic for o in outgoing]
    assert sim.simulator.step_index == 1
    assert sim.awaited_stamp_ns == sim.stamp_ns == 1_000_000


def test_simulator_live_parameters_apply_and_read_only_ones_are_refused(params):
    sim = make_sim(params)
    sim.update_config(dataclasses.replace(sim.config, stop_on_slip=True, command_timeout=2.0))
    assert sim.simulator.config.stop_on_slip
    assert sim.command_timeout == 2.0
    with pytest.raises(ValueError, match='time_step'):
        sim.update_config(dataclasses.replace(sim.config, time_step=0.0005))


# ----------------------------------------------------------------------------------------
# The nominal controller endpoint


def first_state_messages(params):
    """Return the simulator and its state at t_0 (joint states, odometry), through CDR."""
    sim = make_sim(params)
    state = {o.topic: through_cdr(o.msg) for o in sim.start()}
    return sim, state[topics.JOINT_STATES], state[topics.OBJECT_ODOM]


def bad_joint_states(msg):
    msg.position = np.r_[np.inf, msg.position[1:]]
    return msg


def short_velocity(msg):
    msg.velocity = msg.velocity[:-1]
    return msg


def renamed_joint(msg):
    """Rename a model joint: it is missing then (the other name is ignored)."""
    msg.name[3] = 'wrist'
    return msg


def missing_joint(msg):
    msg.name, msg.position = msg.name[:-1], msg.position[:-1]
    msg.velocity, msg.effort = msg.velocity[:-1], msg.effort[:-1]
    return msg


@pytest.mark.parametrize(
    ('mutate', 'match'),
    [
        (bad_joint_states, 'position'),
        (short_velocity, 'velocity'),
        (renamed_joint, r"missing joint names \['finger2_joint1'\]"),
        (missing_joint, 'missing joint'),
    ],
)
def test_nominal_controller_rejects_bad_joint_states_without_a_command(params, mutate, match):
    _, joints, odometry = first_state_messages(params)
    nominal = make_nominal(params)
    mutate(joints)
    assert nominal.on_odom(odometry) == []
    outgoing = nominal.on_joint_states(joints)
    assert [o.topic for o in outgoing] == [topics.DIAGNOSTICS]
    (report,) = statuses(outgoing, 'nominal_controller')
    assert report.level is DiagnosticLevel.WARN
    assert re.search(match, report.message)
    assert nominal.last_output is None


def test_nominal_controller_follows_a_topic_reference_and_reports_it_stale(params):
    sim, joints, odometry = first_state_messages(params)
    nominal = make_nominal(params, **{'reference.source': 'topic'})
    nominal.on_joint_states(joints)
    outgoing = nominal.on_odom(odometry)
    (report,) = statuses(outgoing, 'nominal_controller')
    assert 'no /object/reference' in report.message

    # A planner's reference: a pose 1 cm above the start, moving up at 1 cm/s.
    s = sim.simulator.state
    target = ObjectReference(
        s.p_object_in_palm + np.array([0.0, 0.0, 0.01]),
        s.R_object_to_palm,
        np.array([0.0, 0.0, 0.01, 0.0, 0.0, 0.0]),
        np.zeros(6),
    )
    nominal.on_reference(through_cdr(m.reference_to_msg(MSGS, 0.0, [0.0], [target])))
    nominal.on_joint_states(joints)
    outgoing = nominal.on_odom(odometry)
    assert [o.topic for o in outgoing] == [topics.EFFORT_NOMINAL, topics.OBJECT_REFERENCE_SAMPLE]
    u = m.effort_from_msg(through_cdr(outgoing[0].msg), sim.model.joint_names).effort
    # The sample it tracked is published as it was received from the planner.
    tracked = m.odometry_from_msg(through_cdr(outgoing[1].msg))
    np.testing.assert_allclose(tracked.p_object_in_palm, target.p_object_in_palm, atol=1e-12)
    np.testing.assert_allclose(tracked.R_object_to_palm, target.R_object_to_palm, atol=1e-12)
    np.testing.assert_allclose(tracked.twist_object, target.twist_object, atol=1e-12)
    state = sim.simulator.grasp_state()
    sample = ReferenceSample.from_pose(
        Pose(target.p_object_in_palm, target.R_object_to_palm), target.twist_object
    )
    expected = NominalController(nominal.config).compute(state, sample).u
    np.testing.assert_allclose(u, expected, rtol=1e-9, atol=1e-10)


def test_nominal_controller_gains_change_live(params):
    _, joints, odometry = first_state_messages(params)
    nominal = make_nominal(params)
    nominal.on_joint_states(joints)
    before = nominal.on_odom(odometry)[0].msg.effort.copy()
    nominal.update_config(dataclasses.replace(nominal.config, kf=20.0))
    nominal.on_joint_states(joints)
    after = nominal.on_odom(odometry)[0].msg.effort
    assert not np.allclose(before, after)
    with pytest.raises(ValueError, match='read-only'):
        nominal.update_config(dataclasses.replace(nominal.config, reference_source='topic'))


def test_a_live_gain_change_keeps_the_null_space_posture(params):
    _, joints, odometry = first_state_messages(params)
    nominal = make_nominal(params)
    nominal.on_joint_states(joints)
    nominal.on_odom(odometry)
    posture = nominal.controller.posture
    assert posture is not None
    nominal.update_config(dataclasses.replace(nominal.config, kf=20.0))
    np.testing.assert_array_equal(nominal.controller.posture, posture)


# ----------------------------------------------------------------------------------------
# The safety filter endpoint: bad input is reported and never filtered


def tick_inputs(params):
    """Return valid inputs of the first tick (state and u_nom at t_0), as received."""
    sim, joints, odometry = first_state_messages(params)
    nominal = make_nominal(params)
    nominal.on_joint_states(joints)
    effort_nominal, _reference_sample = nominal.on_odom(odometry)
    return sim, joints, odometry, through_cdr(effort_nominal.msg)


def restamp(msg, t):
    msg.header.stamp = m.time_to_msg(MSGS, t)
    return msg


def filter_after_one_good_tick(params, **overrides):
    """Return (sim, filter endpoint, its safe u*, the inputs) after one accepted tick."""
    sim, joints, odometry, effort_nominal = tick_inputs(params)
    safety_filter = make_filter(params, **overrides)
    safety_filter.filter = CountingFilter(safety_filter.filter)
    assert safety_filter.on_joint_states(joints) == []
    assert safety_filter.on_odom(odometry) == []
    outgoing = safety_filter.on_effort_nominal(effort_nominal)
    assert [o.topic for o in outgoing] == [
        topics.EFFORT_COMMAND,
        topics.MARGINS,
        topics.DIAGNOSTICS,
    ]
    assert safety_filter.filter.calls == 1
    (safe,) = commands(outgoing, sim.model.joint_names)
    return sim, safety_filter, safe, (joints, odometry, effort_nominal)


def nan_nominal(msg):
    msg.effort = np.r_[msg.effort[:4], np.nan, msg.effort[5:]]
    return msg


def skewed_quaternion(msg):
    msg.pose.pose.orientation.w += 0.1
    return msg


CASES = {
    'non-finite joint position': (topics.JOINT_STATES, bad_joint_states, 'position'),
    'wrong velocity length': (topics.JOINT_STATES, short_velocity, 'velocity'),
    'renamed joint': (
        topics.JOINT_STATES,
        renamed_joint,
        "missing joint names ['finger2_joint1']",
    ),
    'missing joint name': (topics.JOINT_STATES, missing_joint, 'missing joint'),
    'NaN nominal effort': (topics.EFFORT_NOMINAL, nan_nominal, 'effort'),
    'non-unit quaternion': (topics.OBJECT_ODOM, skewed_quaternion, 'quaternion'),
}


@pytest.mark.parametrize('case', list(CASES))
def test_filter_holds_the_last_safe_command_on_bad_input(params, case):
    topic, mutate, match = CASES[case]
    sim, safety_filter, safe, (joints, odometry, effort_nominal) = filter_after_one_good_tick(
        params
    )
    dt = sim.config.time_step
    inputs = {
        topics.JOINT_STATES: restamp(joints, dt),
        topics.OBJECT_ODOM: restamp(odometry, dt),
        topics.EFFORT_NOMINAL: restamp(effort_nominal, dt),
    }
    inputs[topic] = mutate(inputs[topic])
    handlers = {
        topics.JOINT_STATES: safety_filter.on_joint_states,
        topics.OBJECT_ODOM: safety_filter.on_odom,
        topics.EFFORT_NOMINAL: safety_filter.on_effort_nominal,
    }
    outgoing = handlers[topic](inputs[topic])
    assert [o.topic for o in outgoing] == [topics.EFFORT_COMMAND, topics.DIAGNOSTICS]
    (held,) = commands(outgoing, sim.model.joint_names)
    assert held.tobytes() == safe.tobytes()
    # Stamped with the rejected tick's stamp, so a lockstep simulator goes on.
    assert outgoing[0].stamp_ns == m.seconds_to_nanoseconds(dt)
    (report,) = statuses(outgoing, 'safety_filter')
    assert report.level is DiagnosticLevel.WARN
    assert report.values['input.mode'] == 'holding'
    assert report.values[Key.STATUS] == TickStatus.INPUT_HELD.value
    assert match in report.message
    # The other inputs of that tick arrive afterwards: no command is computed from them.
    for other, handler in handlers.items():
        if other != topic:
            assert handler(inputs[other]) == []
    assert safety_filter.filter.calls == 1


def test_filter_rejects_stale_and_out_of_order_stamps(params):
    sim, safety_filter, safe, (joints, odometry, _) = filter_after_one_good_tick(params)
    # Older than max_age, but within the hold timeout of the last safe command.
    now = 1.5 * safety_filter.inputs.guard.max_age
    assert now < safety_filter.hold.hold_timeout
    stale = safety_filter.on_joint_states(joints, now=now)
    (report,) = statuses(stale, 'safety_filter')
    assert 'stale' in report.message
    (held,) = commands(stale, sim.model.joint_names)
    assert held.tobytes() == safe.tobytes()

    fresh = make_filter(params)
    fresh.filter = CountingFilter(fresh.filter)
    assert fresh.on_odom(restamp(odometry, 0.002)) == []
    out_of_order = fresh.on_odom(restamp(odometry, 0.001))
    (report,) = statuses(out_of_order, 'safety_filter')
    assert 'out-of-order' in report.message
    # Before its first tick the filter has computed no command: it sends none (a driver
    # that holds its position until commanded must not go limp), only a WARN.
    assert [o.topic for o in out_of_order] == [topics.DIAGNOSTICS]
    assert report.level is DiagnosticLevel.WARN
    assert report.values[Key.STATUS] == TickStatus.INPUT_IGNORED.value
    assert 'no command sent' in report.message
    assert fresh.filter.calls == 0


def test_filter_falls_back_to_gravity_compensation_after_the_hold_timeout(params):
    sim, safety_filter, safe, (joints, odometry, _) = filter_after_one_good_tick(params)
    hold_timeout = safety_filter.hold.hold_timeout
    late = 2 * hold_timeout
    outgoing = safety_filter.on_odom(skewed_quaternion(restamp(odometry, late)), now=late)
    (report,) = statuses(outgoing, 'safety_filter')
    assert report.level is DiagnosticLevel.ERROR
    assert report.values['input.mode'] == 'fallback'
    (fallback,) = commands(outgoing, sim.model.joint_names)
    accepted = m.joint_state_from_msg(joints, sim.model.joint_names)
    s = sim.simulator.state
    g = sim.model.state(
        0.0, accepted.position, np.zeros(9), s.p_object_in_palm, s.R_object_to_palm, np.zeros(6)
    ).gravity_torque
    limits = sim.model.effort_limits
    np.testing.assert_allclose(fallback, np.clip(g, -limits, limits), rtol=1e-12, atol=1e-12)
    assert not np.allclose(fallback, safe)
    assert safety_filter.filter.calls == 1


def test_filter_answers_a_repeated_tick_with_the_same_messages(params):
    _, safety_filter, _, (joints, odometry, effort_nominal) = filter_after_one_good_tick(params)
    first = safety_filter._last_outputs
    assert safety_filter.on_joint_states(joints) == []
    assert safety_filter.on_odom(odometry) == []
    again = safety_filter.on_effort_nominal(effort_nominal)
    assert [o.msg for o in again] == [o.msg for o in first]
    assert safety_filter.filter.calls == 1


def test_filter_diagnostics_report_status_timing_margins_and_mode(params):
    _, safety_filter, _, _ = filter_after_one_good_tick(params)
    (_, margins_out, diagnostics) = safety_filter._last_outputs
    margins = m.margins_from_msg(through_cdr(margins_out.msg))
    (report,) = m.diagnostics_from_msg(through_cdr(diagnostics.msg)).reports
    result = safety_filter.last_result
    assert report.values['status'] == result.status.value
    assert float(report.values['solve_time_us']) == pytest.approx(result.solve_time * 1e6)
    solve, step, tick = (
        float(report.values[key]) for key in ('solve_time_us', 'step_time_us', 'tick_time_us')
    )
    assert 0.0 <= solve <= step <= tick and step > 0.0
    assert report.values['relaxed'] == ('true' if result.relaxed else 'false')
    assert report.values['input.mode'] == 'ok'
    families = {name.split('/')[0] for name in margins.names}
    assert families >= {'no_slip', 'joint_limits', 'fingertip_workspace', 'actuator_limits'}
    for family in families:
        smallest = min(
            h for name, h in zip(margins.names, margins.h, strict=True) if name.startswith(family)
        )
        assert float(report.values[f'min_margin.{family}']) == smallest
    assert list(margins.names) == list(result.margins)
    assert margins.h.tolist() == list(result.margins.values())


def test_filter_can_be_switched_off_and_on_live(params):
    _, safety_filter, _, (joints, odometry, effort_nominal) = filter_after_one_good_tick(params)
    safety_filter.update_config(enabled=False)
    dt = 0.001
    safety_filter.on_joint_states(restamp(joints, dt))
    safety_filter.on_odom(restamp(odometry, dt))
    outgoing = safety_filter.on_effort_nominal(restamp(effort_nominal, dt))
    (passed,) = commands(outgoing, safety_filter.model.joint_names)
    u_nom = m.effort_from_msg(effort_nominal, safety_filter.model.joint_names).effort
    assert passed.tobytes() == u_nom.tobytes()
    assert safety_filter.filter.calls == 1
    assert math.isfinite(float(statuses(outgoing, 'safety_filter')[0].values['step_time_us']))


def next_tick(safety_filter, inputs, t, wall=None, only=None):
    """Deliver the inputs restamped to ``t`` (those of ``only``, else all); return the output."""
    handlers = {
        topics.JOINT_STATES: safety_filter.on_joint_states,
        topics.OBJECT_ODOM: safety_filter.on_odom,
        topics.EFFORT_NOMINAL: safety_filter.on_effort_nominal,
    }
    outgoing = []
    for topic, msg in zip(handlers, inputs, strict=True):
        if only is None or topic in only:
            outgoing += handlers[topic](restamp(msg, t), wall=wall)
    return outgoing


class RestatingFilter(CountingFilter):
    """A SafetyFilter whose answers carry the statuses given per call (else its own)."""

    def __init__(self, core, statuses):
        super().__init__(core)
        self.statuses = statuses

    def solve(self, state, u_nom):
        result = super().solve(state, u_nom)
        status = self.statuses.get(self.calls)
        return result if status is None else dataclasses.replace(result, status=status)


def test_every_qp_status_is_a_tick_status_and_a_failed_one_is_an_error(params):
    assert {TickStatus.of(s).value for s in FilterStatus} == {s.value for s in FilterStatus}
    assert all(TickStatus.of(s) is s for s in TickStatus)  # a tick status is its own
    assert FAILED_STATUSES == {
        TickStatus.of(FilterStatus.FALLBACK_LAST_GOOD),
        TickStatus.of(FilterStatus.FALLBACK_NOMINAL),
    }
    _, joints, odometry, effort_nominal = tick_inputs(params)
    for status in FilterStatus:
        safety_filter = make_filter(params)
        safety_filter.filter = RestatingFilter(safety_filter.filter, {1: status})
        outgoing = next_tick(safety_filter, (joints, odometry, effort_nominal), 0.0)
        (report,) = statuses(outgoing, 'safety_filter')
        assert report.values[Key.STATUS] == status.value
        if TickStatus.of(status) in FAILED_STATUSES:
            assert report.level is DiagnosticLevel.ERROR, status
        else:
            assert report.level is not DiagnosticLevel.ERROR, status


def test_filter_computes_margins_and_active_rows_only_on_ticks_that_send_them(params, monkeypatch):
    calls = Counter()
    for writer in ('_write_margins', '_write_box'):
        original = getattr(ResultAssembler, writer)

        def counted(assembler, *args, original=original, writer=writer):
            calls[writer] += 1
            return original(assembler, *args)

        monkeypatch.setattr(ResultAssembler, writer, counted)
    _, joints, odometry, effort_nominal = tick_inputs(params)
    safety_filter = make_filter(params)
    safety_filter.rate.configure(
        PublicationRateConfig(diagnostics_period=0.0095, margins_period=0.0045)
    )
    sent_per_tick = []
    for i in range(20):
        before = Counter(calls)
        outgoing = next_tick(safety_filter, (joints, odometry, effort_nominal), i * 0.001)
        sent = {o.topic for o in outgoing}
        sent_per_tick.append(sent)
        margins_read = bool(sent & {topics.MARGINS, topics.DIAGNOSTICS})
        # margins: one margin writer call (it writes the box too); active rows: one box call
        assert calls['_write_margins'] - before['_write_margins'] == margins_read, (i, sent)
        expected_box = margins_read + (topics.DIAGNOSTICS in sent)
        assert calls['_write_box'] - before['_write_box'] == expected_box, (i, sent)
    assert {topics.EFFORT_COMMAND} in sent_per_tick  # ticks that send neither
    assert {topics.EFFORT_COMMAND, topics.MARGINS} in sent_per_tick
    assert any(topics.DIAGNOSTICS in sent for sent in sent_per_tick)


# ----------------------------------------------------------------------------------------
# The input watchdog (the steady clock is an argument)

WALL = 1000.0  # an arbitrary steady-clock origin, s


def filter_after_one_wall_tick(params):
    """Return (sim, filter endpoint, its safe u*, the inputs) after a tick accepted at WALL."""
    sim, joints, odometry, effort_nominal = tick_inputs(params)
    safety_filter = make_filter(params)
    safety_filter.filter = CountingFilter(safety_filter.filter)
    assert safety_filter.on_joint_states(joints, wall=WALL - 0.0004) == []
    assert safety_filter.on_odom(odometry, wall=WALL - 0.0002) == []
    (safe,) = commands(
        safety_filter.on_effort_nominal(effort_nominal, wall=WALL), sim.model.joint_names
    )
    return sim, safety_filter, safe, (joints, odometry, effort_nominal)


def test_watchdog_sends_the_fallback_and_an_error_once_no_tick_came_for_the_hold_timeout(params):
    sim, safety_filter, safe, (joints, _, _) = filter_after_one_wall_tick(params)
    hold_timeout = safety_filter.hold.hold_timeout
    # Within the hold timeout: the normal path, nothing to send.
    for wall in (WALL + WATCHDOG_PERIOD, WALL + 0.999 * hold_timeout):
        assert safety_filter.watchdog(wall, now=0.0) == []
    # Past it: fallback and ERROR at every call. The node clock stood still (a dead
    # simulator under use_sim_time): the command is stamped with it.
    accepted = m.joint_state_from_msg(joints, sim.model.joint_names).position
    g = sim.model.hand.terms(accepted, np.zeros(9)).gravity_torque
    limits = sim.model.effort_limits
    expected = np.clip(g, -limits, limits)
    inputs = (topics.JOINT_STATES, topics.OBJECT_ODOM, topics.EFFORT_NOMINAL)
    for k in range(1, 4):
        wall = WALL + hold_timeout + k * WATCHDOG_PERIOD
        outgoing = safety_filter.watchdog(wall, now=0.0)
        assert [o.topic for o in outgoing] == [topics.EFFORT_COMMAND, topics.DIAGNOSTICS]
        assert all(o.stamp_ns == 0 for o in outgoing)
        (fallback,) = commands(outgoing, sim.model.joint_names)
        np.testing.assert_allclose(fallback, expected, rtol=1e-12, atol=1e-12)
        assert not np.allclose(fallback, safe)
        (report,) = statuses(outgoing, 'safety_filter')
        assert report.level is DiagnosticLevel.ERROR
        assert report.values[Key.STATUS] == TickStatus.INPUT_FALLBACK.value
        assert report.values[Key.INPUT_WATCHDOG] == 'true'
        assert report.values[Key.INPUT_MODE] == 'fallback'
        assert report.values[Key.INPUT_MISSING] == ','.join(inputs)
        elapsed = float(report.values[Key.INPUT_WALL_TIME_SINCE_ACCEPTED])
        assert elapsed == pytest.approx(wall - WALL)
        assert float(report.values[silent_for(topics.JOINT_STATES)]) == pytest.approx(
            wall - WALL + 0.0004
        )
        for topic in inputs:
            assert f'nothing on {topic} for ' in report.message
        assert 'gravity_compensation' in report.message
    # The watchdog stamps with the node clock when it runs (not before the last tick).
    (command, _) = safety_filter.watchdog(WALL + 1.0, now=2.5)
    assert command.stamp_ns == m.seconds_to_nanoseconds(2.5)
    assert safety_filter.hold.rejected_ticks == 0
    assert safety_filter.filter.calls == 1


def test_watchdog_names_the_input_that_stopped_and_ticks_say_when_they_resume(params):
    _, safety_filter, _, inputs = filter_after_one_wall_tick(params)
    dt = 0.001
    alive = {topics.JOINT_STATES, topics.OBJECT_ODOM}
    assert next_tick(safety_filter, inputs, dt, wall=WALL + 0.05, only=alive) == []
    (_, diagnostics) = safety_filter.watchdog(WALL + 0.15, now=dt)
    (report,) = statuses([diagnostics], 'safety_filter')
    assert report.values[Key.INPUT_MISSING] == topics.EFFORT_NOMINAL
    assert f'nothing on {topics.EFFORT_NOMINAL} for 0.150 s' in report.message
    assert topics.JOINT_STATES not in report.message.split(':', 2)[-1]

    # The nominal controller is back: a normal tick, which says how long it was away.
    outgoing = next_tick(safety_filter, inputs, dt, wall=WALL + 0.3, only={topics.EFFORT_NOMINAL})
    assert [o.topic for o in outgoing] == [
        topics.EFFORT_COMMAND,
        topics.MARGINS,
        topics.DIAGNOSTICS,
    ]
    (report,) = statuses(outgoing, 'safety_filter')
    assert report.values[Key.INPUT_MODE] == 'ok'
    assert TickStatus(report.values[Key.STATUS]) not in INPUT_STATUSES
    assert float(report.values[Key.INPUT_RESUMED_AFTER]) == pytest.approx(0.3)
    assert 'inputs back after 0.300 s' in report.message
    assert report.level >= DiagnosticLevel.WARN
    assert safety_filter.watchdog(WALL + 0.35, now=dt) == []
    (report,) = statuses(
        next_tick(safety_filter, inputs, 2 * dt, wall=WALL + 0.301), 'safety_filter'
    )
    assert Key.INPUT_RESUMED_AFTER not in report.values


def test_a_tick_answered_again_keeps_the_watchdog_away(params):
    """A simulator that waited in vain sends its state again: the inputs did not stop."""
    sim, safety_filter, safe, inputs = filter_after_one_wall_tick(params)
    hold_timeout = safety_filter.hold.hold_timeout
    resent = WALL + 0.9 * hold_timeout
    joints, odometry, effort_nominal = inputs
    assert safety_filter.on_joint_states(joints, wall=resent) == []
    assert safety_filter.on_odom(odometry, wall=resent) == []
    (again,) = commands(
        safety_filter.on_effort_nominal(effort_nominal, wall=resent), sim.model.joint_names
    )
    np.testing.assert_array_equal(again, safe)
    # A hold timeout after the first answer, not after the second: no fallback yet.
    assert safety_filter.watchdog(WALL + 1.5 * hold_timeout, now=0.0) == []
    # Silent after it: the fallback a hold timeout after the second answer.
    outgoing = safety_filter.watchdog(resent + hold_timeout + WATCHDOG_PERIOD, now=0.0)
    assert [o.topic for o in outgoing] == [topics.EFFORT_COMMAND, topics.DIAGNOSTICS]
    (report,) = statuses(outgoing, 'safety_filter')
    elapsed = float(report.values[Key.INPUT_WALL_TIME_SINCE_ACCEPTED])
    assert elapsed == pytest.approx(hold_timeout + WATCHDOG_PERIOD)
    # Once the watchdog has taken over, a state sent again does not end it.
    assert next_tick(safety_filter, inputs, 0.0, wall=resent + 2 * hold_timeout) != []
    assert safety_filter.watchdog(resent + 2 * hold_timeout + 0.001, now=0.0) != []
    assert safety_filter.filter.calls == 1


def test_the_watchdog_waits_from_the_answer_of_a_slow_tick(params):
    """A tick longer than the hold timeout (a node's first loads its kernels): no fallback."""
    sim, joints, odometry, effort_nominal = tick_inputs(params)
    values = params['safety_filter_node']
    clock = [WALL]
    safety_filter = SafetyFilterEndpoint(
        GraspModel.from_parameters(values),
        SafetyFilterConfig.from_parameters(values),
        InputPolicyConfig.from_parameters(values),
        MSGS,
        wall_clock=lambda: clock[0],
    )
    hold_timeout = safety_filter.hold.hold_timeout
    slow = 3.0 * hold_timeout
    core = safety_filter.filter

    class SlowFilter(CountingFilter):
        def solve(self, state, u_nom):
            clock[0] += slow  # the wall clock runs on while the tick computes
            return super().solve(state, u_nom)

    safety_filter.filter = SlowFilter(core)
    assert safety_filter.on_joint_states(joints, wall=WALL - 0.0004) == []
    assert safety_filter.on_odom(odometry, wall=WALL - 0.0002) == []
    answer = safety_filter.on_effort_nominal(effort_nominal, wall=WALL)
    assert len(commands(answer, sim.model.joint_names)) == 1
    answered = WALL + slow
    # Timed from the last input, the watchdog would send the fallback right after the answer.
    for wall in (answered + WATCHDOG_PERIOD, answered + 0.999 * hold_timeout):
        assert safety_filter.watchdog(wall, now=0.0) == []
    outgoing = safety_filter.watchdog(answered + hold_timeout + WATCHDOG_PERIOD, now=0.0)
    assert [o.topic for o in outgoing] == [topics.EFFORT_COMMAND, topics.DIAGNOSTICS]
    (report,) = statuses(outgoing, 'safety_filter')
    elapsed = float(report.values[Key.INPUT_WALL_TIME_SINCE_ACCEPTED])
    assert elapsed == pytest.approx(hold_timeout + WATCHDOG_PERIOD)
    assert safety_filter.filter.calls == 1


def test_watchdog_waits_for_a_first_tick_with_wall_times(params):
    fresh = make_filter(params)
    assert fresh.watchdog(WALL + 100.0, now=0.0) == []
    # Inputs but no complete tick yet: still nothing to take over from.
    _, joints, _, _ = tick_inputs(params)
    fresh.on_joint_states(joints, wall=WALL)
    assert fresh.watchdog(WALL + 100.0, now=0.0) == []
    # The runner passes no wall times: its watchdog never acts.
    _, safety_filter, _, _ = filter_after_one_good_tick(params)
    assert safety_filter.watchdog(WALL + 100.0, now=0.0) == []


def test_switching_the_filter_is_reported_with_its_time(params):
    _, safety_filter, _, inputs = filter_after_one_good_tick(params)
    assert safety_filter.switch(True, now=0.2) is None  # already on
    text = safety_filter.switch(False, now=0.25)
    assert 'OFF' in text and 't = 0.250000 s' in text
    assert safety_filter.switch(False, now=0.3) is None
    dt = 0.001
    (report,) = statuses(next_tick(safety_filter, inputs, dt), 'safety_filter')
    assert report.level is DiagnosticLevel.WARN
    assert report.values[Key.STATUS] == TickStatus.DISABLED.value
    assert report.values[Key.FILTER_ENABLED] == 'false'
    assert float(report.values[Key.FILTER_SWITCHED_AT]) == 0.25
    text = safety_filter.switch(True, now=0.5)
    assert 'ON' in text and 't = 0.500000 s' in text
    (report,) = statuses(next_tick(safety_filter, inputs, 2 * dt), 'safety_filter')
    assert report.values[Key.STATUS] != TickStatus.DISABLED.value
    assert report.values[Key.FILTER_ENABLED] == 'true'
    assert float(report.values[Key.FILTER_SWITCHED_AT]) == 0.5
    assert report.level is (
        DiagnosticLevel.WARN if report.values[Key.RELAXED] == 'true' else DiagnosticLevel.OK
    )


class CountingModel:
    """Wraps a GraspModel and records the stamps whose state it computed."""

    def __init__(self, core):
        self.core = core
        self.stamps = []

    def state(self, t, *args, **kwargs):
        self.stamps.append(t)
        return self.core.state(t, *args, **kwargs)

    def __getattr__(self, name):
        return getattr(self.core, name)


ARRIVAL_ORDERS = [
    ('joints', 'odometry', 'nominal'),
    ('odometry', 'joints', 'nominal'),
    ('nominal', 'joints', 'odometry'),
    ('joints', 'nominal', 'odometry'),
]


@pytest.mark.parametrize('order', ARRIVAL_ORDERS, ids='-'.join)
def test_filter_computes_the_model_terms_once_the_state_is_complete(params, order):
    """The model terms need not wait for u_nom; the answer is the same in any arrival order."""
    _, joints, odometry, effort_nominal = tick_inputs(params)
    reference = make_filter(params)
    reference.on_joint_states(joints)
    reference.on_odom(odometry)
    expected = reference.on_effort_nominal(effort_nominal)
    safety_filter = make_filter(params)
    counting = safety_filter.inputs.model = CountingModel(safety_filter.model)
    handlers = {
        'joints': lambda: safety_filter.on_joint_states(joints),
        'odometry': lambda: safety_filter.on_odom(odometry),
        'nominal': lambda: safety_filter.on_effort_nominal(effort_nominal),
    }
    state_done = order.index('nominal') == 2
    outgoing = []
    for position, name in enumerate(order):
        outgoing = handlers[name]()
        if position == 1:
            # Both state messages in, u_nom not yet: computed already; else not yet.
            assert len(counting.stamps) == (1 if state_done else 0)
    assert len(counting.stamps) == 1
    assert [o.topic for o in outgoing] == [o.topic for o in expected]
    names = safety_filter.model.joint_names
    np.testing.assert_array_equal(commands(outgoing, names), commands(expected, names))
    np.testing.assert_array_equal(
        m.margins_from_msg(outgoing[1].msg).h, m.margins_from_msg(expected[1].msg).h
    )
    assert safety_filter.inputs.pending_states() == {}


def test_watchdog_never_answers_a_tick_whose_inputs_are_still_coming(params):
    """Lockstep: the simulator waits at t_1 for u*(t_1) while the nominal controller is slow.

    The watchdog's fallback then goes out 1 ns after t_1, which a lockstep simulator does not
    take for its command; the tick, once complete, gets its own u* stamped t_1.
    """
    sim, safety_filter, _, inputs = filter_after_one_wall_tick(params)
    t1 = sim.config.time_step
    late = WALL + 2.0 * safety_filter.hold.hold_timeout
    state_only = (topics.JOINT_STATES, topics.OBJECT_ODOM)
    assert next_tick(safety_filter, inputs, t1, wall=WALL + 0.001, only=state_only) == []
    fallback = safety_filter.watchdog(late, now=t1)
    command = next(o.msg for o in fallback if o.topic == topics.EFFORT_COMMAND)
    assert m.header_stamp_ns(command) == m.seconds_to_nanoseconds(t1) + 1
    outgoing = next_tick(safety_filter, inputs, t1, wall=late, only=(topics.EFFORT_NOMINAL,))
    (tick_command,) = [o.msg for o in outgoing if o.topic == topics.EFFORT_COMMAND]
    assert m.header_stamp_ns(tick_command) == m.seconds_to_nanoseconds(t1)
    assert safety_filter.filter.calls == 2


def test_before_a_first_tick_the_watchdog_reports_the_wait_and_sends_no_command(params):
    fresh = make_filter(params)
    _, joints, _, _ = tick_inputs(params)
    period = WAITING_REPORT_PERIOD
    assert fresh.watchdog(WALL, now=0.0) == []  # the watchdog's first call: the wait starts
    assert fresh.watchdog(WALL + 0.5 * period, now=0.0) == []
    (first,) = fresh.watchdog(WALL + period, now=0.0)
    assert first.topic == topics.DIAGNOSTICS
    (report,) = m.diagnostics_from_msg(first.msg).reports
    assert report.level is DiagnosticLevel.WARN
    assert Key.STATUS not in report.values  # answers no tick: the analysis counts none
    assert report.values[Key.INPUT_MISSING] == ','.join(
        (topics.JOINT_STATES, topics.OBJECT_ODOM, topics.EFFORT_NOMINAL)
    )
    assert fresh.watchdog(WALL + 1.5 * period, now=0.0) == []
    fresh.on_joint_states(joints, wall=WALL + 1.6 * period)
    (second,) = fresh.watchdog(WALL + 2.0 * period, now=0.0)
    (report,) = m.diagnostics_from_msg(second.msg).reports
    assert report.values[Key.INPUT_MISSING] == f'{topics.OBJECT_ODOM},{topics.EFFORT_NOMINAL}'
    assert 'waiting 2.0 s for a first tick' in report.message


# ----------------------------------------------------------------------------------------
# Hardened inputs: no message raises out of an endpoint


def negative_stamp(msg):
    msg.header.stamp = MSGS.Time(sec=-1, nanosec=0)
    return msg


def negative_stamp_cases(params):
    """Return (handler, message, status name) for every endpoint input, by case."""
    sim, joints, odometry, effort_nominal = tick_inputs(params)
    nominal = make_nominal(params)
    safety_filter = make_filter(params)
    started = make_sim(params)
    started.start()
    command = m.effort_to_msg(MSGS, 0.0, sim.model.joint_names, np.zeros(sim.model.n_joints))
    reference = m.reference_to_msg(
        MSGS,
        0.0,
        [0.0],
        [ObjectReference(np.zeros(3), np.eye(3), np.zeros(6), np.zeros(6))],
    )
    return {
        'nominal joint_states': (nominal.on_joint_states, joints, 'nominal_controller'),
        'nominal odom': (nominal.on_odom, odometry, 'nominal_controller'),
        'nominal reference': (nominal.on_reference, reference, 'nominal_controller'),
        'filter joint_states': (safety_filter.on_joint_states, joints, 'safety_filter'),
        'filter odom': (safety_filter.on_odom, odometry, 'safety_filter'),
        'filter effort_nominal': (
            safety_filter.on_effort_nominal,
            effort_nominal,
            'safety_filter',
        ),
        'simulator command': (started.on_command, command, 'hand_sim'),
    }


NEGATIVE_STAMP_CASES = (
    'nominal joint_states',
    'nominal odom',
    'nominal reference',
    'filter joint_states',
    'filter odom',
    'filter effort_nominal',
    'simulator command',
)


@pytest.mark.parametrize('case', NEGATIVE_STAMP_CASES)
@pytest.mark.parametrize('now', [None, 0.0])
def test_a_negative_stamp_is_reported_not_raised(params, case, now):
    handler, msg, name = negative_stamp_cases(params)[case]
    msg = negative_stamp(msg)
    outgoing = handler(msg) if now is None or name != 'safety_filter' else handler(msg, now=now)
    (report,) = statuses(outgoing, name)
    assert report.level >= DiagnosticLevel.WARN
    assert 'sec must be >= 0' in report.message


@pytest.mark.parametrize(
    'error', [m.MessageError('bad'), ValueError('bad'), KeyError('k'), RuntimeError('r')]
)
def test_a_failing_subscription_callback_is_reported_not_raised(error):
    from grasp_safety_filter.nodes.base_node import guarded_callback

    def callback(msg):
        raise error

    reported = []
    guarded = guarded_callback('/t', callback, lambda t, e: reported.append((t, e)), lambda: True)
    guarded(object())
    assert reported == [('/t', error)]

    def failing_report(topic, e):
        raise RuntimeError('publisher gone')

    guarded_callback('/t', callback, failing_report, lambda: True)(object())
    # Once the context is shut down the exception goes on, as before (the spin loop ends).
    with pytest.raises(type(error)):
        guarded_callback('/t', callback, failing_report, lambda: False)(object())


@pytest.mark.parametrize('length', [0, 10, 999, 1000, 1001, 100_000])
def test_report_texts_are_bounded(length):
    text = m.bounded_text('x' * length)
    assert len(text) <= m.MAX_REPORT_TEXT
    assert text == 'x' * length or f'{length} characters in all' in text


@pytest.mark.parametrize('shift', [1e308, 0.5])
def test_gravity_fallback_uses_the_joint_state_of_the_last_accepted_tick(params, shift):
    sim, safety_filter, _, (joints, odometry, _) = filter_after_one_good_tick(params)
    accepted = m.joint_state_from_msg(joints, sim.model.joint_names)
    late = 2 * safety_filter.hold.hold_timeout
    dt = sim.config.time_step
    # A joint state that parses but whose tick is never accepted (no u_nom; or the model
    # refuses it).
    wild = restamp(through_cdr(joints), dt)
    wild.position = np.asarray(wild.position) + shift
    assert safety_filter.on_joint_states(wild) == []
    outgoing = safety_filter.on_odom(skewed_quaternion(restamp(odometry, late)), now=late)
    (fallback,) = commands(outgoing, sim.model.joint_names)
    s = sim.simulator.state
    g = sim.model.state(
        0.0, accepted.position, np.zeros(9), s.p_object_in_palm, s.R_object_to_palm, np.zeros(6)
    ).gravity_torque
    limits = sim.model.effort_limits
    np.testing.assert_allclose(fallback, np.clip(g, -limits, limits), rtol=1e-12, atol=1e-12)


FUTURE_STAMPS = {
    'INT32_MAX s': lambda msg, now: setattr(
        msg.header, 'stamp', MSGS.Time(sec=2**31 - 1, nanosec=0)
    ),
    'now + 1 s': lambda msg, now: restamp(msg, now + 1.0),
}


def filter_handlers(safety_filter):
    return {
        topics.JOINT_STATES: safety_filter.on_joint_states,
        topics.OBJECT_ODOM: safety_filter.on_odom,
        topics.EFFORT_NOMINAL: safety_filter.on_effort_nominal,
    }


@pytest.mark.parametrize('clock', ['node clock', 'no clock'])
@pytest.mark.parametrize('future', list(FUTURE_STAMPS))
@pytest.mark.parametrize('topic', [topics.JOINT_STATES, topics.OBJECT_ODOM, topics.EFFORT_NOMINAL])
def test_a_future_stamp_is_rejected_and_later_valid_ticks_go_on(params, topic, future, clock):
    sim, safety_filter, _, (joints, odometry, effort_nominal) = filter_after_one_good_tick(params)
    dt = sim.config.time_step
    now = dt if clock == 'node clock' else None
    t_now = 0.0 if now is None else now  # without a clock: the last tick's time
    inputs = dict(
        zip(filter_handlers(safety_filter), (joints, odometry, effort_nominal), strict=True)
    )
    wild = through_cdr(inputs[topic])
    FUTURE_STAMPS[future](wild, t_now)
    rejected = filter_handlers(safety_filter)[topic](wild, now=now)
    (report,) = statuses(rejected, 'safety_filter')
    assert 'future stamp' in report.message
    assert report.values[Key.STATUS] == TickStatus.INPUT_HELD.value
    for k in (2, 3, 4):  # the rejection closed the tick of its clock stamp, dt
        outgoing = []
        for other, handler in filter_handlers(safety_filter).items():
            msg = restamp(through_cdr(inputs[other]), k * dt)
            outgoing += handler(msg, now=None if now is None else k * dt)
        (report,) = statuses(outgoing, 'safety_filter')
        assert report.values[Key.STATUS] not in {s.value for s in INPUT_STATUSES}, report.message
    assert safety_filter.filter.calls == 4


@pytest.mark.parametrize('future', list(FUTURE_STAMPS))
@pytest.mark.parametrize('topic', [topics.JOINT_STATES, topics.OBJECT_ODOM, topics.EFFORT_NOMINAL])
def test_without_a_clock_a_future_first_stamp_does_not_block_the_first_tick(params, topic, future):
    _, joints, odometry, effort_nominal = tick_inputs(params)
    safety_filter = make_filter(params)
    inputs = dict(
        zip(filter_handlers(safety_filter), (joints, odometry, effort_nominal), strict=True)
    )
    wild = through_cdr(inputs[topic])
    FUTURE_STAMPS[future](wild, 0.0)
    filter_handlers(safety_filter)[topic](wild)
    # A garbled far-future message (it does not parse) closes no tick either.
    garbled = nan_nominal(through_cdr(effort_nominal))
    FUTURE_STAMPS[future](garbled, 0.0)
    safety_filter.on_effort_nominal(garbled)
    outgoing = []
    for other, handler in filter_handlers(safety_filter).items():
        outgoing += handler(through_cdr(inputs[other]))
    assert [o.topic for o in outgoing] == [
        topics.EFFORT_COMMAND,
        topics.MARGINS,
        topics.DIAGNOSTICS,
    ]
    assert outgoing[0].stamp_ns == 0


def many_names(msg):
    msg.name = [f'joint_{i}' for i in range(100_000)]
    return msg


def many_duplicates(msg):
    msg.name = ['x'] * 100_000
    return msg


def huge_frame(msg):
    msg.header.frame_id = 'f' * 100_000
    return msg


def huge_name(msg):
    msg.name = ['n' * 100_000, *msg.name[1:]]
    return msg


HUGE_INPUTS = {
    '100k joint names': (topics.JOINT_STATES, many_names, '99995 more'),
    '100k duplicate names': (topics.EFFORT_NOMINAL, many_duplicates, 'duplicate'),
    '100 kB frame id': (topics.OBJECT_ODOM, huge_frame, 'frame'),
    '100 kB joint name': (topics.JOINT_STATES, huge_name, 'missing'),
}


@pytest.mark.parametrize('case', list(HUGE_INPUTS))
def test_rejection_reports_are_bounded_and_not_carried_on_at_full_size(params, case):
    topic, mutate, match = HUGE_INPUTS[case]
    sim, safety_filter, _, (joints, odometry, effort_nominal) = filter_after_one_good_tick(params)
    dt = sim.config.time_step
    inputs = dict(
        zip(filter_handlers(safety_filter), (joints, odometry, effort_nominal), strict=True)
    )
    bad = mutate(restamp(through_cdr(inputs[topic]), dt))
    (report,) = statuses(filter_handlers(safety_filter)[topic](bad), 'safety_filter')
    assert match in report.message
    assert len(report.message) <= m.MAX_REPORT_TEXT
    assert len(report.values[Key.INPUT_LAST_REJECTION]) <= m.MAX_REPORT_TEXT
    outgoing = []
    for other, handler in filter_handlers(safety_filter).items():
        outgoing += handler(restamp(through_cdr(inputs[other]), 2 * dt))
    (diagnostics,) = [o.msg for o in outgoing if o.topic == topics.DIAGNOSTICS]
    assert len(TYPESTORE.serialize_cdr(diagnostics, diagnostics.__msgtype__)) < 8_000
    if topic != topics.OBJECT_ODOM:
        # The nominal controller and the simulator bound their reports too.
        nominal = make_nominal(params)
        handler = nominal.on_joint_states if topic == topics.JOINT_STATES else None
        started = make_sim(params)
        started.start()
        command = mutate(m.effort_to_msg(MSGS, 0.0, sim.model.joint_names, np.zeros(9)))
        reports = statuses(started.on_command(command), 'hand_sim')
        if handler is not None:
            reports += statuses(handler(mutate(through_cdr(joints))), 'nominal_controller')
        for other in reports:
            assert len(other.message) <= m.MAX_REPORT_TEXT


@pytest.mark.parametrize(
    ('over', 'clipped'),
    [
        ({}, []),
        ({0: 1e6}, [0]),
        ({2: -1e6, 5: 1e3}, [2, 5]),
    ],
)
def test_simulator_clips_commands_to_the_effort_limits_and_warns(params, over, clipped):
    sim = make_sim(params)
    sim.start()
    names, limits = sim.model.joint_names, sim.model.effort_limits
    u = 0.5 * limits
    for i, value in over.items():
        u[i] = value
    command = m.effort_to_msg(MSGS, 0.0, names, u)
    outgoing = sim.on_command(command)
    reference = make_sim(params)
    reference.start()
    expected = np.clip(u, -limits, limits)
    reference_out = reference.on_command(m.effort_to_msg(MSGS, 0.0, names, expected))
    applied = m.joint_state_from_msg(
        next(o.msg for o in outgoing if o.topic == topics.JOINT_STATES), names
    ).effort
    np.testing.assert_array_equal(applied, expected)

    def cdr(messages):
        return [bytes(TYPESTORE.serialize_cdr(o.msg, o.msg.__msgtype__)) for o in messages]

    assert cdr(o for o in outgoing if o.topic != topics.DIAGNOSTICS) == cdr(reference_out)
    reports = statuses(outgoing, 'hand_sim')
    if not clipped:
        assert reports == []
        return
    (report,) = reports
    assert report.level is DiagnosticLevel.WARN
    assert report.values['effort.clipped'] == ','.join(names[i] for i in clipped)
    for i in clipped:
        excess = abs(u[i]) - limits[i]
        assert float(report.values[f'effort.excess.{names[i]}']) == pytest.approx(excess)
    assert float(report.values['effort.max_excess']) == pytest.approx(
        max(abs(u[i]) - limits[i] for i in clipped)
    )
