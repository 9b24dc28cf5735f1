"""Nominal controller: computed-torque identity, internal force, error dynamics, config."""

import dataclasses
import math

from grasp_states import paper_model, random_configuration
import numpy as np
import pinocchio as pin
import pytest
from synthetic_state import constrained_dynamics, skew

from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.pose_error import (
    euler_from_matrix,
    euler_pose_error,
    euler_rate_jacobian,
    euler_rates_from_twist,
    matrix_from_euler,
)
from grasp_safety_filter.control.reference import (
    PaperReference,
    Pose,
    ReferenceSample,
    TopicReference,
)
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.grasp_state import GraspState


def grasp_map(p_contact, R_contact, p_object):
    """G = [R_pc,i ; (p_c,i - p_o)x R_pc,i], built here independently of the model."""
    blocks = zip(p_contact, R_contact, strict=True)
    return np.hstack([np.vstack((R, skew(p - p_object) @ R)) for p, R in blocks])


def synthetic_state(seed, n=3, m=9):
    """Build a random state whose affine maps solve the hand/object dynamics.

    The maps (``synthetic_state.constrained_dynamics``, written out independently of the
    model) obey the acceleration-level rolling constraint
    J_h ddq + J_h_dot dq = G^T x_ddot + G_dot^T x_dot (DESIGN.md §3).
    """
    rng = np.random.default_rng(seed)
    p_object = rng.normal(size=3) * 0.1
    R_object = matrix_from_euler(rng.uniform([-3, -1.2, -3], [3, 1.2, 3]))
    twist = rng.normal(size=6) * np.array([0.2, 0.2, 0.2, 1.5, 1.5, 1.5])
    p_contact = p_object + rng.normal(size=(n, 3)) * 0.1
    R_contact = np.array([pin.exp3(rng.normal(size=3)) for _ in range(n)])
    G = grasp_map(p_contact, R_contact, p_object)
    U, _, Vt = np.linalg.svd(rng.normal(size=(3 * n, m)))
    J_h = U @ np.diag(rng.uniform(0.5, 2.0, 3 * n)) @ Vt[: 3 * n]
    B = rng.normal(size=(m, m))
    M_h = B @ B.T * 0.01 + 0.02 * np.eye(m)
    dq = np.linalg.lstsq(J_h, G.T @ twist, rcond=None)[0]
    gravity_torque = rng.normal(size=m)
    h_bias = gravity_torque + rng.normal(size=m) * 0.3
    Jh_dot_dq = rng.normal(size=3 * n) * 0.2
    G_dot_T_twist = rng.normal(size=3 * n) * 0.2
    mass = 0.11
    I_body = np.diag([1.2e-3, 1.5e-3, 0.9e-3])
    I_palm = R_object @ I_body @ R_object.T
    M_o = np.block([[mass * np.eye(3), np.zeros((3, 3))], [np.zeros((3, 3)), I_palm]])
    w = twist[3:]
    C_o_twist = np.concatenate((np.zeros(3), np.cross(w, I_palm @ w)))
    w_e = np.array([0.0, 0.0, -9.81 * mass, 0.0, 0.0, 0.0])

    B_ho, contact_force, joint_acceleration, object_acceleration = constrained_dynamics(
        M_h, h_bias, J_h, Jh_dot_dq, G, G_dot_T_twist, M_o, C_o_twist, w_e
    )
    zeros = np.zeros
    return GraspState(
        t=0.0,
        q=zeros(m),
        dq=dq,
        p_object_in_palm=p_object,
        R_object_to_palm=R_object,
        twist_object=twist,
        p_fingertip_in_palm=zeros((n, 3)),
        R_fingertip_to_palm=np.tile(np.eye(3), (n, 1, 1)),
        twist_fingertip=zeros((n, 6)),
        xi_cf=zeros((n, 2)),
        xi_co=zeros((n, 2)),
        psi=zeros(n),
        xi_cf_dot=zeros((n, 2)),
        xi_co_dot=zeros((n, 2)),
        psi_dot=zeros(n),
        penetration=zeros(n),
        p_contact_in_palm=p_contact,
        R_contact_to_palm=R_contact,
        M_h=M_h,
        h_bias=h_bias,
        gravity_torque=gravity_torque,
        J_fingertip=zeros((n, 6, m)),
        J_h=J_h,
        G=G,
        Jh_dot_dq=Jh_dot_dq,
        G_dot_T_twist=G_dot_T_twist,
        M_o=M_o,
        C_o_twist=C_o_twist,
        w_e=w_e,
        B_ho=B_ho,
        contact_force=contact_force,
        joint_acceleration=joint_acceleration,
        object_acceleration=object_acceleration,
        xi_cf_ddot=AffineMap(zeros((2 * n, m)), zeros(2 * n)),
        xi_co_rate_terms=lambda: (zeros((n, 2, 2)), zeros((n, 2))),
    )


