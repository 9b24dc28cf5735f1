"""The compiled nominal controller equals its numpy formulation to the last bit.

``nominal_oracle`` is the law as numpy expressions and Pinocchio's Euler functions; the
controller (kernels between numpy's solves) and the Euler kernels must give the very same
numbers, field by field, at random states and references of the paper's hand (m = 3n), of
synthetic redundant hands (m > 3n: the null-space term) and of the four-finger hand.
"""

from __future__ import annotations

import dataclasses
import math
import re

from grasp_states import CONFIG_DIR, paper_model, random_configuration
import nominal_oracle as oracle
import numpy as np
import pinocchio as pin
import pytest
from test_nominal import synthetic_state

from grasp_safety_filter.control import euler_kernel, pose_error
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
def test_controller_equals_the_numpy_formulation_bit_for_bit(kind, arg):
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
            assert np.array_equal(actual, expected[name]), (name, actual - expected[name])


@pytest.mark.parametrize('seed', range(3))
def test_paper_reference_equals_the_numpy_formulation_bit_for_bit(seed):
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
            assert np.array_equal(actual, wanted)


def random_rotations(rng, count):
    """Random rotations, with gimbal-lock, half-turn and axis-aligned ones among them."""
    for k in range(count):
        kind = k % 4
        if kind == 0:
            yield pin.exp3(rng.normal(size=3) * 2.0)
        elif kind == 1:
            yield oracle_matrix(rng.uniform(-4.0, 4.0, 3))
        elif kind == 2:
            pitch = rng.choice([-1.0, 1.0]) * math.pi / 2 + rng.normal() * 1e-9
            yield oracle_matrix([rng.uniform(-4.0, 4.0), pitch, rng.uniform(-4.0, 4.0)])
        else:
            yield oracle_matrix(rng.choice([0.0, math.pi, -math.pi, math.pi / 2], 3))


def oracle_matrix(phi):
    return np.asarray(pin.rpy.rpyToMatrix(np.asarray(phi, dtype=float)))


def test_euler_functions_equal_pinocchio_and_numpy_bit_for_bit():
    rng = np.random.default_rng(3)
    for R in random_rotations(rng, 2000):
        assert np.array_equal(pose_error.euler_from_matrix(R), oracle.euler_from_matrix(R))
        phi = rng.uniform(-4.0, 4.0, 3)
        twist, r_dot, r_ddot = rng.normal(size=(3, 6))
        pairs = [
            (
                pose_error.euler_rates_from_twist(phi, twist),
                oracle.euler_rates_from_twist(phi, twist),
            ),
            (pose_error.twist_from_euler(phi, r_dot), oracle.twist_from_euler(phi, r_dot)),
            (
                pose_error.acceleration_from_euler(phi, r_dot, r_ddot),
                oracle.acceleration_from_euler(phi, r_dot, r_ddot),
            ),
            (
                pose_error.euler_accelerations_from_acceleration(phi, r_dot, r_ddot),
                oracle.euler_accelerations_from_acceleration(phi, r_dot, r_ddot),
            ),
            (pose_error.euler_rate_jacobian(phi), oracle.euler_rate_jacobian(phi)),
            (
                pose_error.euler_rate_jacobian_dot(phi, r_dot[3:]),
                oracle.euler_rate_jacobian_dot(phi, r_dot[3:]),
            ),
        ]
        for actual, expected in pairs:
            assert np.array_equal(actual, expected)


def test_pose_error_wraps_as_numpy_remainder_bit_for_bit():
    rng = np.random.default_rng(4)
    special = [math.pi, -math.pi, 3 * math.pi, 2 * math.pi, 0.0, -0.0, 1e-300, -1e-300]
    for k in range(3000):
        r_reference = rng.uniform(-10.0, 10.0, 6)
        r_reference[3 + k % 3] = special[k % len(special)]
        r_object = rng.uniform(-10.0, 10.0, 6) if k % 2 else np.zeros(6)
        expected = oracle.euler_pose_error(r_reference, r_object)
        assert np.array_equal(pose_error.euler_pose_error(r_reference, r_object), expected)
        angle = r_reference[3 + k % 3]
        assert euler_kernel.wrap_angle(angle) == oracle.wrap_angle(angle)


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
