"""The hand–object simulator: configuration, constraint events, stabilised dynamics, physics.

The physics tests run the paper's scenario (config/paper_scenario.yaml) and check invariants
of the exact dynamics: energy conservation of the unforced system, the contact constraint
holding over a long run, and the integrators' convergence order on the full plant.
"""

import dataclasses
import itertools
import math
from pathlib import Path

import numpy as np
import pytest

from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.quaternion import from_rotation_matrix
from hand_sim_node.config import flatten_parameters, SimConfig
from hand_sim_node.constraint_margins import (
    FAMILIES,
    FINGERTIP_WORKSPACE,
    JOINT_LIMITS,
    SEPARATION,
    SLIP,
)
from hand_sim_node.event_log import EventLog
from hand_sim_node.events import EventMonitor
from hand_sim_node.simulator import (
    contact_velocity_residual,
    NUMERICAL_FAILURE,
    SimState,
    Simulator,
)

SCENARIO = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'


@pytest.fixture(scope='module')
def scenario():
    model, params = GraspModel.from_parameter_file(SCENARIO)
    return model, params


@pytest.fixture(scope='module')
def model(scenario):
    return scenario[0]


@pytest.fixture(scope='module')
def config(scenario):
    return SimConfig.from_parameters(scenario[1])


@pytest.fixture(scope='module')
def weightless_model(scenario):
    params = {**scenario[1], 'model.gravity': [0.0, 0.0, 0.0]}
    return GraspModel.from_parameters(params, SCENARIO.parent)


def vee(S):
    return np.array([S[2, 1] - S[1, 2], S[0, 2] - S[2, 0], S[1, 0] - S[0, 1]]) / 2.0


def rotation_z(angle):
    c, s = math.cos(angle), math.sin(angle)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def squeeze_force(state, k_f):
    """Return the paper's internal force f_i = R_cp,i k_f (p_bar - p_c,i), contact frames."""
    p_c = state.p_contact_in_palm
    centroid = p_c.mean(axis=0)
    return np.concatenate(
        [state.R_contact_to_palm[i].T @ (k_f * (centroid - p_c[i])) for i in range(len(p_c))]
    )


def holding_torque(state, k_f):
    """Torque whose rolling contact forces are G^+ (-w_e) + squeeze, at rest."""
    f_desired = np.linalg.pinv(state.G) @ (-state.w_e) + squeeze_force(state, k_f)
    return state.h_bias + state.J_h.T @ f_desired, f_desired


class ObjectTracker:
    """Computed torque on the object's acceleration (from the model's affine map) + squeeze.

    u = u_0 + A^+ (x_o_ddot_des - A u_0 - b) with x_o_ddot(u) = A u + b and
    u_0 = h_bias + J_h^T f_squeeze; the reference moves the object up/down by ``amplitude``
    metres and turns it about the palm z axis by ``angle`` radians at ``frequency`` Hz.
    """

    def __init__(self, p_0, R_0, amplitude=0.01, angle=0.1, frequency=0.5, k_p=25.0, k_d=10.0):
        self.p_0, self.R_0 = p_0, R_0
        self.amplitude, self.angle = amplitude, angle
        self.omega = 2.0 * math.pi * frequency
        self.k_p, self.k_d = k_p, k_d

    def reference(self, t):
        s, c, w = math.sin(self.omega * t), math.cos(self.omega * t), self.omega
        z = np.array([0.0, 0.0, 1.0])
        p = self.p_0 + self.amplitude * s * z
        R = rotation_z(self.angle * s) @ self.R_0
        twist = np.concatenate((self.amplitude * w * c * z, self.angle * w * c * z))
        acceleration = -w * w * s * np.concatenate((self.amplitude * z, self.angle * z))
        return p, R, twist, acceleration

    def error(self, state, t):
        p, R, _, _ = self.reference(t)
        return np.concatenate((p - state.p_object_in_palm, vee(R @ state.R_object_to_palm.T)))

    def __call__(self, state, t):
        _, _, twist, acceleration = self.reference(t)
        desired = (
            acceleration
            + self.k_d * (twist - state.twist_object)
            + self.k_p * self.error(state, t)
        )
        u_0 = state.h_bias + state.J_h.T @ squeeze_force(state, 10.0)
        A, b = state.object_acceleration.matrix, state.object_acceleration.offset
        return u_0 + np.linalg.lstsq(A, desired - A @ u_0 - b, rcond=None)[0]


