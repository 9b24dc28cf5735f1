"""Nominal controller on hands with more joints than contact constraints (m > 3n).

The example four-finger hand (config/four_finger_hand.urdf: 16 joints, 4 contacts, 12
contact constraint rows) holds a 50 mm box at the grasp its header gives. The checks use the
model's own affine maps ``u ↦ f_c, ddq, x_o_ddot`` (the constrained dynamics, tested against
finite differences in test_model.py) as the plant, and projectors built here from M_h and J_h.
The paper's hand (m = 3n) is checked against the paper's formula written out with J_h^-1.
"""

from __future__ import annotations

import dataclasses
import math

from grasp_states import CONFIG_DIR, paper_model, random_configuration
import numpy as np
import pinocchio as pin
import pytest

from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.pose_error import euler_from_matrix, matrix_from_euler
from grasp_safety_filter.control.reference import PaperReference, Pose, ReferenceSample
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import load_node_parameters, NODE_SCHEMAS
from grasp_safety_filter.model.grasp_model import GraspModel
from hand_sim_node.config import SimConfig
from hand_sim_node.simulator import SimState, Simulator

FINGERS = ('finger1', 'finger2', 'finger3', 'finger4')
#: The header's grasp, per finger: abduction, then three flexion joints [rad].
FINGER_GRASP = (0.0, 0.3, 0.6, math.pi / 2 - 0.9)
#: The box's centre at that grasp, 0.0752 m above the palm centre (the header) [m].
BOX_CENTRE = (0.0, 0.0, 0.0752131)

SCENARIO = f"""
/**:
  ros__parameters:
    model:
      urdf_file: "{CONFIG_DIR / 'four_finger_hand.urdf'}"
      joint_names: {[f'{f}_joint{k}' for f in FINGERS for k in range(1, 5)]}
      fingertip_frames: {[f'{f}_tip' for f in FINGERS]}
      contact_names: {list(FINGERS)}
{{tip_radius}}      object: {{shape: cube, mass: 0.1, size: 0.05}}
      contact_faces: ["-x", "+x", "-y", "+y"]
      friction_coefficient: 0.8
      gravity: [0.0, 0.0, -9.81]
      fingertip_workspace: {{a_min: -1.42, a_max: 1.42, b_min: -3.14159, b_max: 0.0}}
hand_sim_node:
  ros__parameters:
    initial:
      joint_positions: {list(FINGER_GRASP) * 4}
      object_position: {list(BOX_CENTRE)}
"""


@pytest.fixture(scope='module')
def hand(tmp_path_factory):
    """Return the example hand's GraspModel and its grasp configuration (q, p_o)."""
    path = tmp_path_factory.mktemp('four_finger') / 'scenario.yaml'
    # A schema with model.fingertip_radius takes the 12 mm tip radius from it; one without
    # reads it from the tip links' <collision><sphere>, as the URDF declares them.
    declared = 'model.fingertip_radius' in NODE_SCHEMAS['hand_sim_node'].names
    path.write_text(
        SCENARIO.replace('{tip_radius}', '      fingertip_radius: 0.012\n' if declared else '')
    )
    params = load_node_parameters(path, 'hand_sim_node')
    model = GraspModel.from_parameters(params, path.parent)
    assert (model.n_joints, len(model.contact_names)) == (16, 4)
    return model, np.array(params['initial.joint_positions']), np.array(BOX_CENTRE)


def null_space_basis(J_h):
    """Orthonormal basis of null(J_h), shape (m, m - rank)."""
    _, s, Vt = np.linalg.svd(J_h)
    return Vt[np.sum(s > 1e-10 * s[0]) :].T


def near_grasp(hand, seed):
    """Return a rolling state near the header's grasp, with internal (null(J_h)) finger motion.

    The object is displaced by up to 3 mm and 0.1 rad and given a random twist; the joints
    are projected onto the contact manifold and given the least-norm rolling velocity plus a
    random velocity in null(J_h), so J_h dq = G^T x_o_dot holds with dq outside range(J_h^T).
    """
    model, q_grasp, p_grasp = hand
    rng = np.random.default_rng(seed)
    while True:
        p_object = p_grasp + rng.uniform(-0.003, 0.003, 3)
        R_object = pin.exp3(rng.uniform(-0.1, 0.1, 3))
        q = model.project_to_contact(q_grasp + rng.uniform(-0.05, 0.05, 16), p_object, R_object)
        if np.all(q > model.joint_lower_limits) and np.all(q < model.joint_upper_limits):
            break
    twist = rng.normal(size=6) * np.array([0.05, 0.05, 0.05, 0.5, 0.5, 0.5])
    dq_rolling = model.rolling_joint_velocity(q, p_object, R_object, twist)
    at_rest = model.state(0.0, q, np.zeros(16), p_object, R_object, np.zeros(6))
    basis = null_space_basis(at_rest.J_h)
    assert basis.shape == (16, 4)
    dq = dq_rolling + basis @ rng.normal(size=4)
    state = model.state(0.3, q, dq, p_object, R_object, twist)
    np.testing.assert_allclose(state.J_h @ state.dq, state.G.T @ twist, atol=1e-12)
    return state


