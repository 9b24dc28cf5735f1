"""The controllers check the grasp they receive: at start-up until one passes, then each tick.

In process, on the endpoint cores: a state that is not a grasp gets no QP solve, the hold
policy's command and an ERROR naming the contact; the log says so once; a valid state
starts (or resumes) filtering. The states are the paper's initial grasp with one contact
made wrong, each case built from the geometry (a shifted object pose, a finger moved onto
the object with GraspModel.project_to_contact), not from our own output.
"""

from __future__ import annotations

from dataclasses import dataclass
import math
from pathlib import Path
from typing import Any

from counting_filter import CountingFilter
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.control.hold_policy import InputPolicyConfig
from grasp_safety_filter.control.nominal import NominalConfig
from grasp_safety_filter.control.safety_filter import SafetyFilterConfig
from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.diagnostic_keys import (
    FILTER_DIAGNOSTIC,
    GRASP_STATUSES,
    Key,
    NOMINAL_DIAGNOSTIC,
    TickStatus,
)
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import (
    GRASP_CHECK_GAP_TOLERANCE,
    load_node_parameters,
    NOMINAL_CONTROLLER_NODE,
    SAFETY_FILTER_NODE,
)
from grasp_safety_filter.model.grasp_check import GAP_TOLERANCE, GraspFinding
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.grasp_watch import (
    contact_gap_findings,
    findings_text,
    GAP_TOLERANCE_PARAMETER,
    GraspCheckConfig,
)
from grasp_safety_filter.nodes.nominal_controller import NominalControllerEndpoint
from grasp_safety_filter.nodes.safety_filter import SafetyFilterEndpoint
from grasp_safety_filter.nodes.startup_log import PREFIX as ADVICE_PREFIX
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
MSGS = m.MessageNamespace.from_typestore(get_typestore(Stores.ROS2_JAZZY))
NODES = ('hand_sim_node', NOMINAL_CONTROLLER_NODE, SAFETY_FILTER_NODE)
DT = 0.001
#: finger3 touches the cube's +y face; fingers 1 and 2 the -x and +x faces.
FINGER3 = "contact 'finger3'"


def _grasp_log(endpoint):
    """Return the endpoint's log lines but its start-up advice (logged at its first tick)."""
    return [line for line in endpoint.take_log() if not line.text.startswith(ADVICE_PREFIX)]


@pytest.fixture(scope='module')
def params():
    return {node: load_node_parameters(CONFIG, node) for node in NODES}


@dataclass(frozen=True)
class Inputs:
    """One tick's state as the controllers receive it."""

    q: np.ndarray
    p_object: np.ndarray
    R_object: np.ndarray

    def messages(self, names: list[str], t: float, u_nom: np.ndarray) -> dict[str, Any]:
        zeros = np.zeros(len(names))
        return {
            topics.JOINT_STATES: m.joint_state_to_msg(MSGS, t, names, self.q, zeros, zeros),
            topics.OBJECT_ODOM: m.odometry_to_msg(
                MSGS, t, self.p_object, self.R_object, np.zeros(6)
            ),
            topics.EFFORT_NOMINAL: m.effort_to_msg(MSGS, t, names, u_nom),
        }


def paper_inputs(params) -> Inputs:
    sim_params = params['hand_sim_node']
    sim = HandSimEndpoint(
        GraspModel.from_parameters(sim_params), SimConfig.from_parameters(sim_params), MSGS
    )
    state = {o.topic: o.msg for o in sim.start()}
    names = list(sim.model.joint_names)
    joints = m.joint_state_from_msg(state[topics.JOINT_STATES], names)
    odometry = m.odometry_from_msg(state[topics.OBJECT_ODOM])
    return Inputs(joints.position, odometry.p_object_in_palm, odometry.R_object_to_palm)


def shifted(inputs: Inputs, dy: float, model: GraspModel) -> Inputs:
    """Move the object dy (m) along y: finger3 gets a gap (dy < 0) or penetrates; 1, 2 slide."""
    return Inputs(inputs.q, inputs.p_object + np.array([0.0, dy, 0.0]), inputs.R_object)


def finger3_moved(inputs: Inputs, joint: int, delta: float, model: GraspModel) -> Inputs:
    """finger3's joint moved by delta (rad), then brought back onto the object."""
    q = inputs.q.copy()
    q[6 + joint] += delta
    q = model.project_to_contact(q, inputs.p_object, inputs.R_object)
    return Inputs(q, inputs.p_object, inputs.R_object)