def rolling_start(model, config, twist_object):
    """Return the configured initial grasp, rolling with the object twist ``twist_object``."""
    simulator = Simulator(model, config)
    start = simulator.state
    dq = model.rolling_joint_velocity(
        start.q, start.p_object_in_palm, start.R_object_to_palm, twist_object
    )
    return SimState(
        0.0, start.q, dq, start.p_object_in_palm, start.quaternion_object, twist_object
    )


# --------------------------------------------------------------------------------- config
def test_config_from_scenario_file(config, scenario):
    params = scenario[1]
    np.testing.assert_array_equal(
        config.initial_joint_positions, params['initial.joint_positions']
    )
    np.testing.assert_array_equal(
        config.initial_object_position, params['initial.object_position']
    )
    assert config.integrator == params['integrator']
    assert config.time_step == params['time_step']
    assert config.position_gain == params['stabilization.position_gain']
    assert config.velocity_gain == params['stabilization.velocity_gain']
    assert config.n_steps == round(params['duration'] / params['time_step'])


def test_config_accepts_nested_parameters_and_ignores_other_nodes_parameters():
    nested = {
        'initial': {'joint_positions': [0.1, 0.2], 'object_position': [0.0, 0.0, 0.3]},
        'stabilization': {'position_gain': 100.0, 'velocity_gain': 20.0},
        'integrator': 'rk4',
        'model': {'fingertip_radius': 0.06},
    }
    assert flatten_parameters(nested)['stabilization.velocity_gain'] == 20.0
    config = SimConfig.from_parameters(nested)
    assert config.integrator == 'rk4'
    assert (config.position_gain, config.velocity_gain) == (100.0, 20.0)
    np.testing.assert_array_equal(config.initial_object_orientation, [0.0, 0.0, 0.0, 1.0])
    assert not config.initial_joint_positions.flags.writeable


BAD_CONFIGS = [
    ({'time_step': 0.0}, "parameter 'time_step': expected >= 1e-09"),
    ({'time_step': 1e-9, 'duration': 1e3}, "parameter 'duration': expected at most 1e\\+11 steps"),
    ({'time_step': 0.5, 'duration': 0.1}, "parameter 'time_step': expected <= duration"),
    ({'integrator': 'euler'}, "parameter 'integrator': expected one of"),
    ({'initial_object_position': (0.0, 0.3)}, "parameter 'initial.object_position'"),
    (
        {'initial_object_orientation': (0.0, 0.0, 0.5, 0.5)},
        "parameter 'initial.object_orientation': expected a unit quaternion",
    ),
    ({'initial_joint_positions': ()}, "parameter 'initial.joint_positions'"),
    ({'position_gain': -1.0}, "parameter 'stabilization.position_gain'"),
]


@pytest.mark.parametrize('change, message', BAD_CONFIGS, ids=[m for _, m in BAD_CONFIGS])
def test_config_rejects_bad_values_naming_the_parameter(change, message):
    values = {'initial_joint_positions': (0.1, 0.2), 'initial_object_position': (0, 0, 0.3)}
    with pytest.raises(ParameterError, match=message.replace('(', r'\(')):
        SimConfig(**{**values, **change})


def test_simulator_rejects_initial_joint_positions_of_the_wrong_length(model, config):
    bad = dataclasses.replace(config, initial_joint_positions=config.initial_joint_positions[:5])
    with pytest.raises(ValueError, match=r"'initial.joint_positions': expected 9 joint angles"):
        Simulator(model, bad)