def references(state):
    """Return a paper-shaped reference mid-motion, a random sample, and the held pose."""
    phi = euler_from_matrix(state.R_object_to_palm) + np.array([0.05, -0.05, 0.1])
    pose = Pose(state.p_object_in_palm + np.array([0.002, -0.001, 0.003]), matrix_from_euler(phi))
    rng = np.random.default_rng(5)
    random_sample = ReferenceSample(
        r=pose.euler + rng.normal(size=6) * 0.02,
        r_dot=rng.normal(size=6) * 0.1,
        r_ddot=rng.normal(size=6),
    )
    hold = ReferenceSample.from_pose(Pose(state.p_object_in_palm, state.R_object_to_palm))
    small = PaperReference(pose, amplitude=(0.0, 0.0, 0.01, 0.0, 0.0, 0.2))
    return [small.sample(1.7), random_sample, hold]


def dynamically_consistent_null_projector(state):
    """N = I - M_h^-1 J_h^T (J_h M_h^-1 J_h^T)^-1 J_h, shape (m, m)."""
    M_inv_J_T = np.linalg.solve(state.M_h, state.J_h.T)
    J_bar = M_inv_J_T @ np.linalg.inv(state.J_h @ M_inv_J_T)
    return np.eye(state.n_joints) - J_bar @ state.J_h


def off_posture_controller(state, **gains):
    """Return a controller whose posture is 0.2 rad away from q in every joint."""
    config = NominalConfig(**gains) if gains else NominalConfig()
    return NominalController(config, posture=state.q + 0.2 * np.sign(np.sin(np.arange(16))))


SEEDS = range(6)


@pytest.mark.parametrize('seed', SEEDS)
def test_object_acceleration_is_the_commanded_one_on_the_redundant_hand(hand, seed):
    state = near_grasp(hand, seed)
    controller = off_posture_controller(state)
    for reference in references(state):
        output = controller.compute(state, reference)
        assert np.linalg.norm(output.u_null_space) > 1e-4  # the null-space term is active
        np.testing.assert_allclose(
            state.object_acceleration(output.u), output.object_acceleration_desired, atol=1e-8
        )


@pytest.mark.parametrize('seed', SEEDS)
def test_squeeze_adds_exactly_the_internal_force_and_no_object_wrench(hand, seed):
    state = near_grasp(hand, seed)
    reference = references(state)[0]
    squeezing = off_posture_controller(state).compute(state, reference)
    loose = off_posture_controller(state, kf=0.0).compute(state, reference)
    u_f = squeezing.u_internal
    assert np.linalg.norm(u_f) > 0.05
    np.testing.assert_allclose(state.G @ u_f, 0.0, atol=1e-12)
    np.testing.assert_allclose(
        state.contact_force(squeezing.u) - state.contact_force(loose.u), u_f, atol=1e-9
    )
    np.testing.assert_allclose(
        state.object_acceleration(squeezing.u), state.object_acceleration(loose.u), atol=1e-9
    )