#: name, how the state is made wrong, model overrides, what the finding on finger3 says.
BAD_FIRST_STATES = [
    ('gap 5 mm', lambda i, mo: shifted(i, -0.005, mo), {}, 'separated from the object by 0.005 m'),
    (
        'penetration 5 mm',
        lambda i, mo: shifted(i, 0.005, mo),
        {},
        'penetrates the object by 0.005 m',
    ),
    # joint1 turns the finger about the palm normal: its tip slides off the face's edge.
    ('off its face', lambda i, mo: finger3_moved(i, 0, 0.5, mo), {}, 'beyond the edge of face +y'),
    # joint3 tilts the distal link: the contact moves to a < -0.3 rad on the fingertip.
    (
        'outside the fingertip workspace',
        lambda i, mo: finger3_moved(i, 2, -0.5, mo),
        {'model.fingertip_workspace.a_min': -0.3},
        'outside its fingertip workspace',
    ),
]


def make_filter(params, enabled=True, **overrides) -> SafetyFilterEndpoint:
    values = {**params[SAFETY_FILTER_NODE], **overrides}
    endpoint = SafetyFilterEndpoint(
        GraspModel.from_parameters(values),
        SafetyFilterConfig.from_parameters(values),
        InputPolicyConfig.from_parameters(values),
        MSGS,
        enabled=enabled,
        grasp_check_config=GraspCheckConfig.from_parameters(values),
    )
    endpoint.filter = CountingFilter(endpoint.filter)
    return endpoint


def make_nominal(params, **overrides) -> NominalControllerEndpoint:
    values = {**params[NOMINAL_CONTROLLER_NODE], **overrides}
    return NominalControllerEndpoint(
        GraspModel.from_parameters(values),
        NominalConfig.from_parameters(values),
        MSGS,
        GraspCheckConfig.from_parameters(values),
    )


def tick(endpoint: SafetyFilterEndpoint, inputs: Inputs, t: float, u_nom: np.ndarray):
    """Deliver one tick's three inputs at node clock t; return the filter's answer."""
    names = list(endpoint.model.joint_names)
    messages = inputs.messages(names, t, u_nom)
    assert endpoint.on_joint_states(messages[topics.JOINT_STATES], now=t) == []
    assert endpoint.on_odom(messages[topics.OBJECT_ODOM], now=t) == []
    return endpoint.on_effort_nominal(messages[topics.EFFORT_NOMINAL], now=t)


def answer(outgoing, names):
    """Return (command, status report) of a tick's answer."""
    commands = [o.msg for o in outgoing if o.topic == topics.EFFORT_COMMAND]
    reports = [
        report
        for o in outgoing
        if o.topic == topics.DIAGNOSTICS
        for report in m.diagnostics_from_msg(o.msg).reports
    ]
    (command,) = commands
    (report,) = reports
    return m.effort_from_msg(command, names).effort, report


def gravity_fallback(model: GraspModel, q: np.ndarray) -> np.ndarray:
    """g(q) from the state's own terms, clipped to the actuator limits, N·m."""
    state = model.state(0.0, q, np.zeros_like(q), np.zeros(3), np.eye(3), np.zeros(6))
    limits = np.asarray(model.effort_limits)
    return np.clip(state.gravity_torque, -limits, limits)


U_NOM = np.linspace(-0.2, 0.2, 9)


@pytest.mark.parametrize(
    ('make_bad', 'overrides', 'problem'),
    [case[1:] for case in BAD_FIRST_STATES],
    ids=[case[0] for case in BAD_FIRST_STATES],
)
def test_a_bad_first_state_gets_the_fallback_and_an_error_naming_the_contact(
    params, make_bad, overrides, problem
):
    good = paper_inputs(params)
    safety_filter = make_filter(params, **overrides)
    model = safety_filter.model
    bad = make_bad(good, model)
    names = list(model.joint_names)
    t0 = 1.0
    for k in range(3):  # the same answer while the grasp stays wrong, logged once
        u, report = answer(tick(safety_filter, bad, t0 + k * DT, U_NOM), names)
        assert safety_filter.filter.calls == 0  # no QP solve
        assert report.name == FILTER_DIAGNOSTIC
        assert report.level is m.DiagnosticLevel.ERROR
        assert report.values[Key.STATUS] == TickStatus.GRASP_INVALID.value
        assert report.values[Key.GRASP_VALID] == 'false'
        assert report.values[Key.GRASP_CONTACTS] == FINGER3
        assert FINGER3 in report.message and problem in report.message
        assert 'finger1' not in report.message and 'finger2' not in report.message
        assert len(report.message) <= m.MAX_REPORT_TEXT
        # The documented fallback (gravity compensation at the received q): nothing held.
        np.testing.assert_allclose(u, gravity_fallback(model, bad.q), rtol=1e-12, atol=1e-12)
        log = _grasp_log(safety_filter)
        if k == 0:
            ((level, text),) = log
            assert level is m.DiagnosticLevel.ERROR
            assert FINGER3 in text and problem in text
        else:
            assert log == []
    # A valid state: filtering starts, one INFO line.
    t1 = t0 + 3 * DT
    u, report = answer(tick(safety_filter, good, t1, U_NOM), names)
    assert safety_filter.filter.calls == 1
    assert report.level is not m.DiagnosticLevel.ERROR
    assert report.values[Key.STATUS] not in {s.value for s in GRASP_STATUSES}
    ((level, text),) = _grasp_log(safety_filter)
    assert level is m.DiagnosticLevel.OK and 'valid grasp' in text
    # The same u* as a filter whose first state was that valid one.
    fresh = make_filter(params, **overrides)
    expected, _ = answer(tick(fresh, good, t1, U_NOM), names)
    np.testing.assert_allclose(u, expected, rtol=0, atol=1e-12)