# --------------------------------------------------------------------------------- events
def test_event_margins_and_violations_table(model, config):
    simulator = Simulator(model, config)
    state = simulator.grasp_state()
    monitor = EventMonitor.from_model(model)
    a_min, a_max, b_min, b_max = model.fingertip_workspace
    lower, upper = model.joint_lower_limits, model.joint_upper_limits
    mu = model.friction_coefficient

    xi = np.array([[a_max + 0.01, -1.0], [0.2, b_min - 0.02], [0.0, -1.5]])
    q = (lower + upper) / 2.0
    q[4] = upper[4] + 0.05
    q[6] = lower[6] - 0.1
    forces = np.array([[0.1, 0.0, -0.2], [0.3, 0.4, 0.5], [0.1, 0.1, 1.0]])  # beta_2 = 1.0
    changed = dataclasses.replace(state, t=0.25, xi_cf=xi, q=q)
    margins = monitor.margins(changed, forces.ravel())

    np.testing.assert_allclose(
        margins.fingertip_workspace[0],
        [xi[0, 0] - a_min, -0.01, xi[0, 1] - b_min, b_max - xi[0, 1]],
    )
    np.testing.assert_allclose(margins.joint_limits[4], [q[4] - lower[4], -0.05])
    np.testing.assert_allclose(margins.required_friction, [np.inf, 1.0, math.sqrt(0.02)])
    np.testing.assert_allclose(margins.friction, mu - margins.required_friction)
    np.testing.assert_allclose(margins.normal_force, [-0.2, 0.5, 1.0])

    found = {(e.family, e.index, e.side): e for e in monitor.events(margins)}
    expected = {
        (FINGERTIP_WORKSPACE, 0, 'a_max'): -0.01,
        (FINGERTIP_WORKSPACE, 1, 'b_min'): -0.02,
        (JOINT_LIMITS, 4, 'upper'): -0.05,
        (JOINT_LIMITS, 6, 'lower'): -0.1,
        (SLIP, 0, ''): -np.inf,
        (SLIP, 1, ''): mu - 1.0,
        (SEPARATION, 0, ''): -0.2,
    }
    assert set(found) == set(expected)
    for key, margin in expected.items():
        assert found[key].margin == pytest.approx(margin)
        assert found[key].t == 0.25
    assert found[(JOINT_LIMITS, 6, 'lower')].name == model.joint_names[6]
    assert found[(SLIP, 1, '')].name == model.contact_names[1]


def test_event_log_counts_steps_first_times_onsets_and_worst_margins(model, config):
    simulator = Simulator(model, config)
    state = simulator.grasp_state()
    monitor = EventMonitor.from_model(model)
    log = EventLog()
    upper = model.joint_upper_limits
    safe = np.array([0.0, 0.0, 1.0] * 3)  # beta = 0
    # Joint 2 over its limit at t = 0.1, 0.2 and again at 0.4; contact 1 separates at 0.3.
    samples = [
        (0.0, 0.0, safe),
        (0.1, 0.02, safe),
        (0.2, 0.03, safe),
        (0.3, -0.01, np.array([0.0, 0.0, 1.0, 0.5, 0.0, -0.1, 0.0, 0.0, 1.0])),
        (0.4, 0.01, safe),
    ]
    for t, excess, forces in samples:
        q = state.q.copy()
        q[2] = upper[2] + excess
        margins = monitor.margins(dataclasses.replace(state, t=t, q=q), forces)
        log.record(margins, monitor.events(margins))

    violations = log.violations()
    assert set(violations) == set(FAMILIES)
    assert violations[JOINT_LIMITS] == {'count': 3, 'first_t': 0.1}
    assert violations[SEPARATION] == {'count': 1, 'first_t': 0.3}
    assert violations[SLIP] == {'count': 1, 'first_t': 0.3}
    assert violations[FINGERTIP_WORKSPACE] == {'count': 0, 'first_t': None}
    onsets = [(e.t, e.family, e.index) for e in log.onsets]
    assert onsets == [
        (0.1, JOINT_LIMITS, 2),
        (0.3, SLIP, 1),
        (0.3, SEPARATION, 1),
        (0.4, JOINT_LIMITS, 2),
    ]
    minimum = log.min_margin()
    assert minimum[JOINT_LIMITS] == pytest.approx(-0.03)
    assert minimum['friction'] == -np.inf
    assert minimum[FINGERTIP_WORKSPACE] == pytest.approx(
        np.min(model.fingertip_workspace.margins(state.xi_cf))
    )
    assert log.max_required_friction == np.inf
    assert log.n_evaluations == len(samples)


# ------------------------------------------------------------------------ simulator basics
def test_reset_projects_onto_the_contacts_at_rest(model, config):
    # Start from joint angles off the contact manifold: reset must put the tips on the faces.
    perturbed = dataclasses.replace(
        config, initial_joint_positions=config.initial_joint_positions + 0.02
    )
    simulator = Simulator(model, perturbed)
    state = simulator.grasp_state()
    np.testing.assert_allclose(state.penetration, 0.0, atol=1e-12)
    np.testing.assert_array_equal(state.dq, 0.0)
    np.testing.assert_array_equal(state.twist_object, 0.0)
    assert simulator.t == 0.0 and simulator.step_index == 0 and simulator.stop_reason is None
    assert simulator.grasp_state() is state  # computed once per state