MODEL = paper_model()


def real_state(seed):
    return random_configuration(MODEL, np.random.default_rng(seed)).state(MODEL)


STATES = [('synthetic', seed) for seed in range(4)] + [('model', seed) for seed in range(6)]


def make_state(kind, seed):
    return synthetic_state(seed) if kind == 'synthetic' else real_state(seed)


def references(state):
    """Return a paper reference mid-motion, a random one, and one holding the pose."""
    phi = euler_from_matrix(state.R_object_to_palm) + np.array([0.1, -0.1, 0.2])
    pose = Pose(state.p_object_in_palm + np.array([0.01, -0.02, 0.03]), matrix_from_euler(phi))
    rng = np.random.default_rng(99)
    random_sample = ReferenceSample(
        r=pose.euler + rng.normal(size=6) * 0.1,
        r_dot=rng.normal(size=6),
        r_ddot=rng.normal(size=6),
    )
    hold = ReferenceSample.from_pose(Pose(state.p_object_in_palm, state.R_object_to_palm))
    return [PaperReference(pose).sample(2.3), random_sample, hold]


@pytest.mark.parametrize(('kind', 'seed'), STATES)
def test_internal_force_lies_in_null_space_of_grasp_map(kind, seed):
    state = make_state(kind, seed)
    u_f = NominalController().internal_force(state)
    G = grasp_map(state.p_contact_in_palm, state.R_contact_to_palm, state.p_object_in_palm)
    np.testing.assert_allclose(G, state.G, atol=1e-12)
    assert np.linalg.norm(u_f) > 0.1  # a real squeeze, not a trivially zero one
    np.testing.assert_allclose(G @ u_f, 0.0, atol=1e-12)
    # Palm-frame forces point from each contact to the centroid, with magnitude k_f * distance.
    f_palm = np.einsum('nij,nj->ni', state.R_contact_to_palm, u_f.reshape(-1, 3))
    centroid = state.p_contact_in_palm.mean(axis=0)
    np.testing.assert_allclose(f_palm, 10.0 * (centroid - state.p_contact_in_palm), atol=1e-12)


@pytest.mark.parametrize(('kind', 'seed'), STATES)
def test_computed_torque_produces_the_desired_object_acceleration(kind, seed):
    state = make_state(kind, seed)
    controller = NominalController()
    for reference in references(state):
        output = controller.compute(state, reference)
        x_ddot = state.object_acceleration(output.u)
        scale = max(1.0, np.linalg.norm(output.object_acceleration_desired))
        np.testing.assert_allclose(
            x_ddot, output.object_acceleration_desired, rtol=0, atol=1e-9 * scale
        )
        # The hand moves consistently with the object (acceleration-level rolling constraint).
        ddq = state.joint_acceleration(output.u)
        np.testing.assert_allclose(
            state.J_h @ ddq + state.Jh_dot_dq,
            state.G.T @ x_ddot + state.G_dot_T_twist,
            atol=1e-8 * max(1.0, np.linalg.norm(ddq)),
        )


@pytest.mark.parametrize(('kind', 'seed'), STATES)
def test_squeeze_adds_exactly_the_internal_force_to_the_contact_forces(kind, seed):
    state = make_state(kind, seed)
    reference = references(state)[0]
    squeezing = NominalController(NominalConfig(kf=10.0)).compute(state, reference)
    loose = NominalController(NominalConfig(kf=0.0)).compute(state, reference)
    np.testing.assert_array_equal(loose.u_internal, 0.0)
    np.testing.assert_allclose(
        state.contact_force(squeezing.u) - state.contact_force(loose.u),
        squeezing.u_internal,
        atol=1e-9,
    )
    np.testing.assert_allclose(
        state.object_acceleration(squeezing.u), state.object_acceleration(loose.u), atol=1e-9
    )