def test_a_contact_that_opens_at_run_time_is_held_then_falls_back_then_resumes(params):
    good = paper_inputs(params)
    safety_filter = make_filter(params)
    model = safety_filter.model
    names = list(model.joint_names)
    hold_timeout = safety_filter.hold.hold_timeout
    gap = shifted(good, -0.003, model)  # finger3 leaves the face by 3 mm
    t = 1.0
    safe, report = answer(tick(safety_filter, good, t, U_NOM), names)
    assert report.values[Key.STATUS] not in {s.value for s in GRASP_STATUSES}
    _grasp_log(safety_filter)
    solves = safety_filter.filter.calls

    # Within the hold timeout: the last safe u*, ERROR naming the contact and its gap.
    t += DT
    u, report = answer(tick(safety_filter, gap, t, U_NOM), names)
    assert safety_filter.filter.calls == solves
    assert report.level is m.DiagnosticLevel.ERROR
    assert report.values[Key.STATUS] == TickStatus.GRASP_HELD.value
    assert report.values[Key.GRASP_CONTACTS] == FINGER3
    assert f'{FINGER3}: gap 3.0 mm > 1.0 mm tolerance' in report.message
    np.testing.assert_array_equal(u, safe)
    ((level, text),) = _grasp_log(safety_filter)
    assert level is m.DiagnosticLevel.ERROR and 'gap 3.0 mm' in text

    # Past it: the fallback, still ERROR, not logged again.
    t += 1.5 * hold_timeout
    u, report = answer(tick(safety_filter, gap, t, U_NOM), names)
    assert safety_filter.filter.calls == solves
    assert report.values[Key.STATUS] == TickStatus.GRASP_FALLBACK.value
    assert report.level is m.DiagnosticLevel.ERROR
    np.testing.assert_allclose(u, gravity_fallback(model, gap.q), rtol=1e-12, atol=1e-12)
    assert _grasp_log(safety_filter) == []

    # The contact is back: filtering resumes, logged once at INFO.
    t += DT
    u, report = answer(tick(safety_filter, good, t, U_NOM), names)
    assert safety_filter.filter.calls == solves + 1
    assert report.values[Key.STATUS] not in {s.value for s in GRASP_STATUSES}
    ((level, text),) = _grasp_log(safety_filter)
    assert level is m.DiagnosticLevel.OK and 'contacts back' in text


@pytest.mark.parametrize('enabled', [True, False], ids=['filtered', 'off'])
def test_the_grasp_is_checked_with_the_filter_off_too(params, enabled):
    good = paper_inputs(params)
    safety_filter = make_filter(params, enabled=enabled)
    bad = shifted(good, -0.005, safety_filter.model)
    _, report = answer(tick(safety_filter, bad, 1.0, U_NOM), list(safety_filter.model.joint_names))
    assert report.values[Key.STATUS] == TickStatus.GRASP_INVALID.value


@pytest.mark.parametrize(
    ('tolerance', 'flagged'), [(0.0051, False), (0.0049, True)], ids=['above', 'below']
)
def test_the_gap_tolerance_is_a_parameter(params, tolerance, flagged):
    good = paper_inputs(params)
    safety_filter = make_filter(params, **{GAP_TOLERANCE_PARAMETER: tolerance})
    bad = shifted(good, -0.005, safety_filter.model)
    _, report = answer(tick(safety_filter, bad, 1.0, U_NOM), list(safety_filter.model.joint_names))
    assert (report.values[Key.STATUS] == TickStatus.GRASP_INVALID.value) is flagged