def test_sim_state_vector_round_trip():
    rng = np.random.default_rng(3)
    quaternion = rng.normal(size=4)
    state = SimState(
        0.5,
        rng.normal(size=9),
        rng.normal(size=9),
        rng.normal(size=3),
        quaternion / np.linalg.norm(quaternion),
        rng.normal(size=6),
    )
    back = SimState.from_vector(0.5, state.to_vector(), 9)
    for name in ('q', 'dq', 'p_object_in_palm', 'quaternion_object', 'twist_object'):
        np.testing.assert_array_equal(getattr(back, name), getattr(state, name))
    assert not back.q.flags.writeable


class CountingModel:
    """The model, counting its full-state evaluations (their times)."""

    def __init__(self, model):
        self.calls = []
        self._model = model

    def __getattr__(self, name):
        return getattr(self._model, name)

    def state(self, *args):
        self.calls.append(args[0])
        return self._model.state(*args)


@pytest.mark.parametrize('integrator, stages', [('ode3', 3), ('rk4', 4)])
def test_the_controllers_state_is_the_first_stage(model, config, integrator, stages):
    # The controller's state is the first stage, not evaluated again; each other stage
    # evaluates the model once at its configuration (time 0: the rate does not depend on t).
    u, _ = holding_torque(Simulator(model, config).grasp_state(), 10.0)
    counting = CountingModel(model)
    simulator = Simulator(counting, dataclasses.replace(config, integrator=integrator))
    rates = []
    at = simulator._rate.at
    simulator._rate.at = lambda x, *args: rates.append(x) or at(x, *args)
    for _ in range(5):
        simulator.grasp_state()  # what a controller reads before computing u
        simulator.step(u)
    dt = config.time_step
    assert len(counting.calls) == 5 * stages
    np.testing.assert_allclose(
        counting.calls[::stages], [k * dt for k in range(5)], rtol=0, atol=1e-15
    )
    assert len(rates) == 5 * (stages - 1)


def test_given_first_stage_state_replaces_the_simulators_own(model, config):
    counting = CountingModel(model)
    simulator = Simulator(counting, config)
    plain = Simulator(model, config)
    u, _ = holding_torque(plain.grasp_state(), 10.0)
    u = u + np.linspace(-0.05, 0.05, 9)  # the object moves
    for _ in range(4):
        s = simulator.state
        built = model.state(s.t, s.q, s.dq, s.p_object_in_palm, s.R_object_to_palm, s.twist_object)
        report = simulator.step(u, state=built)
        expected = plain.step(u)
        assert report.grasp_state is built
        np.testing.assert_array_equal(report.state.to_vector(), expected.state.to_vector())
        np.testing.assert_array_equal(report.contact_force, expected.contact_force)
    # Never evaluated its own first stage: only the other stages', one each.
    assert len(counting.calls) == 4 * (len(simulator._tableau.c) - 1)
    assert simulator.state.p_object_in_palm[2] != config.initial_object_position[2]


def _shifted(s, name):
    """Return ``s`` with one field changed by the smallest step a float allows.

    The orientation turns by 1e-12 rad instead (one ulp of a quaternion component may
    round away in its rotation matrix).
    """
    if name == 't':
        return dataclasses.replace(s, t=np.nextafter(s.t, 1.0))
    value = np.array(getattr(s, name))
    if name == 'quaternion_object':
        value[0] += 0.5e-12
        return dataclasses.replace(s, quaternion_object=value / np.linalg.norm(value))
    value.flat[-1] = np.nextafter(value.flat[-1], np.inf)
    return dataclasses.replace(s, **{name: value})


@pytest.mark.parametrize(
    'name', ['t', 'q', 'dq', 'p_object_in_palm', 'quaternion_object', 'twist_object']
)
def test_given_first_stage_state_of_another_state_is_refused(model, config, name):
    simulator = Simulator(model, config)
    u, _ = holding_torque(simulator.grasp_state(), 10.0)
    simulator.step(u)
    other = _shifted(simulator.state, name)
    built = model.state(
        other.t,
        other.q,
        other.dq,
        other.p_object_in_palm,
        other.R_object_to_palm,
        other.twist_object,
    )
    start = simulator.state
    differing = 'R_object_to_palm' if name == 'quaternion_object' else name
    with pytest.raises(ValueError, match=f'not the current state.*{differing}'):
        simulator.step(u, state=built)
    assert simulator.state is start and simulator.step_index == 1  # nothing integrated
    assert simulator.log.n_evaluations == 1
    simulator.step(u)  # the run goes on with its own state