def object_euler_second_derivative(state, x_ddot, h=2e-3):
    """Differentiate the object's Euler coordinates twice, centrally.

    The object moves with twist x_dot and acceleration x_ddot: R(s) = exp(w s + alpha s^2 / 2) R
    agrees with the rotation integrated from w(s) = w + alpha s up to O(s^3), odd terms
    cancel. Richardson extrapolation over h and h/2 removes the O(h^2) truncation error.
    """
    p, R, twist = state.p_object_in_palm, state.R_object_to_palm, state.twist_object

    def r_at(s):
        R_s = pin.exp3(twist[3:] * s + 0.5 * x_ddot[3:] * s * s) @ R
        p_s = p + twist[:3] * s + 0.5 * x_ddot[:3] * s * s
        return np.concatenate((p_s, euler_from_matrix(R_s)))

    r0 = r_at(0.0)

    def second_difference(h):
        # Through euler_pose_error so a principal-range crossing cannot add 2 pi.
        return (euler_pose_error(r_at(h), r0) - euler_pose_error(r0, r_at(-h))) / h**2

    return (4.0 * second_difference(h / 2) - second_difference(h)) / 3.0


@pytest.mark.parametrize(('kind', 'seed'), STATES)
def test_euler_error_obeys_the_linear_closed_loop(kind, seed):
    state = make_state(kind, seed)
    config = NominalConfig(kp=1.7, kd=2.5)
    controller = NominalController(config)
    for reference in references(state):
        output = controller.compute(state, reference)
        r_ddot_object = object_euler_second_derivative(state, output.object_acceleration_desired)
        e_ddot = reference.r_ddot - r_ddot_object
        np.testing.assert_allclose(
            e_ddot + config.kd * output.pose_error_rate + config.kp * output.pose_error,
            0.0,
            atol=1e-5,
        )
        # Without the P_dot term the loop would not be exact: the test can tell.
        phi = euler_from_matrix(state.R_object_to_palm)
        without = output.object_acceleration_desired.copy()
        without[3:] = (
            euler_rate_jacobian(phi)
            @ (
                reference.r_ddot
                + config.kp * output.pose_error
                + config.kd * output.pose_error_rate
            )[3:]
        )
        residual = reference.r_ddot - object_euler_second_derivative(state, without)
        residual += config.kd * output.pose_error_rate + config.kp * output.pose_error
        assert np.linalg.norm(residual) > 1e-2


def test_pose_error_and_rate_definitions():
    state = real_state(0)
    reference = references(state)[1]
    output = NominalController().compute(state, reference)
    r_object = np.concatenate((state.p_object_in_palm, euler_from_matrix(state.R_object_to_palm)))
    np.testing.assert_allclose(output.pose_error[:3], reference.r[:3] - r_object[:3])
    # Same rotation error whatever 2 pi branch the reference angles are given on.
    shifted = dataclasses.replace(reference, r=reference.r + np.array([0, 0, 0, 2, 0, -4]) * np.pi)
    np.testing.assert_allclose(
        NominalController().compute(state, shifted).u, output.u, rtol=1e-12, atol=1e-12
    )
    rates = euler_rates_from_twist(r_object[3:], state.twist_object)
    np.testing.assert_allclose(output.pose_error_rate, reference.r_dot - rates, atol=1e-12)


