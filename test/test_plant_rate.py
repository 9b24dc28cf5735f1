"""The simulator's stage function against the equations solved from a full GraspState.

Oracle: the stabilised dynamics written as in DESIGN.md §3, each term solved for from the
model's GraspState (``f_c = f_c(u) + B_ho^-1 (K_v e + K_p δ)``, ``M_h ddq = u - h - J_h^T f_c``,
``M_o x_o_ddot = G f_c + w_e - C_o x_o_dot``). Both of the simulator's evaluations — from a
GraspState (first stage) and from the bare configuration (the other stages) — must give the
same rate, on and off the contact manifold, with and without stabilisation; with point
contacts and with soft fingers (the torsion rows after the force rows).
"""

from pathlib import Path

import numpy as np
import pinocchio as pin
import pytest

from grasp_safety_filter.model.quaternion import quaternion_derivative, rotation_matrix
from grasp_tools.bench.recorded_run import Scenario
from hand_sim_node.simulator import SimState, Simulator
from hand_sim_node.stage import PlantRate

SCENARIO = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'

#: Soft fingers, the object turned 0.2 rad about the palm z axis: at the paper's symmetric
#: grasp no finger can spin about its normal, so fingers 1 and 2 (opposite faces) forbid the
#: same object spin twice and B_ho is singular.
SOFT_FINGERS = {
    'model.torsional_friction': 0.005,
    'model.torsional_compliance': 0.0,
    'initial.object_orientation': [0.0, 0.0, 0.09983341664682815, 0.9950041652780258],
}


#: The default compliant spin rows: B_ho's spin diagonal times 1 + rho in every solve.
COMPLIANT_SOFT_FINGERS = {**SOFT_FINGERS, 'model.torsional_compliance': 0.1}


@pytest.fixture(
    scope='module',
    params=[{}, SOFT_FINGERS, COMPLIANT_SOFT_FINGERS],
    ids=['point contacts', 'soft fingers', 'compliant soft fingers'],
)
def scenario(request):
    loaded = Scenario.load(SCENARIO, plant_overrides=request.param)
    assert loaded.model.soft_finger == bool(request.param)
    return loaded.model, loaded.sim_config


def oracle_rate(model, x, u, position_gain, velocity_gain):
    """x_dot from a GraspState by solving each equation, and f_c."""
    m = model.n_joints
    s = SimState.from_vector(0.0, x, m)
    state = model.state(0.0, s.q, s.dq, s.p_object_in_palm, s.R_object_to_palm, s.twist_object)
    e = state.J_h @ state.dq - state.G.T @ state.twist_object
    correction = velocity_gain * e
    # The normal rows; a soft finger's spin rows (after the 3n force rows) are not stabilised.
    correction[2 : 3 * model.n_contacts : 3] += position_gain * state.penetration
    correction[3 * model.n_contacts :] = 0.0
    B_ho = state.B_ho.copy()
    spin_rows = np.arange(3 * model.n_contacts, B_ho.shape[0])
    B_ho[spin_rows, spin_rows] *= 1.0 + model.torsional_compliance
    f_c = state.contact_force(u) + np.linalg.solve(B_ho, correction)
    ddq = np.linalg.solve(state.M_h, u - state.h_bias - state.J_h.T @ f_c)
    x_o_ddot = np.linalg.solve(state.M_o, state.G @ f_c + state.w_e - state.C_o_twist)
    quaternion = x[2 * m + 3 : 2 * m + 7]
    rate = np.concatenate(
        (
            s.dq,
            ddq,
            s.twist_object[:3],
            quaternion_derivative(quaternion, s.twist_object[3:]),
            x_o_ddot,
        )
    )
    return state, rate, f_c


def random_state(model, config, rng, gap):
    """Return the initial grasp with random velocities, the object moved ``gap`` m off finger 3."""
    start = Simulator(model, config).state
    quaternion = start.quaternion_object * rng.uniform(0.98, 1.02)  # not unit, as mid-step
    return SimState(
        0.0,
        start.q + rng.normal(0.0, 0.01, model.n_joints),
        rng.normal(0.0, 0.3, model.n_joints),
        start.p_object_in_palm + np.array([0.0, gap, 0.0]),
        quaternion,
        rng.normal(0.0, 0.1, 6),
    ).to_vector()


