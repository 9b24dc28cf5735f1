"""The rigid plant with soft fingers: physics invariants that hold only if the torsion rows do.

Soft fingers (``model.torsional_friction`` > 0) add, per contact, a torque about the contact
normal and the no-spin constraint ``n_i^T (w_f - w_o) = 0``. The plant is checked by what
does not come from those rows: Newton–Euler summed contact by contact (forces at the contact
points, torques ``n_i tau_i``), the spin residual's rate taken by finite differences of the
two bodies' angular velocities, energy conservation of the unactuated plant, and the
constraint, spin rows included, holding over a run.

The instantaneous checks run at random grasps near the paper's, on a cube and on a sphere;
the runs start from the paper's grasp with the object turned 0.2 rad about the palm z axis:
at the paper's symmetric grasp no finger can spin about its contact normal (every joint axis is
perpendicular to it), so fingers 1 and 2, on opposite faces, forbid the same object spin
twice, ``[J_h, -G^T]`` loses rank and ``B_ho`` is singular (the internal torsion between
them is statically indeterminate).
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path

from grasp_states import paper_model, random_configuration
import numpy as np
import pytest
from stacked_arrays import skew
from test_simulator import hand_kinetic_energy, unactuated_run

from grasp_safety_filter.model.quaternion import from_rotation_matrix
from grasp_tools.bench.recorded_run import Scenario
from hand_sim_node.simulator import SimState, Simulator
from hand_sim_node.stage import PlantRate

SCENARIO = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
YAW = 0.2  # rad, the object's turn about the palm z axis from the paper's grasp
SOFT_FINGERS = {
    'model.torsional_friction': 0.005,
    'model.torsional_compliance': 0.0,  # the rigid no-spin constraint: exact physics
    'initial.object_orientation': [0.0, 0.0, math.sin(YAW / 2), math.cos(YAW / 2)],
}


@pytest.fixture(scope='module')
def soft():
    scenario = Scenario.load(SCENARIO, plant_overrides=SOFT_FINGERS)
    assert scenario.model.soft_finger and scenario.model.wrench_size == 12
    return scenario.model, scenario.sim_config


def spin_residual(state):
    """``n_i^T (w_f,i - w_o)`` per contact, rad/s, from the bodies' angular velocities."""
    normals = state.R_contact_to_palm[:, :, 2]
    w_f = state.twist_fingertip[:, 3:]
    return np.einsum('ij,ij->i', normals, w_f - state.twist_object[3:])


#: Soft-finger models for the instantaneous checks (at random grasps near the paper's): on a
#: sphere the contact frame does not turn with the object, so every rate term is exercised.
MODELS = {
    'cube': {'model.torsional_friction': 0.005, 'model.torsional_compliance': 0.0},
    'sphere object': {
        'model.object.shape': 'sphere',
        'model.object.size': 0.3,
        'model.torsional_friction': [0.004, 0.005, 0.006],
        'model.torsional_compliance': 0.0,
    },
}


@pytest.fixture(scope='module', params=list(MODELS), ids=list(MODELS))
def soft_model(request):
    return paper_model(**MODELS[request.param])


def random_state(model, rng, on_manifold):
    """Return a random grasp near the paper's, rolling (off the manifold: velocities perturbed)."""
    c = random_configuration(model, rng)
    dq, twist = c.dq, c.twist_object
    if not on_manifold:
        dq = dq + rng.normal(0.0, 0.3, dq.size)
        twist = twist + rng.normal(0.0, 0.1, 6)
    return SimState(0.0, c.q, dq, c.p_object, from_rotation_matrix(c.R_object), twist)


def grasp_state(model, s):
    return model.state(s.t, s.q, s.dq, s.p_object_in_palm, s.R_object_to_palm, s.twist_object)