@pytest.mark.parametrize('seed', SEEDS)
def test_null_space_torque_moves_only_the_internal_finger_motion(hand, seed):
    state = near_grasp(hand, seed)
    controller = off_posture_controller(state, null_space_kp=1e4, null_space_kd=200.0)
    tau_null = controller.compute(state, references(state)[0]).u_null_space
    assert np.linalg.norm(tau_null) > 1e-2
    # Alone, tau_null changes neither the contact forces nor the object's acceleration ...
    np.testing.assert_allclose(state.contact_force.matrix @ tau_null, 0.0, atol=1e-9)
    np.testing.assert_allclose(state.object_acceleration.matrix @ tau_null, 0.0, atol=1e-9)
    # ... while a torque of its size in a random direction does,
    rng = np.random.default_rng(seed)
    random_torque = rng.normal(size=16)
    random_torque *= np.linalg.norm(tau_null) / np.linalg.norm(random_torque)
    assert np.linalg.norm(state.contact_force.matrix @ random_torque) > 1e-3
    # ... and the joint acceleration it causes is the PD one projected on null(J_h):
    # ddq = M_h^-1 N^T M_h a_null = N a_null, a_null = -kp (q - q_posture) - kd dq.
    N = dynamically_consistent_null_projector(state)
    a_null = -1e4 * (state.q - controller.posture) - 200.0 * state.dq
    ddq_null = state.joint_acceleration.matrix @ tau_null
    np.testing.assert_allclose(ddq_null, N @ a_null, atol=1e-7 * np.linalg.norm(a_null))
    np.testing.assert_allclose(state.J_h @ ddq_null, 0.0, atol=1e-9)


@pytest.mark.parametrize('seed', SEEDS)
def test_internal_motion_obeys_the_documented_null_space_dynamics(hand, seed):
    """Under the whole law, N ddq = N a_null - M_h^-1 N^T C_h dq (module docstring)."""
    state = near_grasp(hand, seed)
    controller = off_posture_controller(state)
    output = controller.compute(state, references(state)[1])
    N = dynamically_consistent_null_projector(state)
    a_null = -25.0 * (state.q - controller.posture) - 10.0 * state.dq
    C_h_dq = state.h_bias - state.gravity_torque
    expected = N @ a_null - np.linalg.solve(state.M_h, N.T @ C_h_dq)
    ddq = state.joint_acceleration(output.u)
    np.testing.assert_allclose(N @ ddq, expected, atol=1e-7 * np.linalg.norm(a_null))


def test_posture_defaults_to_the_first_joint_positions_seen(hand):
    first, second = near_grasp(hand, 0), near_grasp(hand, 1)
    controller = NominalController()
    assert controller.posture is None
    controller.compute(first, references(first)[2])
    np.testing.assert_array_equal(controller.posture, first.q)
    output = controller.compute(second, references(second)[2])
    np.testing.assert_array_equal(controller.posture, first.q)
    given = NominalController(posture=first.q).compute(second, references(second)[2])
    np.testing.assert_array_equal(output.u, given.u)
    with pytest.raises(ValueError, match='posture has 9 joint angles, the hand 16 joints'):
        NominalController(posture=np.zeros(9)).compute(first, references(first)[2])


def paper_formula(state, reference, config):
    """Return u_nom by the paper's eq. 19–21 with J_h^-1 (m = 3n), written out independently."""
    J_inv = np.linalg.inv(state.J_h)
    A = J_inv @ state.G.T
    x_ddot_des = NominalController(config).desired_object_acceleration(state, reference)[0]
    M_ho = state.M_o + A.T @ state.M_h @ A
    ddq_velocity = J_inv @ (state.G_dot_T_twist - state.Jh_dot_dq)
    C_h_dq = state.h_bias - state.gravity_torque
    C_ho_x_dot = state.C_o_twist + A.T @ (C_h_dq + state.M_h @ ddq_velocity)
    u_m = M_ho @ x_ddot_des + C_ho_x_dot - state.w_e
    G_pinv = np.linalg.pinv(state.G)
    p_c = state.p_contact_in_palm
    f_squeeze = config.kf * (p_c.mean(axis=0) - p_c)
    u_f = np.einsum('nij,ni->nj', state.R_contact_to_palm, f_squeeze).reshape(-1)
    return state.J_h.T @ (G_pinv @ u_m + u_f) + state.gravity_torque


PAPER_MODEL = paper_model()


@pytest.mark.parametrize('seed', range(8))
def test_square_hand_is_the_papers_law_with_no_null_space_term(seed):
    state = random_configuration(PAPER_MODEL, np.random.default_rng(seed)).state(PAPER_MODEL)
    pose = Pose(state.p_object_in_palm, state.R_object_to_palm)
    config = NominalConfig()
    for reference in (PaperReference(pose).sample(0.1 + seed), ReferenceSample.from_pose(pose)):
        expected = paper_formula(state, reference, config)
        for posture in (None, state.q + 0.3):
            output = NominalController(config, posture=posture).compute(state, reference)
            np.testing.assert_allclose(output.u, expected, rtol=0.0, atol=1e-9)
            np.testing.assert_array_equal(output.u_null_space, 0.0)