def test_closed_object_loop_tracks_the_paper_reference_through_the_yaw_cut():
    """Drive the object with x_ddot_des and compare the error with the analytic solution.

    x_ddot_des is the acceleration u_nom produces; e'' + kd e' + kp e = 0 with kd = 2.5,
    kp = 1 gives e(t) = c1 exp(-t/2) + c2 exp(-2t). The initial yaw of -2.5 rad makes the
    reference yaw (-2.5 + 2 (cos t - 1)) cross -pi, and the object's measured yaw jump to +pi.
    """
    base = real_state(0)
    controller = NominalController()
    reference = PaperReference(Pose([0.0, 0.0, 0.3], matrix_from_euler([0.0, 0.0, -2.5])))

    def acceleration(t, p, R, twist):
        state = dataclasses.replace(
            base, p_object_in_palm=p, R_object_to_palm=R, twist_object=twist
        )
        return controller.desired_object_acceleration(state, reference.sample(t))

    # Start off the reference: displaced, turned and moving.
    p = np.array([0.02, -0.01, 0.28])
    R = matrix_from_euler([0.1, -0.15, -2.3])
    twist = np.array([0.05, 0.0, -0.1, 0.2, -0.3, 0.4])
    _, e0, e0_dot = acceleration(0.0, p, R, twist)
    c2 = -(e0_dot + 0.5 * e0) / 1.5
    c1 = e0 - c2

    def derivative(t, y):
        p, R, twist = y
        x_ddot, _, _ = acceleration(t, p, R, twist)
        return twist[:3], skew(twist[3:]) @ R, x_ddot

    def step(y, slope, h):
        return tuple(a + h * b for a, b in zip(y, slope, strict=True))

    dt, t = 1e-3, 0.0
    y = (p, R, twist)
    crossed = False
    while t < 4.0 - 1e-12:
        k1 = derivative(t, y)
        k2 = derivative(t + dt / 2, step(y, k1, dt / 2))
        k3 = derivative(t + dt / 2, step(y, k2, dt / 2))
        k4 = derivative(t + dt, step(y, k3, dt))
        y = step(
            y,
            tuple(
                (b1 + 2 * b2 + 2 * b3 + b4) / 6
                for b1, b2, b3, b4 in zip(k1, k2, k3, k4, strict=True)
            ),
            dt,
        )
        t += dt
        crossed |= reference.sample(t).r[5] < -math.pi and euler_from_matrix(y[1])[2] > 0.0
        _, e, _ = acceleration(t, *y)
        expected = c1 * math.exp(-0.5 * t) + c2 * math.exp(-2.0 * t)
        np.testing.assert_allclose(e, expected, atol=1e-7)
    assert crossed
    assert np.linalg.norm(e) < 0.5 * np.linalg.norm(e0)


def test_stale_topic_reference_holds_pose_with_zero_feed_forward():
    state = real_state(1)
    pose = Pose(state.p_object_in_palm + np.array([0, 0, 0.01]), state.R_object_to_palm)
    topic = TopicReference(pose, timeout=0.1)
    sent = ReferenceSample.from_pose(pose, [0.1, 0, 0, 0, 0, 0.5], [0, 0.2, 0, 0, 0, 0])
    topic.update(sent, stamp=0.0)
    controller = NominalController()
    fresh = controller.compute(state, topic.sample(0.05))
    stale = controller.compute(state, topic.sample(0.5))
    assert not fresh.reference_stale and stale.reference_stale
    np.testing.assert_allclose(stale.pose_error, fresh.pose_error)
    held = controller.compute(state, ReferenceSample(r=sent.r))
    np.testing.assert_allclose(stale.u, held.u)
    assert np.linalg.norm(stale.u - fresh.u) > 1e-3


def test_config_defaults_are_the_papers():
    config = NominalConfig.from_parameters({'model.fingertip_radius': 0.06})
    assert (config.kp, config.kd, config.kf) == (1.0, 2.5, 10.0)
    assert config.reference_source == 'paper'
    assert config.amplitude == (0.0, 0.0, 0.25, 0.0, 0.0, 2.0)
    assert config.frequency == 1.0


def test_config_reads_flat_and_nested_parameters():
    flat = NominalConfig.from_parameters(
        {'gains.kp': 2.0, 'reference.source': 'topic', 'reference.timeout': 0.25}
    )
    nested = NominalConfig.from_parameters(
        {'gains': {'kp': 2.0}, 'reference': {'source': 'topic', 'timeout': 0.25}}
    )
    assert flat == nested
    assert flat.kp == 2.0 and flat.timeout == 0.25
    pose = Pose([0, 0, 0.3], np.eye(3))
    assert isinstance(flat.make_reference(pose), TopicReference)
    assert isinstance(NominalConfig().make_reference(pose), PaperReference)


@pytest.mark.parametrize(
    ('name', 'value', 'message'),
    [
        ('gains.kp', 0.0, 'expected > 0'),
        ('gains.kd', -2.5, 'expected > 0'),
        ('gains.kf', -1.0, 'expected >= 0'),
        ('gains.kp', 'fast', 'expected a double'),
        ('reference.source', 'joystick', 'expected one of'),
        ('reference.amplitude', [0.0, 0.25], 'expected 6 elements'),
        ('reference.amplitude', [0, 0, 0.25, 0, 0, math.inf], 'finite'),
        ('reference.frequency', -1.0, 'expected >= 0'),
        ('reference.timeout', 0.0, 'expected > 0'),
    ],
)
def test_config_errors_name_the_parameter(name, value, message):
    with pytest.raises(ParameterError, match=rf"'{name}'.*{message}"):
        NominalConfig.from_parameters({name: value})