def test_time_is_step_count_times_step(model, config):
    simulator = Simulator(model, dataclasses.replace(config, time_step=0.003))
    u, _ = holding_torque(simulator.grasp_state(), 10.0)
    for _ in range(7):
        simulator.step(u)
    assert simulator.t == 7 * 0.003
    assert simulator.step_index == 7


@pytest.mark.parametrize('effort', [np.zeros(8), np.full(9, np.nan)], ids=['shape', 'nan'])
def test_step_rejects_bad_effort(model, config, effort):
    simulator = Simulator(model, config)
    with pytest.raises(ValueError, match='expected 9 finite joint torques'):
        simulator.step(effort)


@pytest.mark.parametrize('k_f, slips', [(10.0, False), (0.01, True)])
def test_static_hold_forces_and_slip_stop(model, config, k_f, slips):
    # At rest with u = h_bias + J_h^T f_d and G f_d = -w_e, the rolling contact force is f_d:
    # the object stays put. A weak squeeze needs beta > mu to carry the weight.
    simulator = Simulator(model, dataclasses.replace(config, stop_on_slip=True))
    u, f_desired = holding_torque(simulator.grasp_state(), k_f)
    report = simulator.step(u)
    np.testing.assert_allclose(report.contact_force, f_desired, atol=1e-9)
    beta = np.hypot(f_desired[0::3], f_desired[1::3]) / f_desired[2::3]
    np.testing.assert_allclose(report.margins.required_friction, beta, rtol=1e-9, atol=1e-9)
    assert (report.stop_reason == SLIP) is slips
    assert (SLIP in {event.family for event in report.events}) is slips
    if slips:
        assert report.state is report.start and simulator.step_index == 0
        with pytest.raises(RuntimeError, match='the run stopped'):
            simulator.step(u)
    else:
        for _ in range(20):
            report = simulator.step(u)
        np.testing.assert_allclose(report.state.q, report.start.q, atol=1e-12)
        np.testing.assert_allclose(
            report.state.p_object_in_palm, config.initial_object_position, atol=1e-12
        )


def test_unactuated_hand_drops_the_object_and_stops_on_workspace_exit(model, config):
    simulator = Simulator(model, config)
    for _ in range(2000):
        report = simulator.step(np.zeros(model.n_joints))
        if report.stop_reason is not None:
            break
    assert report.stop_reason == FINGERTIP_WORKSPACE
    assert report.state is report.start  # the exit instant is the last state
    violations = simulator.log.violations()
    assert violations[FINGERTIP_WORKSPACE] == {'count': 1, 'first_t': report.start.t}
    assert simulator.log.min_margin()[FINGERTIP_WORKSPACE] <= 0.0
    exits = [e for e in report.events if e.family == FINGERTIP_WORKSPACE]
    assert exits and all(e.margin <= 0.0 for e in exits)
    assert report.start.t < 1.0


def test_numerical_failure_stops_instead_of_raising(model, config):
    simulator = Simulator(model, config)
    start = simulator.state
    # Absurd velocities overflow the dynamics: the step must stop, not raise or return NaN.
    broken = SimState(
        0.0,
        start.q,
        np.full(9, 1e200),
        start.p_object_in_palm,
        start.quaternion_object,
        np.full(6, 1e200),
    )
    simulator.reset(broken)
    with np.errstate(all='ignore'):
        report = simulator.step(np.zeros(9))
    assert report.stop_reason == NUMERICAL_FAILURE
    assert report.state is report.start


