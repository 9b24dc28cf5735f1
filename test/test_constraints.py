"""Constraint families: barrier signs, row names and shapes, rows against their formulas."""

import math

import numpy as np
import pytest
from synthetic_state import synthetic_state, SyntheticHand, with_fields

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints import (
    ActuatorLimits,
    ConstraintFamily,
    FingertipWorkspaceBarrier,
    FrictionPyramid,
    JointLimitBarrier,
    stack_constraints,
)
from grasp_safety_filter.model.affine import AffineMap

HAND = SyntheticHand()
WORKSPACE = (-1.4, 1.4, -3.0, -0.1)
ALPHAS = [
    (ClassKFunction(), ClassKFunction()),
    (ClassKFunction('linear', 2.5), ClassKFunction('linear', 7.0)),
    (ClassKFunction('cubic', 0.5), ClassKFunction('linear', 3.0)),
]


def alpha_value(alpha, h):
    return alpha.gain * h**3 if alpha.kind == 'cubic' else alpha.gain * h


def alpha_slope(alpha, h):
    return 3.0 * alpha.gain * h**2 if alpha.kind == 'cubic' else alpha.gain


def zcbf_residual(alpha1, alpha2, h, h_dot, h_ddot):
    """Evaluate the documented ZCBF row ``h_ddot + alpha_1'(h) h_dot + alpha_2(B)``."""
    B = h_dot + alpha_value(alpha1, h)
    return h_ddot + alpha_slope(alpha1, h) * h_dot + alpha_value(alpha2, B)


def make_families(alpha1=None, alpha2=None, faces=8, margin=0.05, mu=0.9):
    return {
        'no_slip': FrictionPyramid(HAND.contact_names, mu, faces, margin),
        'joint_limits': JointLimitBarrier(
            HAND.joint_names, HAND.joint_lower_limits, HAND.joint_upper_limits, alpha1, alpha2
        ),
        'fingertip_workspace': FingertipWorkspaceBarrier(
            HAND.contact_names, *WORKSPACE, alpha1, alpha2
        ),
        'actuator_limits': ActuatorLimits(
            HAND.joint_names, -HAND.effort_limits, HAND.effort_limits
        ),
    }


@pytest.fixture
def rng():
    return np.random.default_rng(20181217)


# -- extended class-K functions ------------------------------------------------------------


@pytest.mark.parametrize(
    'kind,gain', [('cubic', 1.0), ('cubic', 0.3), ('linear', 1.0), ('linear', 4.0)]
)
def test_class_k_is_increasing_through_zero_and_its_derivative_matches_finite_differences(
    kind, gain
):
    alpha = ClassKFunction(kind, gain)
    h = np.linspace(-2.0, 2.0, 401)
    values = alpha.value(h)
    assert alpha.value(np.array(0.0)) == 0.0
    assert np.all(np.diff(values) > 0.0)
    assert np.allclose(values, alpha_value(alpha, h))
    step = 1e-6
    finite_difference = (alpha.value(h + step) - alpha.value(h - step)) / (2 * step)
    assert np.allclose(alpha.derivative(h), finite_difference, rtol=1e-6, atol=1e-8)
    assert np.shape(alpha.derivative(h)) == h.shape


@pytest.mark.parametrize(
    'kwargs,message',
    [
        ({'kind': 'quadratic'}, 'kind'),
        ({'gain': 0.0}, 'gain'),
        ({'gain': -1.0}, 'gain'),
        ({'gain': float('nan')}, 'gain'),
        ({'gain': True}, 'gain'),
        ({'gain': '1'}, 'gain'),
    ],
)
def test_class_k_rejects_bad_arguments_naming_them(kwargs, message):
    with pytest.raises(ValueError, match=message):
        ClassKFunction(**kwargs)


# -- barrier signs (h > 0 inside, < 0 outside) --------------------------------------------------


def joint_state(rng, q):
    return synthetic_state(rng, HAND, q=q)


def workspace_state(rng, xi_cf):
    return synthetic_state(rng, HAND, xi_cf=xi_cf)