def test_fewer_joints_than_contact_rows_is_refused_with_the_counts():
    state = random_configuration(PAPER_MODEL, np.random.default_rng(0)).state(PAPER_MODEL)
    keep = np.arange(8)
    short = dataclasses.replace(
        state,
        q=state.q[keep],
        dq=state.dq[keep],
        J_h=state.J_h[:, keep],
        M_h=state.M_h[np.ix_(keep, keep)],
    )
    hold = ReferenceSample.from_pose(Pose(state.p_object_in_palm, state.R_object_to_palm))
    with pytest.raises(ValueError, match=r'm = 8 joints for n = 3 contacts.*3n = 9'):
        NominalController().compute(short, hold)


def test_a_rank_deficient_hand_jacobian_is_reported_with_its_rank(hand):
    state = near_grasp(hand, 0)
    J_h = state.J_h.copy()
    J_h[4] = 2.0 * J_h[3]  # finger2's tangential rows now dependent: rank 11
    hold = ReferenceSample.from_pose(Pose(state.p_object_in_palm, state.R_object_to_palm))
    with pytest.raises(np.linalg.LinAlgError, match=r'\(12 x 16\) is rank-deficient: rank 11'):
        NominalController().compute(dataclasses.replace(state, J_h=J_h), hold)


def test_null_space_gains_are_parameters_with_units_and_bounds():
    config = NominalConfig.from_parameters({'null_space': {'kp': 4.0, 'kd': 4.0}})
    assert (config.null_space_kp, config.null_space_kd) == (4.0, 4.0)
    defaults = NominalConfig.from_parameters({})
    assert defaults.null_space_kd**2 >= 4.0 * defaults.null_space_kp  # not underdamped
    for name in ('null_space.kp', 'null_space.kd'):
        with pytest.raises(ParameterError, match=rf"'{name}'.*expected >= 0"):
            NominalConfig.from_parameters({name: -1.0})


def test_held_box_internal_finger_motion_decays_as_designed_in_closed_loop(hand):
    """Lockstep simulation, 0.5 s: the box held, the fingers kicked along null(J_h).

    The initial joint velocity (norm v0 = 2 rad/s) lies in null(J_h): it moves no contact,
    so the box starts at rest. With the default null-space gains (critically damped,
    omega = 5 rad/s) the linearised internal motion is x(t) = v0 t e^(-omega t): its
    velocity falls to |1 - omega t| e^(-omega t) v0 = 0.12 v0 at 0.5 s and its excursion
    peaks at v0 / (e omega) = 0.15 rad. The bounds allow for the nonlinear terms (Coriolis,
    the projector turning with q) with margin, and fail without the null-space term (the
    internal speed then does not decay). The object is commanded to stay: its error is
    the torque's sample-and-hold over 1 ms steps only, O(dt).
    """
    model, q_grasp, p_grasp = hand
    config = SimConfig(
        initial_joint_positions=q_grasp, initial_object_position=p_grasp, duration=0.5
    )
    simulator = Simulator(model, config)
    start = simulator.state
    basis = null_space_basis(simulator.grasp_state().J_h)
    v0 = 2.0
    dq0 = basis @ np.array([1.0, -0.5, 0.8, 0.3])
    dq0 *= v0 / np.linalg.norm(dq0)
    simulator.reset(
        SimState(
            0.0,
            start.q,
            dq0,
            start.p_object_in_palm,
            start.quaternion_object,
            start.twist_object,
        )
    )
    controller = NominalController(NominalConfig(kf=40.0, reference_source='topic'))
    held = ReferenceSample.from_pose(Pose(start.p_object_in_palm, start.R_object_to_palm))
    internal_speed, excursion, pose_error = [], [], []
    for _ in range(config.n_steps):
        state = simulator.grasp_state()
        output = controller.compute(state, held)
        simulator.step(output.u)
        assert simulator.stop_reason is None
        N = dynamically_consistent_null_projector(state)
        internal_speed.append(np.linalg.norm(N @ state.dq))
        excursion.append(np.linalg.norm(N @ (state.q - start.q)))
        pose_error.append(np.abs(output.pose_error))
    assert internal_speed[0] == pytest.approx(v0, rel=1e-6)
    assert max(internal_speed) <= 1.01 * v0
    assert internal_speed[-1] <= 0.25 * v0
    assert max(excursion) <= 1.5 * v0 / (math.e * 5.0)
    pose_error = np.array(pose_error)
    assert pose_error[:, :3].max() < 1e-3 and pose_error[:, 3:].max() < 1e-2