# ------------------------------------------------------------------- stabilised dynamics
def test_without_stabilisation_the_rates_are_the_models_affine_maps(model, config):
    simulator = Simulator(model, dataclasses.replace(config, position_gain=0.0, velocity_gain=0.0))
    rng = np.random.default_rng(5)
    simulator.reset(rolling_start(model, config, rng.normal(0.0, 0.2, 6)))
    state = simulator.grasp_state()
    u = rng.normal(0.0, 0.5, 9)
    x_dot, f_c = simulator.derivative(state, u, simulator.state.quaternion_object)
    np.testing.assert_allclose(f_c, state.contact_force(u), rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(x_dot[9:18], state.joint_acceleration(u), rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(x_dot[25:31], state.object_acceleration(u), rtol=1e-9, atol=1e-9)


def test_stabilisation_makes_the_residual_decay_as_designed(model, config):
    # Off the constraint (tips 0.1 mm into the faces, velocities that do not roll), the
    # residual must obey e_dot = -K_v e - K_p [0, 0, delta] and delta_dot = e_n, with the
    # rates taken by finite differences of e(x) and delta(x) along the simulated x_dot.
    simulator = Simulator(model, config)
    rng = np.random.default_rng(11)
    start = simulator.state
    R = start.R_object_to_palm
    q = model.project_to_contact(start.q, start.p_object_in_palm, R)
    # Move the object 0.1 mm away from finger 3 (+y face): a gap at contact 3.
    p_shifted = start.p_object_in_palm + np.array([0.0, 1e-4, 0.0])
    off = SimState(
        0.0,
        q,
        rng.normal(0.0, 0.3, 9),
        p_shifted,
        start.quaternion_object,
        rng.normal(0.0, 0.1, 6),
    )
    simulator.reset(off)
    state = simulator.grasp_state()
    assert np.max(np.abs(state.penetration)) > 5e-5
    e = contact_velocity_residual(state)
    assert np.max(np.abs(e)) > 1e-2
    u = rng.normal(0.0, 0.5, 9)
    x = off.to_vector()
    x_dot, _ = simulator.derivative(state, u, off.quaternion_object)

    def at(h):
        moved = SimState.from_vector(h, x + h * x_dot, 9)
        return model.state(
            h,
            moved.q,
            moved.dq,
            moved.p_object_in_palm,
            moved.R_object_to_palm,
            moved.twist_object,
        )

    h = 1e-6
    plus, minus = at(h), at(-h)
    e_dot = (contact_velocity_residual(plus) - contact_velocity_residual(minus)) / (2 * h)
    delta_dot = (plus.penetration - minus.penetration) / (2 * h)
    expected = -config.velocity_gain * e
    expected[2::3] -= config.position_gain * state.penetration
    np.testing.assert_allclose(delta_dot, e[2::3], rtol=1e-5, atol=1e-8)
    np.testing.assert_allclose(e_dot, expected, rtol=1e-4, atol=1e-4 * np.abs(expected).max())


# ----------------------------------------------------------------------------- physics
def unactuated_run(model, config, time_step, duration, *quantities):
    """Return drift, E(0) and the peak of each ``quantity(state)`` of an unactuated run.

    The drift is the largest |E(t) - E(0)| of the plant under u = 0 (ode3, no stabilisation).
    """
    plain = dataclasses.replace(
        config,
        integrator='ode3',
        time_step=time_step,
        position_gain=0.0,
        velocity_gain=0.0,
        stop_on_workspace_exit=False,
    )
    simulator = Simulator(model, plain)
    energy_0 = model.total_energy(simulator.grasp_state())
    drift, peaks = 0.0, [0.0] * len(quantities)
    for _ in range(round(duration / time_step)):
        simulator.step(np.zeros(model.n_joints))
        state = simulator.grasp_state()
        drift = max(drift, abs(model.total_energy(state) - energy_0))
        peaks = [max(p, q(state)) for p, q in zip(peaks, quantities, strict=True)]
    assert simulator.stop_reason is None and simulator.t == pytest.approx(duration)
    return drift, energy_0, peaks


def hand_kinetic_energy(state):
    """``dq^T M_h dq / 2``, J."""
    return 0.5 * state.dq @ state.M_h @ state.dq


def energy_drift(model, config, time_step, duration=2.0):
    """Largest |E(t) - E(0)| of the unactuated plant (u = 0, ode3, no stabilisation), and E(0)."""
    drift, energy_0, (kinetic_peak,) = unactuated_run(
        model, config, time_step, duration, hand_kinetic_energy
    )
    assert kinetic_peak > abs(energy_0)  # the system really moved
    return drift, energy_0


def test_energy_of_the_unactuated_hand_is_conserved_to_integrator_accuracy(model, config):
    # u = 0, gravity, no damping, 2 s, ode3. The hand collapses under gravity with the object
    # rolling on the fingertips (the plant's contact is bilateral; separation is only
    # flagged); joint speeds reach ~60 rad/s and J_h comes close to singular (condition
    # number ~500), so at 1 ms the drift is ~3e-4 of E(0), above a 1e-4 tolerance. The test
    # shows that the drift is the integrator's (third order: halving the step divides it by
    # ~8, so rolling contact does no work) and meets 1e-4 at 0.5 ms. The stabilisation is
    # off: it vanishes on the exact solution and would only add its own integration error.
    drift_coarse, energy_0 = energy_drift(model, config, 0.001)
    drift_fine, _ = energy_drift(model, config, 0.0005)
    assert 6.0 < drift_coarse / drift_fine < 10.5, (drift_coarse, drift_fine)
    assert drift_fine <= 1e-4 * abs(energy_0), drift_fine / abs(energy_0)


def test_contact_constraint_holds_over_a_fifteen_second_manipulation(model, config):
    # The configured plant (ode3, 1 ms, the scenario's stabilisation) under a holding
    # controller tracking 1 cm / 0.1 rad: gap <= 1e-6 m and rolling residual <= 1e-6 m/s
    # at every step, and no grasp constraint is violated.
    assert config.time_step == 0.001 and config.integrator == 'ode3'
    simulator = Simulator(model, dataclasses.replace(config, duration=15.0))
    start = simulator.state
    controller = ObjectTracker(start.p_object_in_palm, start.R_object_to_palm)
    max_gap = max_residual = 0.0
    xi_0 = simulator.grasp_state().xi_cf.copy()
    xi_travel = 0.0
    errors = []
    for k in range(simulator.config.n_steps):
        state = simulator.grasp_state()
        max_gap = max(max_gap, np.max(np.abs(state.penetration)))
        max_residual = max(max_residual, np.max(np.abs(contact_velocity_residual(state))))
        xi_travel = max(xi_travel, np.max(np.abs(state.xi_cf - xi_0)))
        if k % 100 == 0:
            errors.append(np.max(np.abs(controller.error(state, simulator.t))))
        report = simulator.step(controller(state, simulator.t))
        assert report.stop_reason is None
    assert simulator.t == pytest.approx(15.0)
    assert xi_travel > 0.01  # the contacts really rolled
    assert max_gap <= 1e-6
    assert max_residual <= 1e-6
    assert max(errors[-20:]) < 0.1 * max(errors[:5])  # tracking error decays
    assert all(record['count'] == 0 for record in simulator.log.violations().values())


@pytest.fixture(scope='module')
def coasting(weightless_model, config):
    """Return a free rolling motion (no gravity, no torque) and its solution at t = 1 s."""
    twist = np.array([0.02, -0.03, 0.05, 0.2, 0.1, 0.5])
    start = rolling_start(weightless_model, config, twist)

    def solve(integrator, dt):
        simulator = Simulator(
            weightless_model,
            dataclasses.replace(
                config, integrator=integrator, time_step=dt, stop_on_workspace_exit=False
            ),
        )
        simulator.reset(start)
        for _ in range(round(1.0 / dt)):
            simulator.step(np.zeros(weightless_model.n_joints))
        assert simulator.log.violations()[FINGERTIP_WORKSPACE]['count'] == 0
        return simulator.state.to_vector()

    return solve, solve('rk4', 0.000625)


@pytest.mark.parametrize('integrator, order', [('ode3', 3), ('rk4', 4)])
def test_full_simulator_converges_with_the_integrators_order(coasting, integrator, order):
    solve, reference = coasting
    errors = [np.max(np.abs(solve(integrator, dt) - reference)) for dt in (0.01, 0.005, 0.0025)]
    for coarse, fine in itertools.pairwise(errors):
        assert 0.75 * 2**order < coarse / fine < 1.3 * 2**order, errors
    assert errors[-1] < 1e-5


def test_quaternion_stays_unit_and_matches_the_rotation(model, config):
    simulator = Simulator(model, config)
    simulator.reset(rolling_start(model, config, np.array([0.0, 0.0, 0.0, 0.3, -0.2, 1.0])))
    for _ in range(50):
        simulator.step(np.zeros(9))
    quaternion = simulator.state.quaternion_object
    assert abs(np.linalg.norm(quaternion) - 1.0) < 1e-15
    np.testing.assert_allclose(
        np.abs(from_rotation_matrix(simulator.grasp_state().R_object_to_palm)),
        np.abs(quaternion),
        atol=1e-14,
    )