def test_the_nominal_controller_holds_gravity_and_waits_for_a_valid_grasp(params):
    good = paper_inputs(params)
    nominal = make_nominal(params)
    model = nominal.model
    names = list(model.joint_names)
    bad = shifted(good, 0.005, model)
    t0 = 1.0
    messages = bad.messages(names, t0, U_NOM)
    assert nominal.on_joint_states(messages[topics.JOINT_STATES]) == []
    outgoing = nominal.on_odom(messages[topics.OBJECT_ODOM])
    efforts = [o.msg for o in outgoing if o.topic == topics.EFFORT_NOMINAL]
    (report,) = [
        r
        for o in outgoing
        if o.topic == topics.DIAGNOSTICS
        for r in m.diagnostics_from_msg(o.msg).reports
    ]
    assert report.name == NOMINAL_DIAGNOSTIC
    assert report.level is m.DiagnosticLevel.ERROR
    assert FINGER3 in report.message and 'penetrates the object by 0.005 m' in report.message
    assert report.values[Key.GRASP_VALID] == 'false'
    (u_nom,) = [m.effort_from_msg(msg, names).effort for msg in efforts]
    state = model.state(t0, bad.q, np.zeros(9), bad.p_object, bad.R_object, np.zeros(6))
    np.testing.assert_allclose(u_nom, state.gravity_torque, rtol=1e-12, atol=1e-12)
    assert nominal.reference is None  # the planner's motion has not started
    ((level, _),) = nominal.take_log()
    assert level is m.DiagnosticLevel.ERROR

    # A valid state at t1: the same command as a controller that saw only that state.
    t1 = t0 + 0.25
    messages = good.messages(names, t1, U_NOM)
    nominal.on_joint_states(messages[topics.JOINT_STATES])
    effort, _reference_sample = nominal.on_odom(messages[topics.OBJECT_ODOM])
    fresh = make_nominal(params)
    fresh.on_joint_states(messages[topics.JOINT_STATES])
    expected, _reference_sample = fresh.on_odom(messages[topics.OBJECT_ODOM])
    np.testing.assert_array_equal(
        m.effort_from_msg(effort.msg, names).effort, m.effort_from_msg(expected.msg, names).effort
    )
    ((level, text),) = nominal.take_log()
    assert level is m.DiagnosticLevel.OK and 'valid grasp' in text


@pytest.mark.parametrize('value', [0.0, -1e-3, math.nan, math.inf, True, '0.001'])
def test_a_gap_tolerance_must_be_a_positive_finite_number(value):
    with pytest.raises(ConfigError, match=GAP_TOLERANCE_PARAMETER.replace('.', r'\.')):
        GraspCheckConfig(value)


@pytest.mark.parametrize('node', [NOMINAL_CONTROLLER_NODE, SAFETY_FILTER_NODE])
def test_the_parameter_defaults_to_the_start_up_tolerance_and_refuses_zero(node):
    assert GRASP_CHECK_GAP_TOLERANCE == GAP_TOLERANCE
    assert load_node_parameters(CONFIG, node)[GAP_TOLERANCE_PARAMETER] == GAP_TOLERANCE
    with pytest.raises(ParameterError, match=GAP_TOLERANCE_PARAMETER.replace('.', r'\.')):
        load_node_parameters(CONFIG, node, overrides={GAP_TOLERANCE_PARAMETER: 0.0})


@pytest.mark.parametrize(
    ('depth', 'found'),
    [
        (0.0, None),
        (-0.9e-3, None),
        (0.9e-3, None),
        (-1.1e-3, 'gap 1.1 mm'),
        (1.1e-3, 'penetration 1.1 mm'),
        (math.nan, 'finite'),
    ],
)
def test_the_run_time_check_counts_from_the_tolerance_either_way(depth, found):
    findings = contact_gap_findings(['a', 'b'], np.array([0.0, depth]), 1e-3)
    if found is None:
        assert findings == []
    else:
        (finding,) = findings
        assert finding.subject == "contact 'b'" and found in finding.problem


def test_a_report_of_many_contacts_stays_bounded():
    findings = [
        GraspFinding(f"contact 'c{i}'", 'gap 5.0 mm > 1.0 mm tolerance') for i in range(500)
    ]
    text = findings_text(findings)
    assert len(text) <= m.MAX_REPORT_TEXT and "contact 'c0'" in text
