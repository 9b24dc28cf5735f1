"""The generated MJCF against our model: MuJoCo computes what our model computes.

At random states of the paper's hand and of the four-finger hand (box and sphere objects):
the joint-space inertia, the bias torques (hand and object), the fingertip sphere poses and
the object's inertia match our model to ~1e-12 (relative); at each scenario's initial grasp
MuJoCo's own collision detection finds one contact per fingertip at the distance our model
gives (zero gap). MuJoCo and Pinocchio are independent implementations of rigid-body
dynamics, so an agreement at this level checks the generated bodies, frames, axes, inertias,
fingertips, object and gravity, and the plant's state conversions.
"""

from pathlib import Path

import mujoco
import numpy as np
import pytest

from grasp_safety_filter.model.grasp_model import GraspModel
from hand_sim_node.config import SimConfig
from hand_sim_node.mjcf import fingertip_geom_name, mjcf_from_model, MjcfOptions
from hand_sim_node.mujoco_plant import MuJoCoPlant
from hand_sim_node.simulator import SimState

CONFIG = Path(__file__).resolve().parent.parent / 'config'
SCENARIOS = (
    'paper_scenario.yaml',
    'four_finger_box.yaml',
    'four_finger_sphere.yaml',
    'four_finger_three_contacts.yaml',  # a free finger, and unequal μ
)
SEEDS = range(4)
#: Relative agreement of MuJoCo's and our (Pinocchio's) dynamics terms.
RELATIVE = 1e-12


@pytest.fixture(scope='module', params=SCENARIOS)
def plant(request):
    model, params = GraspModel.from_parameter_file(CONFIG / request.param)
    return MuJoCoPlant(model, SimConfig.from_parameters(params))


def random_state(model, seed):
    """Return a random state: joints in range, any object pose, any velocities."""
    rng = np.random.default_rng(seed)
    lower, upper = model.joint_lower_limits, model.joint_upper_limits
    quaternion = rng.normal(size=4)
    return SimState(
        0.0,
        rng.uniform(lower, upper),
        rng.normal(size=model.n_joints),
        rng.normal(scale=0.1, size=3),
        quaternion / np.linalg.norm(quaternion),
        rng.normal(size=6),
    )


def full_inertia(plant):
    """Return MuJoCo's joint-space inertia M (nv, nv), by columns (mj_mulM of unit vectors)."""
    nv = plant.mj_model.nv
    M = np.empty((nv, nv))
    column = np.empty(nv)
    for k, unit in enumerate(np.eye(nv)):
        mujoco.mj_mulM(plant.mj_model, plant.mj_data, column, unit)
        M[:, k] = column
    return M


def object_to_palm(R):
    """``blkdiag(I, R)``: MuJoCo's free-joint velocity (v, w in body) to our twist (v, w)."""
    T = np.eye(6)
    T[3:, 3:] = R
    return T


def assert_close(ours, theirs, what):
    scale = max(np.max(np.abs(ours)), 1e-300)
    error = np.max(np.abs(np.asarray(theirs) - ours))
    assert error <= RELATIVE * scale, f'{what}: MuJoCo differs by {error:.3g} (scale {scale:.3g})'


@pytest.mark.parametrize('seed', SEEDS)
def test_state_round_trip(plant, seed):
    """The state set in MuJoCo is the state observed (quaternion order, twist frames)."""
    state = random_state(plant.model, seed)
    observed = plant.reset(state)
    for name in ('q', 'dq', 'p_object_in_palm', 'quaternion_object', 'twist_object'):
        assert_close(getattr(state, name), getattr(observed, name), name)
    data = plant.mj_data
    assert_close(state.R_object_to_palm, data.xmat[plant.object_body].reshape(3, 3), 'R_o')
    # MuJoCo's own velocity of the object body (world orientation): (w, v) at its origin.
    velocity = np.empty(6)
    mujoco.mj_objectVelocity(
        plant.mj_model, data, mujoco.mjtObj.mjOBJ_BODY, plant.object_body, velocity, 0
    )
    assert_close(state.twist_object, np.concatenate((velocity[3:], velocity[:3])), 'twist')


@pytest.mark.parametrize('seed', SEEDS)
def test_mass_matrix_and_bias(plant, seed):
    """M and C dq + g of hand and object as our model's; no hand–object inertial coupling."""
    model = plant.model
    state = random_state(model, seed)
    plant.reset(state)
    ours = model.state(
        0.0, state.q, state.dq, state.p_object_in_palm, state.R_object_to_palm,
        state.twist_object,
    )
    M = full_inertia(plant)
    hand = plant.joint_dofs
    obj = plant.object_dof + np.arange(6)
    assert_close(ours.M_h, M[np.ix_(hand, hand)], 'M_h')
    assert np.all(M[np.ix_(hand, obj)] == 0.0)
    T = object_to_palm(state.R_object_to_palm)
    assert_close(ours.M_o, T @ M[np.ix_(obj, obj)] @ T.T, 'M_o')
    bias = plant.mj_data.qfrc_bias
    assert_close(ours.h_bias, bias[hand], 'h_bias = C_h dq + g')
    # M_o x_o_ddot = w_e - C_o x_o_dot in our twist; MuJoCo's object bias, turned to palm axes.
    assert_close(ours.C_o_twist - ours.w_e, T @ bias[obj], 'C_o x_o_dot - w_e')


