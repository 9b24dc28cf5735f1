"""The compiled nominal controller against its numpy formulation.

``nominal_oracle`` is the law as numpy expressions and Pinocchio's Euler functions; the
controller (kernels between numpy's solves) must give the same numbers to round-off, field
by field, at random states and references of the paper's hand (m = 3n), of synthetic
redundant hands (m > 3n: the null-space term) and of the four-finger hand. (The Euler maps
themselves are checked against finite differences in test_reference.py.)
"""

from __future__ import annotations

import dataclasses
import re

from grasp_states import CONFIG_DIR, paper_model, random_configuration
import nominal_oracle as oracle
import numpy as np
import pinocchio as pin
import pytest
from test_nominal import synthetic_state

from grasp_safety_filter.control import pose_error
from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import PaperReference, Pose, ReferenceSample
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel

FIELDS = (
    'u',
    'u_manipulation_wrench',
    'u_internal',
    'u_null_space',
    'pose_error',
    'pose_error_rate',
    'object_acceleration_desired',
)
CONFIG = NominalConfig(kp=1.3, kd=2.1, kf=7.0, null_space_kp=20.0, null_space_kd=8.0)


def four_finger_state(seed):
    """Return a rolling state of the four-finger box grasp with random velocities."""
    params = load_node_parameters(CONFIG_DIR / 'four_finger_box.yaml', 'hand_sim_node')
    model = GraspModel.from_parameters(params, CONFIG_DIR)
    rng = np.random.default_rng(seed)
    q0 = np.array(params['initial.joint_positions'])
    p0 = np.array(params['initial.object_position'])
    p_object = p0 + rng.uniform(-0.002, 0.002, 3)
    R_object = pin.exp3(rng.uniform(-0.05, 0.05, 3))
    q = model.project_to_contact(q0 + rng.uniform(-0.02, 0.02, q0.size), p_object, R_object)
    twist = rng.normal(size=6) * np.array([0.05, 0.05, 0.05, 0.5, 0.5, 0.5])
    dq = model.rolling_joint_velocity(q, p_object, R_object, twist)
    dq = dq + rng.normal(size=q.size) * 0.1
    return model.state(0.2, q, dq, p_object, R_object, twist)


PAPER = paper_model()
STATES = (
    [('paper', seed) for seed in range(8)]
    + [('synthetic', (seed, 3, 9)) for seed in range(4)]
    + [('synthetic', (seed, 3, 12)) for seed in range(4)]
    + [('synthetic', (seed, 4, 16)) for seed in range(4)]
    + [('four_finger', seed) for seed in range(4)]
)


def make_state(kind, arg):
    if kind == 'paper':
        return random_configuration(PAPER, np.random.default_rng(arg)).state(PAPER)
    if kind == 'synthetic':
        return synthetic_state(*arg)
    return four_finger_state(arg)


def references(state, seed):
    """Return a paper reference at a random time, a random sample and the held pose."""
    rng = np.random.default_rng(seed)
    phi = pose_error.euler_from_matrix(state.R_object_to_palm) + rng.normal(size=3) * 0.3
    p_reference = state.p_object_in_palm + rng.normal(size=3) * 0.02
    pose = Pose(p_reference, pose_error.matrix_from_euler(phi))
    random_sample = ReferenceSample(
        r=pose.euler + rng.normal(size=6) * 2.0,
        r_dot=rng.normal(size=6),
        r_ddot=rng.normal(size=6),
    )
    hold = ReferenceSample.from_pose(Pose(state.p_object_in_palm, state.R_object_to_palm))
    return [PaperReference(pose).sample(rng.uniform(0.0, 20.0)), random_sample, hold]


@pytest.mark.parametrize(('kind', 'arg'), STATES)
def test_controller_equals_the_numpy_formulation(kind, arg):
    state = make_state(kind, arg)
    rng = np.random.default_rng(7)
    posture = state.q + rng.normal(size=state.q.size) * 0.1
    for reference in references(state, 11):
        controller = NominalController(CONFIG, posture=posture)
        output = controller.compute(state, reference)
        expected, rank_ok = oracle.compute(state, reference, CONFIG, posture)
        assert rank_ok
        for name in FIELDS:
            actual = getattr(output, name)
            assert actual.shape == expected[name].shape, name
            # Round-off of a few solves on inertias of 1e-6..1 kg m²: relative to the field.
            scale = 1.0 + np.abs(expected[name]).max()
            np.testing.assert_allclose(actual, expected[name], rtol=0.0, atol=1e-9 * scale)


@pytest.mark.parametrize('seed', range(3))
def test_paper_reference_equals_the_numpy_formulation(seed):
    rng = np.random.default_rng(seed)
    pose = Pose(rng.normal(size=3), pin.exp3(rng.normal(size=3)))
    amplitude = rng.normal(size=6)
    frequency, t0 = rng.uniform(0.1, 3.0), rng.uniform(-5.0, 5.0)
    reference = PaperReference(pose, amplitude, frequency, t0)
    r0 = oracle.euler_from_matrix(pose.R_to_palm)
    r0 = np.concatenate((pose.p_in_palm, r0))
    for t in rng.uniform(-100.0, 100.0, 50):
        sample = reference.sample(t)
        expected = oracle.paper_sample(r0, amplitude, frequency, t0, t)
        for actual, wanted in zip((sample.r, sample.r_dot, sample.r_ddot), expected, strict=True):
            np.testing.assert_allclose(actual, wanted, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize(
    ('field', 'bad', 'shape'),
    [
        ('G', lambda s: s.G[:, :-3], '(6, 9)'),
        ('h_bias', lambda s: s.h_bias[:-1], '(9,)'),
        ('R_contact_to_palm', lambda s: s.R_contact_to_palm[:2], '(3, 3, 3)'),
        ('twist_object', lambda s: s.twist_object.astype(np.float32), '(6,)'),
    ],
)
def test_a_state_array_of_the_wrong_shape_or_type_is_named_before_any_kernel(field, bad, shape):
    state = make_state('paper', 0)
    broken = dataclasses.replace(state, **{field: bad(state)})
    hold = ReferenceSample.from_pose(Pose(state.p_object_in_palm, state.R_object_to_palm))
    expected = rf'state\.{field}: expected float64 of shape {re.escape(shape)}'
    with pytest.raises(ValueError, match=expected):
        NominalController().compute(broken, hold)


def test_euler_functions_name_an_argument_of_the_wrong_shape():
    expected = r'euler_from_matrix: R: expected shape \(3, 3\), got \(2, 2\)'
    with pytest.raises(ValueError, match=expected):
        pose_error.euler_from_matrix(np.eye(2))
    expected = r'acceleration_from_euler: r_ddot: expected shape \(6,\)'
    with pytest.raises(ValueError, match=expected):
        pose_error.acceleration_from_euler(np.zeros(3), np.zeros(6), np.zeros(5))