def force_state(rng, forces, u):
    """Make a state whose contact forces at torque u are ``forces`` (n, 3)."""
    state = synthetic_state(rng, HAND)
    F = state.contact_force.matrix
    return with_fields(state, contact_force=AffineMap(F, np.ravel(forces) - F @ u))


def row_index(family, name):
    return family.names.index(f'{family.family}/{name}')


LIMIT_CASES = [
    # (joint index, value relative to limits, row that must be negative)
    (0, 'above', 'finger1_joint1/upper'),
    (1, 'below', 'finger1_joint2/lower'),
    (5, 'above', 'finger2_joint3/upper'),
    (7, 'below', 'finger3_joint2/lower'),
]


@pytest.mark.parametrize('joint,side,row', LIMIT_CASES)
def test_joint_limit_barriers_are_positive_inside_and_negative_outside(rng, joint, side, row):
    family = make_families()['joint_limits']
    lo, hi = HAND.joint_lower_limits, HAND.joint_upper_limits
    q = (lo + hi) / 2
    h_inside = family.values(joint_state(rng, q)).h
    assert np.all(h_inside > 0.0)
    q_out = q.copy()
    q_out[joint] = hi[joint] + 0.1 if side == 'above' else lo[joint] - 0.1
    h = family.values(joint_state(rng, q_out)).h
    negative = {family.names[i].split('/', 1)[1] for i in np.flatnonzero(h < 0.0)}
    assert negative == {row}
    assert h[row_index(family, row)] == pytest.approx(-0.1)


WORKSPACE_CASES = [
    (0, (-1.5, -1.0), 'finger1/a_min'),
    (1, (1.45, -1.0), 'finger2/a_max'),
    (2, (0.0, -3.1), 'finger3/b_min'),
    (0, (0.2, -0.05), 'finger1/b_max'),
]


@pytest.mark.parametrize('contact,coordinates,row', WORKSPACE_CASES)
def test_workspace_barriers_are_positive_inside_and_negative_outside(
    rng, contact, coordinates, row
):
    family = make_families()['fingertip_workspace']
    xi = np.array([[0.1, -1.5]] * 3)
    assert np.all(family.values(workspace_state(rng, xi)).h > 0.0)
    xi[contact] = coordinates
    h = family.values(workspace_state(rng, xi)).h
    negative = {family.names[i].split('/', 1)[1] for i in np.flatnonzero(h < 0.0)}
    assert negative == {row}


def test_friction_margins_are_positive_inside_the_pyramid_and_negative_outside(rng):
    family = make_families(faces=8)['no_slip']
    u = rng.normal(size=HAND.n_joints)
    mu_face = 0.9 * math.cos(math.pi / 8)  # pyramid apothem per newton of normal force
    inside = [[0.0, 0.0, 2.0], [0.99 * mu_face * 2.0, 0.0, 2.0], [0.3, -0.4, 1.0]]
    h = family.values(force_state(rng, inside, u), u).h
    assert np.all(h > 0.0)
    # Tangential force beyond mu f_n in direction 30 degrees: outside the cone, some face < 0.
    tangential = 0.95 * 2.0 * np.array([math.cos(0.5), math.sin(0.5)])
    outside = [[*tangential, 2.0], [0.0, 0.0, -1.0], [0.0, 0.0, 2.0]]
    h = family.values(force_state(rng, outside, u), u).h.reshape(3, 8)
    assert np.any(h[0] < 0.0)
    assert np.all(h[1] < 0.0)  # pulling contact: every face violated
    assert np.all(h[2] > 0.0)