@pytest.mark.parametrize(
    'gains, gap, seed',
    [
        ((2500.0, 100.0), 0.0, 0),
        ((2500.0, 100.0), 1e-4, 1),
        ((0.0, 0.0), 1e-4, 2),
        ((0.0, 100.0), 0.0, 3),
        ((2500.0, 0.0), -2e-4, 4),
    ],
    ids=['paper-gains', 'paper-gains-gap', 'no-stabilisation', 'velocity-only', 'position-only'],
)
def test_both_stage_evaluations_equal_the_solved_equations(scenario, gains, gap, seed):
    model, config = scenario
    rate = PlantRate(model)
    rng = np.random.default_rng(seed)
    m = model.n_joints
    for _ in range(5):
        x = random_state(model, config, rng, gap)
        u = rng.normal(0.0, 0.5, m)
        state, expected, f_c = oracle_rate(model, x, u, *gains)
        assert np.abs(state.penetration).max() > 1e-6  # off the manifold: δ matters
        scale = np.abs(expected).max()
        from_state, force = rate.from_state(state, u, x[2 * m + 3 : 2 * m + 7], *gains)
        np.testing.assert_allclose(force, f_c, rtol=0, atol=1e-11 * np.abs(f_c).max())
        np.testing.assert_allclose(from_state, expected, rtol=0, atol=1e-11 * scale)
        np.testing.assert_allclose(rate.at(x, u, *gains), expected, rtol=0, atol=1e-11 * scale)


def test_stage_rate_uses_the_normalised_rotation_and_the_raw_quaternion(scenario):
    model, config = scenario
    m = model.n_joints
    x = random_state(model, config, np.random.default_rng(7), 0.0)
    scaled = x.copy()
    scaled[2 * m + 3 : 2 * m + 7] *= 1.5
    rate, u = PlantRate(model), np.zeros(m)
    unit, long = rate.at(x, u, 2500.0, 100.0), rate.at(scaled, u, 2500.0, 100.0)
    quaternion = slice(2 * m + 3, 2 * m + 7)
    # Same rotation, so the same accelerations; the quaternion's rate scales with it.
    np.testing.assert_allclose(
        np.delete(long, range(2 * m + 3, 2 * m + 7)),
        np.delete(unit, range(2 * m + 3, 2 * m + 7)),
        rtol=1e-12,
        atol=1e-12,
    )
    np.testing.assert_allclose(long[quaternion], 1.5 * unit[quaternion], rtol=1e-12, atol=1e-15)


def test_the_rotation_matrix_is_pinocchios_of_the_normalised_quaternion():
    rng = np.random.default_rng(9)
    for quaternion in rng.normal(0.0, 1.0, (2000, 4)) * rng.uniform(0.5, 2.0, (2000, 1)):
        x, y, z, w = quaternion / np.linalg.norm(quaternion)
        expected = pin.Quaternion(w, x, y, z).toRotationMatrix()
        np.testing.assert_allclose(rotation_matrix(quaternion), expected, rtol=0, atol=1e-15)
    for bad in (np.zeros(4), np.array([np.nan, 0.0, 0.0, 1.0]), np.array([np.inf, 0, 0, 1.0])):
        with pytest.raises(ValueError, match='non-zero finite quaternion'):
            rotation_matrix(bad)


@pytest.mark.parametrize('seed', range(4))
def test_stage_rate_is_the_rate_at_the_models_state(scenario, seed):
    """One implementation: ``at`` is ``from_state`` at ``GraspModel.state``'s terms."""
    model, config = scenario
    m = model.n_joints
    rng = np.random.default_rng(20 + seed)
    rate = PlantRate(model)
    x = random_state(model, config, rng, 1e-4 * seed)
    u = rng.normal(0.0, 0.5, m)
    s = SimState.from_vector(0.0, x, m)
    state = model.state(0.0, s.q, s.dq, s.p_object_in_palm, s.R_object_to_palm, s.twist_object)
    from_state, _ = rate.from_state(state, u, x[2 * m + 3 : 2 * m + 7], 2500.0, 100.0)
    np.testing.assert_allclose(
        rate.at(x, u, 2500.0, 100.0), from_state, rtol=0, atol=1e-12 * np.abs(from_state).max()
    )


def test_stage_rate_on_a_sphere_object_equals_the_solved_equations():
    """The same one path with the sphere object's kernel (curved object surfaces)."""
    loaded = Scenario.load(
        SCENARIO, plant_overrides={'model.object.shape': 'sphere', 'model.object.size': 0.3}
    )
    model, config = loaded.model, loaded.sim_config
    m = model.n_joints
    rng = np.random.default_rng(31)
    rate = PlantRate(model)
    for gap in (0.0, 1e-4):
        x = random_state(model, config, rng, gap)
        u = rng.normal(0.0, 0.5, m)
        _, expected, _ = oracle_rate(model, x, u, 2500.0, 100.0)
        assert not model._compiled_contacts.flat
        np.testing.assert_allclose(
            rate.at(x, u, 2500.0, 100.0), expected, rtol=0, atol=1e-11 * np.abs(expected).max()
        )