@pytest.mark.parametrize('on_manifold', [True, False], ids=['rolling', 'off the manifold'])
def test_newton_euler_contact_by_contact(soft_model, on_manifold):
    """The stage's accelerations are Newton–Euler of its wrench, summed contact by contact.

    Object: ``M_o x_o_ddot = (sum f_i, sum (p_c,i - p_o) × f_i + n_i tau_i) + w_e - C_o x_o_dot``;
    hand: ``M_h ddq = u - h - sum (J_c,i^T f_i + J_w,i^T n_i tau_i)``, J_c,i the Jacobian of
    the fingertip's material point at the contact. Neither G nor J_h is used.
    """
    model = soft_model
    m, n = model.n_joints, model.n_contacts
    rate = PlantRate(model)
    rng = np.random.default_rng(40 + on_manifold)
    torsion_seen = 0.0
    for _ in range(5):
        s = random_state(model, rng, on_manifold)
        state = grasp_state(model, s)
        u = state.h_bias + rng.normal(0.0, 0.5, m)
        x_dot, wrench = rate.from_state(state, u, s.quaternion_object, 2500.0, 100.0)
        ddq, x_o_ddot = x_dot[m : 2 * m], x_dot[2 * m + 7 :]
        assert wrench.shape == (4 * n,)
        force = np.einsum('nij,nj->ni', state.R_contact_to_palm, wrench[: 3 * n].reshape(n, 3))
        torque = state.R_contact_to_palm[:, :, 2] * wrench[3 * n :, None]  # n_i tau_i
        arm = state.p_contact_in_palm - state.p_object_in_palm
        on_object = np.concatenate((force.sum(axis=0), (np.cross(arm, force) + torque).sum(0)))
        expected = np.linalg.solve(state.M_o, on_object + state.w_e - state.C_o_twist)
        np.testing.assert_allclose(x_o_ddot, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
        on_hand = np.zeros(m)
        for i in range(n):
            J_v, J_w = state.J_fingertip[i, :3], state.J_fingertip[i, 3:]
            J_c = J_v - skew(state.p_contact_in_palm[i] - state.p_fingertip_in_palm[i]) @ J_w
            on_hand += J_c.T @ force[i] + J_w.T @ torque[i]
        expected = np.linalg.solve(state.M_h, u - state.h_bias - on_hand)
        np.testing.assert_allclose(ddq, expected, rtol=0, atol=1e-9 * np.abs(expected).max())
        torsion_seen = max(torsion_seen, np.abs(wrench[3 * n :]).max())
    assert torsion_seen > 1e-3  # the torsions are not all zero: the check has teeth


def spin_rate(model, s, effort, position_gain, velocity_gain):
    """Return the spin residual, its rate along the stage's x_dot, and max |n_i^T alpha_o|."""
    m = model.n_joints
    x = s.to_vector()
    x_dot = PlantRate(model).at(x, effort, position_gain, velocity_gain)
    h = 1e-6
    plus, minus = (
        grasp_state(model, SimState.from_vector(step, x + step * x_dot, m)) for step in (h, -h)
    )
    normals = grasp_state(model, s).R_contact_to_palm[:, :, 2]
    alpha_o = x_dot[2 * m + 10 :]
    return spin_residual(grasp_state(model, s)), (
        spin_residual(plus) - spin_residual(minus)
    ) / (2 * h), np.abs(normals @ alpha_o).max()


def test_rolling_fingertips_keep_not_spinning(soft_model):
    """On the manifold, the stage's accelerations keep ``n_i^T (w_f - w_o) = 0``.

    The spin residual comes from the bodies' angular velocities (not J_h, G) at ``x ± h
    x_dot``: its rate vanishes only if the torsion rows' rates ``J_h_dot dq`` and
    ``G_dot^T x_o_dot`` are those the stage solves with. On a sphere the contact frame does
    not turn with the object, so ``G_dot^T x_o_dot``'s torsion entries are not zero.
    """
    model = soft_model
    rng = np.random.default_rng(50)
    for _ in range(3):
        s = random_state(model, rng, on_manifold=True)
        u = grasp_state(model, s).h_bias + rng.normal(0.0, 0.5, model.n_joints)
        spin, spin_dot, alpha_about_normals = spin_rate(model, s, u, 0.0, 0.0)
        assert np.abs(spin).max() < 1e-12
        assert alpha_about_normals > 0.1  # rad/s²: both bodies do turn about the normals
        np.testing.assert_allclose(spin_dot, 0.0, rtol=0, atol=1e-8 * alpha_about_normals)


def test_the_spin_residual_is_held_not_stabilised():
    """Off the manifold, ``d/dt n_i^T (w_f - w_o) = 0`` along the rate, whatever K_v.

    The stabilisation corrects the force rows only: near grasps where an internal torsion
    is barely reachable, ``B_ho^-1`` of a spin residual is huge, and a compliant spin row's
    residual is its creep, not drift. On the cube's flat faces (on curved surfaces the
    contact kinematics hold on the manifold only).
    """
    model = paper_model(**MODELS['cube'])
    rng = np.random.default_rng(51)
    velocity_gain = 100.0
    for _ in range(3):
        s = random_state(model, rng, on_manifold=False)
        u = grasp_state(model, s).h_bias + rng.normal(0.0, 0.5, model.n_joints)
        spin, spin_dot, _ = spin_rate(model, s, u, 2500.0, velocity_gain)
        assert np.abs(spin).max() > 1e-2
        # Stabilised, it would fall at K_v |spin| > 1 rad/s².
        scale = velocity_gain * np.abs(spin).max()
        np.testing.assert_allclose(spin_dot, 0.0, rtol=0, atol=1e-6 * scale)


def object_spin_about_normals(state):
    """Largest ``|n_i^T w_o|``, rad/s: how fast the object turns about a contact normal."""
    normals = state.R_contact_to_palm[:, :, 2]
    return np.abs(normals @ state.twist_object[3:]).max()


def energy_drift(model, config, time_step, duration):
    """Largest |E(t) - E(0)| of the unactuated plant (u = 0, ode3, no stabilisation), E(0)."""
    drift, energy_0, (kinetic_peak, spin_peak) = unactuated_run(
        model, config, time_step, duration, hand_kinetic_energy, object_spin_about_normals
    )
    assert kinetic_peak > 0.1 * abs(energy_0)  # the system really moved
    assert spin_peak > 0.1  # rad/s: the fingertips turned with the object about the normals
    return drift, energy_0


def test_energy_of_the_unactuated_plant_is_conserved_to_integrator_accuracy(soft):
    """Zero torque, gravity, 1 s, no stabilisation: the drift is ode3's (half the step, 1/8).

    Contacts that roll without slipping or spinning do no work; a torsion row with a wrong
    rate would make the constraint force work on the motion.
    """
    model, config = soft
    # At 1 ms the drift is ~8e-4 of E(0) (the fingers fold fast; the point-contact test's
    # plant drifts ~3e-4): the steps are halved once more than there.
    drift_coarse, energy_0 = energy_drift(model, config, 0.0005, 1.0)
    drift_fine, _ = energy_drift(model, config, 0.00025, 1.0)
    assert 6.0 < drift_coarse / drift_fine < 10.5, (drift_coarse, drift_fine)
    assert drift_fine <= 1e-4 * abs(energy_0), drift_fine / abs(energy_0)


def holding_torque(state, squeeze=10.0):
    """``h + J_h^T f``: the wrench that holds the object against gravity, no torsion, squeezed.

    ``f = G^+ (-w_e)`` on the force rows plus the paper's internal force
    ``k_f (p_bar - p_c,i)`` (contact frames).
    """
    n = state.p_contact_in_palm.shape[0]
    G = state.G[:, : 3 * n]
    p_c = state.p_contact_in_palm
    inward = squeeze * (p_c.mean(axis=0) - p_c)
    internal = np.einsum('nji,nj->ni', state.R_contact_to_palm, inward).ravel()
    return state.h_bias + state.J_h[: 3 * n].T @ (np.linalg.pinv(G) @ -state.w_e + internal)


def test_constraint_spin_rows_included_holds_over_a_manipulation(soft):
    """Over 3 s the gap, rolling and spin residuals stay below 1e-6 (m, m/s, rad/s).

    The configured plant (ode3, 1 ms, stabilised) under a holding torque and a joint torque
    wave.
    """
    model, config = soft
    assert config.time_step == 0.001 and config.integrator == 'ode3'
    simulator = Simulator(model, dataclasses.replace(config, duration=3.0))
    n = model.n_contacts
    wave = np.random.default_rng(60).normal(0.0, 0.02, model.n_joints)
    max_gap = max_residual = max_spin = spin_peak = 0.0
    xi_0 = simulator.grasp_state().xi_cf.copy()
    xi_travel = 0.0
    for _ in range(simulator.config.n_steps):
        state = simulator.grasp_state()
        e = state.J_h @ state.dq - state.G.T @ state.twist_object
        max_gap = max(max_gap, np.abs(state.penetration).max())
        max_residual = max(max_residual, np.abs(e[: 3 * n]).max())
        # The spin rows of the residual, and the same from the bodies' angular velocities.
        np.testing.assert_allclose(e[3 * n :], spin_residual(state), rtol=0, atol=1e-12)
        max_spin = max(max_spin, np.abs(e[3 * n :]).max())
        normals = state.R_contact_to_palm[:, :, 2]
        spin_peak = max(spin_peak, np.abs(normals @ state.twist_object[3:]).max())
        xi_travel = max(xi_travel, np.abs(state.xi_cf - xi_0).max())
        u = holding_torque(state) + wave * math.sin(2.0 * math.pi * simulator.t)
        report = simulator.step(u)
        assert report.stop_reason is None
    assert simulator.t == pytest.approx(3.0)
    assert xi_travel > 0.01  # the contacts really rolled
    assert spin_peak > 0.05  # rad/s: the fingertips turned with the object about the normals
    assert max_gap <= 1e-6
    assert max_residual <= 1e-6
    assert max_spin <= 1e-6


@pytest.mark.parametrize('yaw, rank', [(0.0, 11), (YAW, 12)], ids=['paper grasp', 'turned'])
def test_at_the_papers_grasp_two_spin_rows_coincide(yaw, rank):
    """Why the runs start turned: at the paper's grasp the 12 constraints have rank 11.

    No finger can spin about its normal there (its spin row of J_h is zero), so the spin
    rows of fingers 1 and 2 (normals ±x) both read ``w_o,x = 0``: B_ho is singular and the
    internal torsion between them is statically indeterminate. Turned, each finger can spin.
    """
    quaternion = [0.0, 0.0, math.sin(yaw / 2), math.cos(yaw / 2)]
    overrides = {**SOFT_FINGERS, 'initial.object_orientation': quaternion}
    scenario = Scenario.load(SCENARIO, plant_overrides=overrides)
    state = Simulator(scenario.model, scenario.sim_config).grasp_state()
    spin_rows = np.abs(state.J_h[9:]).max(axis=1)
    constraint = np.hstack([state.J_h, -state.G.T])
    assert np.linalg.matrix_rank(constraint) == rank
    assert np.linalg.matrix_rank(state.B_ho) == rank
    assert np.all(spin_rows < 1e-12) if rank == 11 else np.all(spin_rows > 0.1)
