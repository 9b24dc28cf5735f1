"""Reference sources and Euler-coordinate conventions, checked against finite differences."""

import math

import numpy as np
import pinocchio as pin
import pytest

from grasp_safety_filter.control.pose_error import (
    acceleration_from_euler,
    euler_accelerations_from_acceleration,
    euler_from_matrix,
    euler_pose_error,
    euler_rate_jacobian,
    euler_rate_jacobian_dot,
    euler_rates_from_angular_velocity,
    euler_rates_from_twist,
    matrix_from_euler,
    twist_from_euler,
    wrap_angle,
)
from grasp_safety_filter.control.reference import (
    PaperReference,
    Pose,
    ReferenceSample,
    TopicReference,
)

H = 1e-5


def rot_x(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def rot_y(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def rot_z(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def angular_velocity_fd(R_of_t, t, h=H):
    """Palm-frame angular velocity from a central difference of R(t): log(R+ R-^T) / 2h."""
    return pin.log3(R_of_t(t + h) @ R_of_t(t - h).T) / (2 * h)


EULER_CASES = [
    np.array([0.0, 0.0, 0.0]),
    np.array([0.3, -0.4, 2.9]),
    np.array([-2.5, 1.2, -3.0]),
    np.array([1.0, -1.3, 0.7]),
]
RATE = np.array([0.7, -0.5, 1.3])


@pytest.mark.parametrize('phi', EULER_CASES)
def test_matrix_from_euler_is_extrinsic_zyx(phi):
    roll, pitch, yaw = phi
    np.testing.assert_allclose(
        matrix_from_euler(phi), rot_z(yaw) @ rot_y(pitch) @ rot_x(roll), atol=1e-15
    )
    np.testing.assert_allclose(euler_from_matrix(matrix_from_euler(phi)), phi, atol=1e-12)


@pytest.mark.parametrize('phi', EULER_CASES)
def test_euler_rate_jacobian_gives_palm_angular_velocity(phi):
    w_fd = angular_velocity_fd(lambda s: matrix_from_euler(phi + s * RATE), 0.0)
    np.testing.assert_allclose(euler_rate_jacobian(phi) @ RATE, w_fd, atol=1e-8)
    np.testing.assert_allclose(
        euler_rates_from_angular_velocity(phi, euler_rate_jacobian(phi) @ RATE), RATE, atol=1e-12
    )


@pytest.mark.parametrize('phi', EULER_CASES)
def test_euler_rate_jacobian_dot_matches_finite_difference(phi):
    E_dot_fd = (euler_rate_jacobian(phi + H * RATE) - euler_rate_jacobian(phi - H * RATE)) / (
        2 * H
    )
    np.testing.assert_allclose(euler_rate_jacobian_dot(phi, RATE), E_dot_fd, atol=1e-8)


@pytest.mark.parametrize('phi', EULER_CASES)
def test_acceleration_from_euler_matches_second_difference(phi):
    r = np.concatenate(([0.1, -0.2, 0.3], phi))
    r_dot = np.array([0.2, 0.1, -0.3, *RATE])
    r_ddot = np.array([-0.4, 0.5, 0.6, 0.9, -0.8, 0.2])

    def twist_at(s):
        return twist_from_euler((r + s * r_dot + 0.5 * s * s * r_ddot)[3:], r_dot + s * r_ddot)

    acceleration_fd = (twist_at(H) - twist_at(-H)) / (2 * H)
    acceleration = acceleration_from_euler(phi, r_dot, r_ddot)
    np.testing.assert_allclose(acceleration, acceleration_fd, atol=1e-8)
    np.testing.assert_allclose(
        euler_accelerations_from_acceleration(phi, r_dot, acceleration), r_ddot, atol=1e-12
    )


@pytest.mark.parametrize(
    ('angle', 'expected'),
    [
        (0.0, 0.0),
        (math.pi, math.pi),
        (-math.pi, math.pi),
        (1.5 * math.pi, -0.5 * math.pi),
        (-4.0, 2 * math.pi - 4.0),
        (7 * math.pi + 0.1, -math.pi + 0.1),
    ],
)
def test_wrap_angle(angle, expected):
    assert wrap_angle(angle) == pytest.approx(expected, abs=1e-12)


def test_pose_error_is_continuous_through_the_yaw_branch_cut():
    # Reference yaw sweeps 2.5 -> -5.5 rad (through -pi and -3 pi); the object lags by 0.3
    # rad and is measured through its rotation matrix, so its yaw jumps by 2 pi.
    lag = 0.3
    for yaw_ref in np.linspace(2.5, -5.5, 401):
        R_object = matrix_from_euler([0.1, -0.2, yaw_ref + lag])
        r_object = np.concatenate(([0.0, 0.0, 0.0], euler_from_matrix(R_object)))
        r_reference = np.array([0.0, 0.0, 0.0, 0.1, -0.2, yaw_ref])
        np.testing.assert_allclose(
            euler_pose_error(r_reference, r_object), [0, 0, 0, 0, 0, -lag], atol=1e-9
        )


def random_pose(rng):
    phi = rng.uniform([-math.pi, -1.2, -math.pi], [math.pi, 1.2, math.pi])
    return Pose(rng.normal(size=3) * 0.1, matrix_from_euler(phi))


def test_paper_reference_starts_at_the_initial_pose_at_rest():
    pose = random_pose(np.random.default_rng(0))
    reference = PaperReference(pose, t0=2.0)
    sample = reference.sample(2.0)
    np.testing.assert_allclose(sample.pose.p_in_palm, pose.p_in_palm, atol=1e-15)
    np.testing.assert_allclose(sample.pose.R_to_palm, pose.R_to_palm, atol=1e-12)
    np.testing.assert_allclose(sample.r_dot, 0.0, atol=1e-15)
    np.testing.assert_allclose(sample.twist, 0.0, atol=1e-15)
    assert not sample.stale


@pytest.mark.parametrize('t', [0.0, 0.3, 1.7, math.pi, 5.0, 12.4])
@pytest.mark.parametrize('frequency', [1.0, 2.3])
def test_paper_reference_derivatives_match_finite_differences(t, frequency):
    pose = random_pose(np.random.default_rng(1))
    reference = PaperReference(
        pose, amplitude=(0.05, -0.1, 0.25, 0.3, 0.2, 2.0), frequency=frequency
    )
    sample = reference.sample(t)
    r_dot_fd = (reference.sample(t + H).r - reference.sample(t - H).r) / (2 * H)
    r_ddot_fd = (reference.sample(t + H).r_dot - reference.sample(t - H).r_dot) / (2 * H)
    np.testing.assert_allclose(sample.r_dot, r_dot_fd, atol=1e-8)
    np.testing.assert_allclose(sample.r_ddot, r_ddot_fd, atol=1e-8)
    # Twist and acceleration against differences of the pose itself.
    v_fd = (reference.sample(t + H).pose.p_in_palm - reference.sample(t - H).pose.p_in_palm) / (
        2 * H
    )
    w_fd = angular_velocity_fd(lambda s: reference.sample(s).pose.R_to_palm, t)
    np.testing.assert_allclose(sample.twist, np.concatenate((v_fd, w_fd)), atol=1e-7)
    acceleration_fd = (reference.sample(t + H).twist - reference.sample(t - H).twist) / (2 * H)
    np.testing.assert_allclose(sample.acceleration, acceleration_fd, atol=1e-7)


def test_paper_reference_values_are_the_papers_cosines():
    pose = random_pose(np.random.default_rng(2))
    reference = PaperReference(pose)
    for t in (0.5, math.pi, 4.0):
        sample = reference.sample(t)
        # Position: 0.25 m amplitude along palm z only.
        np.testing.assert_allclose(
            sample.pose.p_in_palm - pose.p_in_palm, [0, 0, 0.25 * (math.cos(t) - 1)], atol=1e-15
        )
        # Orientation: turned about the palm Z axis by 2 (cos t - 1) rad.
        np.testing.assert_allclose(
            sample.pose.R_to_palm, rot_z(2 * (math.cos(t) - 1)) @ pose.R_to_palm, atol=1e-12
        )


def test_reference_sample_round_trips_through_pose_twist_acceleration():
    reference = PaperReference(
        random_pose(np.random.default_rng(3)), amplitude=(0.1, 0, 0.25, 0.4, -0.3, 2.0)
    )
    for t in (0.4, 2.2, 3.5):
        sample = reference.sample(t)
        again = ReferenceSample.from_pose(sample.pose, sample.twist, sample.acceleration)
        np.testing.assert_allclose(euler_pose_error(again.r, sample.r), 0.0, atol=1e-12)
        np.testing.assert_allclose(again.r_dot, sample.r_dot, atol=1e-12)
        np.testing.assert_allclose(again.r_ddot, sample.r_ddot, atol=1e-11)


def test_topic_reference_holds_until_first_sample_and_when_stale():
    initial = random_pose(np.random.default_rng(4))
    topic = TopicReference(initial, timeout=0.2)

    before = topic.sample(0.0)
    assert before.stale
    np.testing.assert_allclose(before.r, initial.euler)
    np.testing.assert_array_equal(before.r_dot, 0.0)
    assert topic.age(0.0) == math.inf

    target = Pose([0.01, 0.02, 0.03], matrix_from_euler([0.1, 0.0, -0.5]))
    twist = np.array([0.1, 0.0, -0.2, 0.0, 0.3, 0.5])
    acceleration = np.array([0.0, 0.4, 0.0, -0.1, 0.0, 0.2])
    sent = ReferenceSample.from_pose(target, twist, acceleration)
    topic.update(sent, stamp=1.0)

    for t in (1.0, 1.1, 1.2):  # fresh up to and including the timeout
        fresh = topic.sample(t)
        assert not fresh.stale and not topic.is_stale(t)
        np.testing.assert_array_equal(fresh.r_dot, sent.r_dot)
        np.testing.assert_allclose(fresh.twist, twist, atol=1e-12)
        np.testing.assert_allclose(fresh.acceleration, acceleration, atol=1e-12)

    stale = topic.sample(1.25)
    assert stale.stale and topic.is_stale(1.25)
    assert topic.age(1.25) == pytest.approx(0.25)
    np.testing.assert_array_equal(stale.r, sent.r)  # last pose held...
    np.testing.assert_array_equal(stale.r_dot, 0.0)  # ...with zero feed-forward
    np.testing.assert_array_equal(stale.r_ddot, 0.0)

    topic.update(ReferenceSample.from_pose(initial), stamp=1.3)
    assert not topic.sample(1.35).stale


@pytest.mark.parametrize(
    ('build', 'message'),
    [
        (lambda: Pose([0, 0], np.eye(3)), 'p_in_palm'),
        (lambda: Pose([0, 0, 0], 2 * np.eye(3)), 'R_to_palm'),
        (lambda: Pose([0, 0, 0], np.diag([1.0, 1.0, -1.0])), 'R_to_palm'),
        (lambda: PaperReference(Pose([0, 0, 0], np.eye(3)), amplitude=(0, 0, 1)), 'amplitude'),
        (lambda: PaperReference(Pose([0, 0, 0], np.eye(3)), frequency=-1.0), 'frequency'),
        (lambda: TopicReference(Pose([0, 0, 0], np.eye(3)), timeout=0.0), 'timeout'),
        (lambda: ReferenceSample(r=[0, 0, 0, 0, 0, math.nan]), 'ReferenceSample.r'),
    ],
)
def test_invalid_construction_names_the_argument(build, message):
    with pytest.raises(ValueError, match=message):
        build()


def test_euler_rates_from_twist_inverts_twist_from_euler():
    phi = np.array([0.4, -0.9, 2.0])
    r_dot = np.array([0.1, 0.2, 0.3, *RATE])
    np.testing.assert_allclose(
        euler_rates_from_twist(phi, twist_from_euler(phi, r_dot)), r_dot, atol=1e-12
    )