@pytest.mark.parametrize('seed', SEEDS)
def test_fingertip_poses(plant, seed):
    """Each fingertip sphere: our radius, centred on our fingertip frame, with its axes."""
    model = plant.model
    state = random_state(model, seed)
    plant.reset(state)
    p_f, R_f, _ = model.hand.fingertip_placements(state.q)
    data, mj = plant.mj_data, plant.mj_model
    for i, (name, tip) in enumerate(zip(model.contact_names, model.hand.fingertips, strict=True)):
        geom = mj.geom(fingertip_geom_name(name)).id
        assert mj.geom_size[geom][0] == tip.radius
        assert_close(p_f[i], data.geom_xpos[geom], f'{name} centre')
        assert_close(R_f[i], data.geom_xmat[geom].reshape(3, 3), f'{name} axes')


def test_initial_grasp_touches(plant):
    """Collision detection finds one contact per fingertip, at our (zero) penetration."""
    model = plant.model
    plant.reset()
    state = plant.grasp_state()
    assert np.max(np.abs(state.penetration)) < 1e-12
    mj, data = plant.mj_model, plant.mj_data
    # A margin of 1 µm makes MuJoCo report a touching pair whose distance rounds to +1e-17 m
    # too (its contacts are reported at distance <= margin); the distance is unchanged.
    saved = mj.geom_margin.copy()
    try:
        mj.geom_margin[:] = 1e-6
        mujoco.mj_forward(mj, data)
        pairs = [
            ({int(data.contact[c].geom1), int(data.contact[c].geom2)}, data.contact[c].dist)
            for c in range(data.ncon)
        ]
    finally:
        mj.geom_margin[:] = saved
        mujoco.mj_forward(mj, data)
    assert len(pairs) == model.n_contacts
    for i, geom in enumerate(plant.fingertip_geoms):
        found = [dist for geoms, dist in pairs if geoms == {int(geom), plant.object_geom}]
        assert len(found) == 1, f'{model.contact_names[i]}: {len(found)} contacts'
        assert abs(found[0] + state.penetration[i]) < 1e-9
    report = plant.contact_report()
    assert report.present.all()
    np.testing.assert_allclose(report.distance, -state.penetration, rtol=0.0, atol=1e-9)


@pytest.mark.parametrize(
    'options',
    [MjcfOptions(), MjcfOptions(cone='elliptic', condim=4, solref=(0.004, 1.0),
                                friction_coefficient=0.5)],
)
def test_contact_parameters_reach_mujoco(plant, options):
    """The options are the compiled model's: cone, condim, friction, solref, gravity, limits."""
    model = plant.model
    mj = mujoco.MjModel.from_xml_string(mjcf_from_model(model, options))
    assert mj.opt.cone == {'pyramidal': 0, 'elliptic': 1}[options.cone]
    assert mj.opt.timestep == options.timestep
    assert mj.opt.impratio == options.impratio
    assert mj.opt.noslip_iterations == options.noslip_iterations
    np.testing.assert_array_equal(mj.opt.gravity, model.object.gravity)
    tips = [mj.geom(fingertip_geom_name(name)).id for name in model.contact_names]
    mu = options.friction(model)
    for geom in (*tips, mj.geom('object/shape').id):
        assert mj.geom_condim[geom] == options.condim
        np.testing.assert_array_equal(mj.geom_solref[geom], options.solref)
    # MuJoCo mixes a pair's coefficients by their maximum: each contact gets its own μ.
    object_mu = mj.geom_friction[mj.geom('object/shape').id][0]
    for geom, mu_i in zip(tips, mu, strict=True):
        assert max(mj.geom_friction[geom][0], object_mu) == mu_i
    for k, name in enumerate(model.joint_names):
        joint = mj.joint(name)
        np.testing.assert_array_equal(
            joint.range, [model.joint_lower_limits[k], model.joint_upper_limits[k]]
        )
        limit = model.effort_limits[k]
        np.testing.assert_array_equal(mj.actuator(name).ctrlrange, [-limit, limit])
    # Only fingertip–object pairs can collide.
    for a in range(mj.ngeom):
        for b in range(mj.ngeom):
            collide = (mj.geom_contype[a] & mj.geom_conaffinity[b]) or (
                mj.geom_contype[b] & mj.geom_conaffinity[a]
            )
            expected = {a, b} in [{tip, mj.geom('object/shape').id} for tip in tips]
            assert bool(collide) == expected