@pytest.mark.parametrize('faces', [3, 4, 8, 16])
def test_friction_pyramid_is_inscribed_in_the_cone(rng, faces):
    """Check the pyramid is inscribed: inside it means inside the cone ||f_t|| <= mu f_n.

    Each face touches the cone along its centre line; every force on the cone violates or
    touches a face.
    """
    mu = 0.9
    family = FrictionPyramid(HAND.contact_names, mu, faces, 0.0)
    u = np.zeros(HAND.n_joints)
    inside = 0
    for _ in range(100):
        forces = rng.normal(size=(3, 3)) + np.array([0.0, 0.0, 1.0])
        h = family.values(force_state(rng, forces, u), u).h.reshape(3, faces)
        for force, margins in zip(forces, h, strict=True):
            if np.all(margins >= 0.0):
                inside += 1
                assert np.hypot(force[0], force[1]) <= mu * force[2] + 1e-12
    assert inside > 20
    for angle in np.linspace(0.0, 2 * np.pi, 37):
        on_cone = [mu * math.cos(angle), mu * math.sin(angle), 1.0]
        assert family.values(force_state(rng, [on_cone] * 3, u), u).h.min() <= 1e-12
    theta = 2 * np.pi / faces  # centre line of face j = 1
    apothem = mu * math.cos(math.pi / faces)
    touching = [apothem * math.cos(theta), apothem * math.sin(theta), 1.0]
    h = family.values(force_state(rng, [touching] * 3, u), u).h.reshape(3, faces)
    assert h[0, 1] == pytest.approx(0.0, abs=1e-12)
    assert np.all(np.delete(h[0], 1) > 0.0)


def test_actuator_margins_are_positive_inside_the_box_and_negative_outside():
    family = make_families()['actuator_limits']
    u = np.zeros(HAND.n_joints)
    assert np.all(family.values(None, u).h > 0.0)
    u[3] = 6.0
    h = family.values(None, u).h
    assert {family.names[i] for i in np.flatnonzero(h < 0.0)} == {
        'actuator_limits/finger2_joint1/upper'
    }
    assert np.array_equal(family.clip(u), np.minimum(u, 5.0))


# -- row shapes and names -----------------------------------------------------------------


def test_row_shapes_and_names(rng):
    families = make_families(faces=6)
    state = synthetic_state(rng, HAND)
    expected = {
        'no_slip': [f'no_slip/finger{i}/face{j}' for i in (1, 2, 3) for j in range(6)],
        'joint_limits': [
            f'joint_limits/finger{i}_joint{j}/{side}'
            for i in (1, 2, 3)
            for j in (1, 2, 3)
            for side in ('upper', 'lower')
        ],
        'fingertip_workspace': [
            f'fingertip_workspace/finger{i}/{row}'
            for i in (1, 2, 3)
            for row in ('a_min', 'a_max', 'b_min', 'b_max')
        ],
        'actuator_limits': [
            f'actuator_limits/finger{i}_joint{j}/{side}'
            for i in (1, 2, 3)
            for j in (1, 2, 3)
            for side in ('lower', 'upper')
        ],
    }
    for name, family in families.items():
        assert isinstance(family, ConstraintFamily)
        rows = family.rows(state)
        assert list(rows.names) == expected[name] == list(family.names)
        assert rows.A.shape == (len(expected[name]), HAND.n_joints)
        assert rows.lower.shape == (len(expected[name]),)
        assert family.values(state, np.zeros(HAND.n_joints)).h.shape == (len(expected[name]),)


# -- each row against its documented inequality, evaluated independently --------------------


@pytest.mark.parametrize(
    'faces,margin,mu', [(8, 0.05, 0.9), (4, 0.0, 0.5), (5, 0.2, (0.3, 0.9, 1.2))]
)
def test_no_slip_rows_match_the_pyramid_inequality(rng, faces, margin, mu):
    family = FrictionPyramid(HAND.contact_names, mu, faces, margin)
    mus = np.broadcast_to(mu, (3,))
    for _ in range(5):
        state = synthetic_state(rng, HAND, speed=0.3)
        rows = family.rows(state)
        u = rng.normal(scale=3.0, size=HAND.n_joints)
        forces = state.contact_force(u).reshape(3, 3)
        expected = []
        for i in range(3):
            fx, fy, fn = forces[i]
            for j in range(faces):
                theta = 2 * math.pi * j / faces
                # cos fx + sin fy - mu cos(pi/l) fn <= -eps  <=>  -(lhs) - eps >= 0
                apothem = mus[i] * math.cos(math.pi / faces)
                lhs = math.cos(theta) * fx + math.sin(theta) * fy - apothem * fn
                expected.append(-lhs - margin)
        assert np.allclose(rows.residual(u), expected, rtol=1e-10, atol=1e-10)
        assert np.allclose(family.values(state, u).h - margin, expected, rtol=1e-10, atol=1e-10)


@pytest.mark.parametrize('alpha1,alpha2', ALPHAS)
def test_joint_limit_rows_match_the_zcbf_inequality(rng, alpha1, alpha2):
    family = JointLimitBarrier(
        HAND.joint_names, HAND.joint_lower_limits, HAND.joint_upper_limits, alpha1, alpha2
    )
    for _ in range(5):
        state = synthetic_state(rng, HAND, speed=0.5)
        rows = family.rows(state)
        u = rng.normal(scale=3.0, size=HAND.n_joints)
        ddq = state.joint_acceleration(u)
        expected = []
        for j in range(HAND.n_joints):
            for h, h_dot, h_ddot in (
                (HAND.joint_upper_limits[j] - state.q[j], -state.dq[j], -ddq[j]),
                (state.q[j] - HAND.joint_lower_limits[j], state.dq[j], ddq[j]),
            ):
                expected.append(zcbf_residual(alpha1, alpha2, h, h_dot, h_ddot))
        assert np.allclose(rows.residual(u), expected, rtol=1e-10, atol=1e-9)


@pytest.mark.parametrize('alpha1,alpha2', ALPHAS)
def test_workspace_rows_match_the_zcbf_inequality(rng, alpha1, alpha2):
    family = FingertipWorkspaceBarrier(HAND.contact_names, *WORKSPACE, alpha1, alpha2)
    a_min, a_max, b_min, b_max = WORKSPACE
    for _ in range(5):
        state = synthetic_state(rng, HAND, speed=0.5)
        rows = family.rows(state)
        u = rng.normal(scale=3.0, size=HAND.n_joints)
        accelerations = state.xi_cf_ddot(u).reshape(3, 2)
        expected = []
        for i in range(3):
            (a, b), (a_dot, b_dot), (a_ddot, b_ddot) = (
                state.xi_cf[i],
                state.xi_cf_dot[i],
                accelerations[i],
            )
            for h, h_dot, h_ddot in (
                (a - a_min, a_dot, a_ddot),
                (a_max - a, -a_dot, -a_ddot),
                (b - b_min, b_dot, b_ddot),
                (b_max - b, -b_dot, -b_ddot),
            ):
                expected.append(zcbf_residual(alpha1, alpha2, h, h_dot, h_ddot))
        assert np.allclose(rows.residual(u), expected, rtol=1e-10, atol=1e-9)


def test_actuator_rows_match_the_box(rng):
    family = make_families()['actuator_limits']
    u = rng.normal(scale=4.0, size=HAND.n_joints)
    expected = np.column_stack((u + HAND.effort_limits, HAND.effort_limits - u)).ravel()
    assert np.allclose(family.rows(None).residual(u), expected)
    assert np.allclose(family.values(None, u).h, expected)


def test_stack_constraints_concatenates_rows_in_order(rng):
    families = make_families()
    order = [families[name] for name in ('no_slip', 'joint_limits', 'fingertip_workspace')]
    state = synthetic_state(rng, HAND)
    stacked = stack_constraints(order, state)
    u = rng.normal(size=HAND.n_joints)
    assert stacked.names == sum((family.names for family in order), ())
    assert np.allclose(
        stacked.residual(u), np.concatenate([family.rows(state).residual(u) for family in order])
    )
    empty = stack_constraints([], state)
    assert empty.A.shape == (0, HAND.n_joints) and empty.names == ()


# -- the ZCBF keeps its set forward invariant --------------------------------------------


@pytest.mark.parametrize('alpha1,alpha2', ALPHAS)
def test_joint_limit_rows_keep_a_driven_joint_inside_its_limits(rng, alpha1, alpha2):
    """Check forward invariance (Theorem 1) on a unit-inertia joint (ddq = u).

    Pushed hard at its upper limit, the row's minimal correction applied every step keeps
    h = q_max - q >= 0, while the unfiltered push crosses the limit.
    """
    base = synthetic_state(rng, HAND)
    family = JointLimitBarrier(['joint'], [-1.0], [1.0], alpha1, alpha2)
    dt, q, dq = 1e-3, 0.0, 0.0
    q_free, dq_free = 0.0, 0.0
    lowest = np.inf
    for _ in range(4000):
        state = with_fields(
            base,
            q=np.array([q]),
            dq=np.array([dq]),
            joint_acceleration=AffineMap(np.eye(1), np.zeros(1)),
        )
        rows = family.rows(state)
        u = np.array([5.0])  # pushes towards q_max = 1
        for A_row, lower in zip(rows.A, rows.lower, strict=True):
            if A_row @ u < lower:
                u = u + (lower - A_row @ u) / (A_row @ A_row) * A_row
        dq += dt * u[0]
        q += dt * dq
        lowest = min(lowest, 1.0 - q)
        dq_free += dt * 5.0
        q_free += dt * dq_free
    assert lowest >= -1e-3  # explicit Euler: only O(dt) overshoot
    assert 1.0 - q_free < -1.0


# -- construction and state validation ---------------------------------------------------------


@pytest.mark.parametrize(
    'build,message',
    [
        (lambda: FrictionPyramid(HAND.contact_names, 0.9, 2), 'faces'),
        (lambda: FrictionPyramid(HAND.contact_names, 0.9, 8.0), 'faces'),
        (lambda: FrictionPyramid(HAND.contact_names, 0.0), 'mu'),
        (lambda: FrictionPyramid(HAND.contact_names, [0.9, 0.9]), 'mu'),
        (lambda: FrictionPyramid(HAND.contact_names, 0.9, 8, -0.1), 'normal_force_margin'),
        (lambda: FrictionPyramid(['a', 'a', 'b'], 0.9), 'contact_names'),
        (lambda: FrictionPyramid([], 0.9), 'contact_names'),
        (lambda: FrictionPyramid('finger1', 0.9), 'contact_names'),
        (lambda: FrictionPyramid(['a/b'], 0.9), 'contact_names'),
        (lambda: JointLimitBarrier(['j1', 'j2'], [0.0, 1.0], [1.0, 1.0]), 'q_max'),
        (lambda: JointLimitBarrier(['j1'], [0.0], [np.inf]), 'q_max'),
        (lambda: JointLimitBarrier(['j1'], [0.0, 0.0], [1.0, 1.0]), 'q_min'),
        (lambda: JointLimitBarrier(['j1'], [0.0], [1.0], alpha1='cubic'), 'alpha1'),
        (lambda: FingertipWorkspaceBarrier(['c'], 1.0, -1.0, -3.0, 0.0), 'a_max'),
        (lambda: FingertipWorkspaceBarrier(['c'], -1.0, 1.0, 0.0, 0.0), 'b_max'),
        (lambda: FingertipWorkspaceBarrier(['c'], float('nan'), 1.0, -3.0, 0.0), 'a_min'),
        (lambda: ActuatorLimits(['j1', 'j2'], -1.0, [1.0, -2.0]), 'u_max'),
        (lambda: ActuatorLimits(['j1'], 'low', 1.0), 'u_min'),
    ],
)
def test_constructors_reject_bad_arguments_naming_them(build, message):
    with pytest.raises(ValueError, match=message):
        build()


@pytest.mark.parametrize(
    'family,field',
    [('joint_limits', 'q'), ('fingertip_workspace', 'xi_cf'), ('no_slip', 'contact_force')],
)
def test_rows_reject_a_state_of_another_hand(rng, family, field):
    other = synthetic_state(rng, SyntheticHand(n_fingers=2))
    with pytest.raises(ValueError, match=f'state.{field}'):
        make_families()[family].rows(other)
