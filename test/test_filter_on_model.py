"""The safety filter on the paper's hand and cube: barriers, signs and optimality on real states.

The states come from the grasp model (:mod:`grasp_states`): the fingertips touch the cube
and roll with it. Every check is independent of the filter's own assembly: barrier rates
against finite differences along the constrained dynamics, barrier signs against the hand's
kinematics and the cone geometry, rows against the formulas written out here, optima
against two exact solvers (daqp and the Goldfarb-Idnani method), feasibility against a
linear program.
"""

from __future__ import annotations

from collections import Counter
import dataclasses
from dataclasses import replace
import math
from xml.etree import ElementTree

from grasp_states import (
    CONFIG_DIR,
    Configuration,
    moved,
    P_OBJECT_PAPER,
    paper_model,
    PAPER_MODEL_PARAMETERS,
    Q_PAPER,
    random_configuration,
)
import numpy as np
import pytest
from qp_reference import chebyshev_radius, hard_optimum, relaxed_optimum
import scipy.linalg

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints import (
    FingertipWorkspaceBarrier,
    FrictionPyramid,
    JointLimitBarrier,
)
from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.qp_solvers import BACKENDS
from grasp_safety_filter.control.safety_filter import (
    FilterStatus,
    SafetyFilter,
)
from grasp_safety_filter.io.paths import config_path
from grasp_tools.bench import record_filtered_run, Scenario

N_STATES = 20  # finite-difference checks
N_RANDOM_STATES = 240  # optimality checks, per configuration
EPS = 1e-6
RTOL = 1e-5
CERTIFIED = {FilterStatus.NOMINAL, FilterStatus.SOLVED}

CONFIGS = {
    'cubic': PAPER_CONFIG,
    'linear': replace(
        PAPER_CONFIG,
        alpha1_kind='linear', alpha1_gain=3.0, alpha2_kind='linear', alpha2_gain=8.0
    ),
}

#: Outward normal of each cube face label, object frame.
FACE_NORMALS = {
    f'{sign}{axis}': (1.0 if sign == '+' else -1.0) * np.eye(3)[index]
    for index, axis in enumerate('xyz')
    for sign in '+-'
}

#: Random configurations with these (spread, speed): near the paper's grasp and slow, up
#: to far from it and fast.
SPREAD_SPEED = ((0.1, 0.1), (0.25, 0.5), (0.3, 1.0), (0.4, 2.0))


@pytest.fixture(scope='module')
def model():
    return paper_model()


@pytest.fixture(scope='module')
def configurations(model):
    rng = np.random.default_rng(17)
    return [
        random_configuration(model, rng, *SPREAD_SPEED[i % len(SPREAD_SPEED)])
        for i in range(N_STATES)
    ]


# -- helpers -------------------------------------------------------------------------------


def alpha(kind, gain, h):
    """Return the extended class-K function, written out: ``k h^3`` or ``k h``."""
    return gain * h**3 if kind == 'cubic' else gain * h


def alpha_slope(kind, gain, h):
    """Return its derivative: ``3 k h^2`` or ``k``."""
    return 3.0 * gain * h**2 if kind == 'cubic' else np.full_like(h, gain)


def zcbf_residual(config, h, h_dot, h_ddot):
    """``h_ddot + alpha_1'(h) h_dot + alpha_2(h_dot + alpha_1(h))`` (>= 0 where the row holds)."""
    B = h_dot + alpha(config.alpha1_kind, config.alpha1_gain, h)
    return (
        h_ddot
        + alpha_slope(config.alpha1_kind, config.alpha1_gain, h) * h_dot
        + alpha(config.alpha2_kind, config.alpha2_gain, B)
    )


def joint_limit_barriers(model, state, u):
    """``(names, h, h_dot, h_ddot(u))`` of the joint limits from their definition."""
    ddq = state.joint_acceleration(u)
    names, h, h_dot, h_ddot = [], [], [], []
    for j, joint in enumerate(model.joint_names):
        names += [f'joint_limits/{joint}/upper', f'joint_limits/{joint}/lower']
        h += [model.joint_upper_limits[j] - state.q[j], state.q[j] - model.joint_lower_limits[j]]
        h_dot += [-state.dq[j], state.dq[j]]
        h_ddot += [-ddq[j], ddq[j]]
    return names, np.array(h), np.array(h_dot), np.array(h_ddot)


def workspace_barriers(model, state, u):
    """``(names, h, h_dot, h_ddot(u))`` of the fingertip-workspace box from its definition."""
    a_min, a_max, b_min, b_max = model.fingertip_workspace
    xi_ddot = state.xi_cf_ddot(u).reshape(-1, 2)
    names, h, h_dot, h_ddot = [], [], [], []
    for i, contact in enumerate(model.contact_names):
        (a, b), (a_dot, b_dot), (a_ddot, b_ddot) = state.xi_cf[i], state.xi_cf_dot[i], xi_ddot[i]
        names += [
            f'fingertip_workspace/{contact}/{row}' for row in ('a_min', 'a_max', 'b_min', 'b_max')
        ]
        h += [a - a_min, a_max - a, b - b_min, b_max - b]
        h_dot += [a_dot, -a_dot, b_dot, -b_dot]
        h_ddot += [a_ddot, -a_ddot, b_ddot, -b_ddot]
    return names, np.array(h), np.array(h_dot), np.array(h_ddot)


def pyramid_margins(model, config, state, u):
    """``(names, mu_i cos(pi/l) f_n - cos(th_j) f_x - sin(th_j) f_y)`` at ``f_c(u)``, N."""
    faces = config.pyramid_faces
    forces = state.contact_force(u).reshape(-1, 3)
    names, margins = [], []
    for contact, mu, (f_x, f_y, f_n) in zip(
        model.contact_names, model.friction_coefficient, forces, strict=True
    ):
        apothem = mu * math.cos(math.pi / faces)
        for j in range(faces):
            theta = 2.0 * math.pi * j / faces
            names.append(f'no_slip/{contact}/face{j}')
            margins.append(apothem * f_n - math.cos(theta) * f_x - math.sin(theta) * f_y)
    return names, np.array(margins)


def independent_residuals(model, config, state, u):
    """``(names, A u - lower)`` of every enabled row, in the filter's order, from the formulas."""
    names, residuals = [], []
    if config.no_slip_enabled:
        rows, margins = pyramid_margins(model, config, state, u)
        names += rows
        residuals.append(margins - config.normal_force_margin)
    if config.joint_limits_enabled:
        rows, *barrier = joint_limit_barriers(model, state, u)
        names += rows
        residuals.append(zcbf_residual(config, *barrier))
    if config.fingertip_workspace_enabled:
        rows, *barrier = workspace_barriers(model, state, u)
        names += rows
        residuals.append(zcbf_residual(config, *barrier))
    return tuple(names), np.concatenate(residuals)


def independent_rows(model, config, state):
    """``(names, A, lower)`` by evaluating the (affine) residuals at 0 and the unit torques."""
    m = model.n_joints
    names, at_zero = independent_residuals(model, config, state, np.zeros(m))
    A = np.column_stack(
        [independent_residuals(model, config, state, e)[1] - at_zero for e in np.eye(m)]
    )
    return names, A, -at_zero


def reference_optimum(A, lower, u_nom, effort):
    """``(feasible, u*)`` of ``min 1/2 ||u - u_nom||^2 s.t. A u >= lower, |u| <= effort``.

    daqp and the Goldfarb-Idnani method, both cold, must agree (:mod:`qp_reference`).
    """
    return hard_optimum(A, lower, u_nom, -effort, effort)


def reference_relaxed_optimum(A, lower, weights, u_nom, effort):
    """Solve the relaxed QP, written out from its documentation (:mod:`qp`), exactly.

    ``min 1/2 ||u - u_nom||^2 + 1/2 sum_r w_r s_r^2`` s.t. ``A_r u + ||A_r|| s_r >= lower_r``,
    ``|u| <= effort``, ``s >= 0`` (daqp and the Goldfarb-Idnani method agree).
    """
    return relaxed_optimum(A, lower, weights, u_nom, -effort, effort)[0]


def family_of(name):
    return name.split('/')[0]


def row_weights(config, names):
    """Slack weight of each row: its family's ``relaxation.<family>_weight``."""
    weights = {
        'no_slip': config.no_slip_weight,
        'joint_limits': config.joint_limits_weight,
        'fingertip_workspace': config.fingertip_workspace_weight,
    }
    return np.array([weights[family_of(name)] for name in names])


def assert_relative(actual, expected, what):
    """Elementwise ``|actual - expected| <= RTOL max(|expected|, 1e-3 max|expected|, 1e-6)``."""
    floor = max(1e-3 * float(np.max(np.abs(expected))), 1e-6)
    error = np.abs(actual - expected) / np.maximum(np.abs(expected), floor)
    worst = int(np.argmax(error))
    assert error[worst] <= RTOL, (
        f'{what}: relative error {error[worst]:.2e} > {RTOL:g} at entry {worst}: '
        f'{actual[worst]!r} vs {expected[worst]!r}'
    )


# -- 1. barrier rates along the constrained dynamics ---------------------------------------


def box_barrier(model, config, family):
    alpha1 = ClassKFunction(config.alpha1_kind, config.alpha1_gain)
    alpha2 = ClassKFunction(config.alpha2_kind, config.alpha2_gain)
    if family == 'joint_limits':
        return JointLimitBarrier(
            model.joint_names,
            model.joint_lower_limits,
            model.joint_upper_limits,
            alpha1,
            alpha2,
        )
    return FingertipWorkspaceBarrier(
        model.contact_names, *model.fingertip_workspace, alpha1, alpha2
    )


DEFINITIONS = {'joint_limits': joint_limit_barriers, 'fingertip_workspace': workspace_barriers}


@pytest.mark.parametrize('config_name', list(CONFIGS))
@pytest.mark.parametrize('family', list(DEFINITIONS))
def test_barrier_rates_match_finite_differences_along_the_constrained_dynamics(
    model, configurations, family, config_name
):
    """h_dot = d/dt h and h_ddot(u) = d/dt h_dot, with h_ddot(u) recovered from the row.

    The motion is the one the torque u produces: ``ddq(u)`` and ``x_o_ddot(u)`` of the
    constrained hand–object dynamics; the row ``A u - lower = h_ddot(u) + alpha_1'(h) h_dot
    + alpha_2(B)`` then gives ``h_ddot(u)`` once the class-K terms (evaluated here) are removed.
    """
    config = CONFIGS[config_name]
    barrier = box_barrier(model, config, family)
    rng = np.random.default_rng(23)
    for c in configurations:
        state = c.state(model)
        u = rng.normal(0.0, 1.0, model.n_joints)
        ddq, x_ddot = state.joint_acceleration(u), state.object_acceleration(u)
        h, h_dot = barrier.barrier(state)
        np.testing.assert_array_equal(barrier.values(state).h, h)
        rows = barrier.rows(state)
        h_ddot = rows.residual(u) - zcbf_residual(config, h, h_dot, np.zeros_like(h))
        # The same pieces from the family's documented definition, by row name.
        names, *defined = DEFINITIONS[family](model, state, u)
        assert tuple(names) == rows.names == barrier.names
        for what, value, expected in zip(('h', 'h_dot'), (h, h_dot), defined, strict=False):
            np.testing.assert_allclose(value, expected, rtol=0, atol=1e-12, err_msg=what)
        assert_relative(h_ddot, defined[2], f'{family} h_ddot(u) against its definition')

        after = barrier.barrier(moved(c, EPS, ddq, x_ddot).state(model))
        before = barrier.barrier(moved(c, -EPS, ddq, x_ddot).state(model))
        assert_relative(h_dot, (after[0] - before[0]) / (2 * EPS), f'{family} h_dot')
        assert_relative(h_ddot, (after[1] - before[1]) / (2 * EPS), f'{family} h_ddot(u)')


def test_pyramid_rows_match_the_pyramid_at_the_contact_forces(model, configurations):
    """The no-slip rows against the pyramid evaluated at ``f_c(u)``, in the filter and alone."""
    rng = np.random.default_rng(29)
    coarse = replace(PAPER_CONFIG, pyramid_faces=5, normal_force_margin=0.3)
    for config in (CONFIGS['cubic'], coarse):
        filter_ = SafetyFilter.from_config(model, config)
        pyramid = FrictionPyramid(
            model.contact_names,
            model.friction_coefficient,
            config.pyramid_faces,
            config.normal_force_margin,
        )
        for c in configurations:
            state = c.state(model)
            rows = filter_.constraint_rows(state)
            no_slip = [i for i, name in enumerate(rows.names) if family_of(name) == 'no_slip']
            for _ in range(3):
                u = rng.normal(0.0, 2.0, model.n_joints)
                names, margins = pyramid_margins(model, config, state, u)
                scale = 1.0 + np.max(np.abs(margins))
                assert tuple(names) == pyramid.names == tuple(rows.names[i] for i in no_slip)
                expected = margins - config.normal_force_margin
                np.testing.assert_allclose(
                    rows.residual(u)[no_slip], expected, rtol=0, atol=1e-10 * scale
                )
                np.testing.assert_allclose(
                    pyramid.rows(state).residual(u), expected, rtol=0, atol=1e-10 * scale
                )
                np.testing.assert_allclose(
                    pyramid.values(state, u).h, margins, rtol=0, atol=1e-10 * scale
                )


# -- 2. signs: > 0 inside, < 0 outside -----------------------------------------------------


def urdf_joint_limits():
    """``{joint: (lower, upper)}`` read straight from the hand's URDF, rad."""
    root = ElementTree.parse(CONFIG_DIR / PAPER_MODEL_PARAMETERS['model.urdf_file']).getroot()
    return {
        joint.get('name'): (float(limit.get('lower')), float(limit.get('upper')))
        for joint in root.iter('joint')
        if (limit := joint.find('limit')) is not None
    }


@pytest.mark.parametrize('side', ['upper', 'lower'])
@pytest.mark.parametrize('joint', PAPER_MODEL_PARAMETERS['model.joint_names'])
def test_joint_limit_barrier_is_positive_inside_and_negative_outside(model, joint, side):
    """A joint set across its URDF limit, the rest of a real grasp unchanged.

    Read through the filter's margins (by row name), so that the URDF limit of each joint
    reaches the row of that joint and side. The barrier reads only q, so the moved joint
    need not keep its fingertip on the cube.
    """
    filter_ = SafetyFilter.from_config(model, PAPER_CONFIG)
    lower, upper = urdf_joint_limits()[joint]
    bound, outward = (upper, 1.0) if side == 'upper' else (lower, -1.0)
    index = model.joint_names.index(joint)
    row = f'joint_limits/{joint}/{side}'
    c = random_configuration(model, np.random.default_rng(31 + index))
    u = np.zeros(model.n_joints)
    inside = filter_.margins(c.state(model), u)
    assert all(inside[name] > 0.0 for name in inside if family_of(name) == 'joint_limits')
    for distance in (1e-4, 0.05, 0.5):
        for sign in (-1.0, 1.0):  # -1: inside, +1: outside
            q = c.q.copy()
            q[index] = bound + sign * outward * distance
            state = dataclasses.replace(c, q=q).state(model)
            margins = filter_.margins(state, u)
            assert np.sign(margins[row]) == -sign, (distance, sign, margins[row])
            assert margins[row] == pytest.approx(-sign * distance, abs=1e-12)
            # Every other joint limit (the other side of this joint included) stays inside.
            assert all(
                margins[name] > 0.0
                for name in margins
                if family_of(name) == 'joint_limits' and name != row
            )


def contact_directions(model, c):
    """Return the unit contact directions in the fingertip frames, (n, 3), from kinematics.

    The fingertip touches the face where its outward normal is opposite to the face's:
    ``d = -R_fingertip_to_palm^T R_object_to_palm n_face``.
    """
    _, R_fingertip, _ = model.hand.fingertip_placements(c.q)
    normals = [FACE_NORMALS[label] for label in PAPER_MODEL_PARAMETERS['model.contact_faces']]
    return np.array(
        [-R_f.T @ (c.R_object @ n) for R_f, n in zip(R_fingertip, normals, strict=True)]
    )


#: Which side of each workspace bound a contact direction d is on, > 0 inside. In the chart
#: ``d = (-cos a cos b, sin a, -cos a sin b)``: a > a_min iff ``d_y > sin(a_min)``; for b and
#: its bounds in (-pi, 0), ``sin(b - b_min) cos a = d_x sin(b_min) - d_z cos(b_min)`` and
#: ``sin(b_max - b) cos a = d_z cos(b_max) - d_x sin(b_max)``: half-spaces through the
#: fingertip's y axis.
WORKSPACE_SIDES = {
    'a_min': lambda d, box: d[:, 1] - math.sin(box['a_min']),
    'a_max': lambda d, box: math.sin(box['a_max']) - d[:, 1],
    'b_min': lambda d, box: d[:, 0] * math.sin(box['b_min']) - d[:, 2] * math.cos(box['b_min']),
    'b_max': lambda d, box: d[:, 2] * math.cos(box['b_max']) - d[:, 0] * math.sin(box['b_max']),
}


@pytest.mark.parametrize('row', list(WORKSPACE_SIDES))
def test_workspace_barrier_sign_matches_the_contact_point_on_the_fingertip(model, row):
    """On real grasps, h of each workspace row has the sign of the contact's side of the bound.

    The box (``model.fingertip_workspace.*``) is narrowed to the middle of the coordinates
    these grasps reach, so that contacts fall on both sides of every bound; h is read
    through the filter's margins, and the side from the fingertip's orientation and the
    face normal (hand kinematics only, not the rolling model).
    """
    rng = np.random.default_rng(37)
    configurations = [
        random_configuration(model, rng, *SPREAD_SPEED[i % len(SPREAD_SPEED)]) for i in range(60)
    ]
    paper_filter = SafetyFilter.from_config(model, PAPER_CONFIG)
    xi = np.concatenate([c.state(model).xi_cf for c in configurations])
    (a_low, a_high), (b_low, b_high) = np.quantile(xi, [0.3, 0.7], axis=0).T
    box = {'a_min': a_low, 'a_max': a_high, 'b_min': b_low, 'b_max': b_high}
    narrowed = paper_model(
        **{f'model.fingertip_workspace.{name}': float(value) for name, value in box.items()}
    )
    narrowed_filter = SafetyFilter.from_config(narrowed, PAPER_CONFIG)
    rows = [f'fingertip_workspace/{contact}/{row}' for contact in model.contact_names]
    u = np.zeros(model.n_joints)
    signs = Counter()
    for c in configurations:
        paper_margins = paper_filter.margins(c.state(model), u)
        # Valid grasps are inside the paper's box.
        assert all(
            paper_margins[name] > 0.0
            for name in paper_margins
            if family_of(name) == 'fingertip_workspace'
        )
        margins = narrowed_filter.margins(c.state(narrowed), u)
        h = np.array([margins[name] for name in rows])
        side = WORKSPACE_SIDES[row](contact_directions(model, c), box)
        np.testing.assert_array_equal(np.sign(h), np.sign(side), err_msg=f'{row}: {h} vs {side}')
        signs.update(np.sign(h).tolist())
    assert signs[1.0] >= 20 and signs[-1.0] >= 20, signs


def test_pyramid_margins_are_positive_inside_and_negative_outside(model, configurations):
    """Between the inscribed cone ``mu cos(pi/l) f_n`` and the friction cone ``mu f_n``.

    Inside the inner cone every face margin is > 0; outside the friction cone some face
    margin is < 0 (the pyramid lies between the two).
    """
    config = replace(PAPER_CONFIG, pyramid_faces=6, normal_force_margin=0.0)
    pyramid = FrictionPyramid(model.contact_names, model.friction_coefficient, 6, 0.0)
    mu = model.friction_coefficient
    rng = np.random.default_rng(41)
    seen = Counter()
    for c in configurations:
        state = c.state(model)
        for _ in range(10):
            u = rng.normal(0.0, 1.5, model.n_joints)
            forces = state.contact_force(u).reshape(-1, 3)
            tangential, normal = np.hypot(forces[:, 0], forces[:, 1]), forces[:, 2]
            h = pyramid.values(state, u).h.reshape(model.n_contacts, -1)
            _, written = pyramid_margins(model, config, state, u)
            np.testing.assert_allclose(
                h.ravel(), written, atol=1e-10 * (1 + np.abs(written).max())
            )
            inner = tangential < mu * math.cos(math.pi / 6) * normal
            outer = tangential > mu * normal
            assert np.all(h[inner].min(axis=1) > 0.0)
            assert np.all(h[outer].min(axis=1) < 0.0)
            np.testing.assert_array_equal(state.required_friction(forces) > mu, outer)
            seen.update({'inside': int(inner.sum()), 'outside': int(outer.sum())})
    assert seen['inside'] >= 50 and seen['outside'] >= 50, seen


# -- 3. the filter on random real states ---------------------------------------------------


def test_joint_and_workspace_rows_act_through_the_objects_six_dofs(model, configurations):
    """The joint-limit and workspace rows constrain only the object's acceleration.

    Three rolling contacts fix nine velocity components, as many as the hand has joints:
    the hand moves with the object. So the torques that leave ``x_o_ddot`` unchanged (they
    only squeeze the object) change no joint and no contact-coordinate acceleration either:
    the thirty rows have rank 6 and vanish on that null space; the no-slip rows see it.
    This is why too many nearly active barriers can leave no feasible torque (docs/paper_runs.md).
    """
    config = PAPER_CONFIG
    for c in configurations:
        state = c.state(model)
        names, A, _ = independent_rows(model, config, state)
        motion = np.array([not name.startswith('no_slip') for name in names])
        object_map = state.object_acceleration.matrix
        squeeze = scipy.linalg.null_space(object_map)
        assert squeeze.shape == (model.n_joints, model.n_joints - 6)
        scale = np.abs(A[motion]).max()
        assert np.abs(A[motion] @ squeeze).max() <= 1e-9 * scale
        assert np.linalg.matrix_rank(A[motion], tol=1e-9 * scale) == 6
        assert np.abs(A[~motion] @ squeeze).max() > 1e-3 * np.abs(A[~motion]).max()


@pytest.mark.parametrize('solver', sorted(BACKENDS))
@pytest.mark.parametrize('config_name', list(CONFIGS))
def test_random_real_states_rows_hold_nominal_kept_optimum_matches_the_reference(
    model, config_name, solver
):
    """On random grasps: every row of u* holds, u_nom kept when feasible, the exact optimum.

    u_nom is drawn around the centre of the largest ball inside the feasible set (an LP):
    within the ball it is feasible, beyond it usually not; a quarter of the draws are wide
    (box saturation). Where the LP finds no ball the hard QP is infeasible: the filter must
    relax, stay finite and inside the box, and match the exact relaxed optimum. Every
    backend (``qp.solver``) on the same draws.
    """
    config = dataclasses.replace(CONFIGS[config_name], solver=solver)
    filter_ = SafetyFilter.from_config(model, config)
    effort = np.asarray(model.effort_limits, dtype=float)
    rng = np.random.default_rng(43 + len(config_name))
    counts = Counter()
    for trial in range(N_RANDOM_STATES):
        c = random_configuration(model, rng, *SPREAD_SPEED[trial % len(SPREAD_SPEED)])
        state = c.state(model)
        names, A, lower = independent_rows(model, config, state)
        rows = filter_.constraint_rows(state)
        assert rows.names == names == filter_.row_names
        scale = 1.0 + np.abs(lower).max()
        np.testing.assert_allclose(rows.A, A, rtol=0, atol=1e-9 * (1.0 + np.abs(A).max()))
        np.testing.assert_allclose(rows.lower, lower, rtol=0, atol=1e-9 * scale)

        centre, radius = chebyshev_radius(A, lower, effort)
        if trial % 4 == 3:
            u_nom = centre + rng.normal(0.0, 2.0, model.n_joints)
        else:
            direction = rng.normal(size=model.n_joints)
            reach = abs(radius) * 10.0 ** rng.uniform(-1.0, 1.5)
            u_nom = centre + reach * direction / np.linalg.norm(direction)
        result = filter_.solve(state, u_nom)
        u = result.u
        where = f'trial {trial}, status {result.status.value}'
        assert np.all(np.isfinite(u)), where
        assert np.all(u >= -effort) and np.all(u <= effort), where

        residual = independent_residuals(model, config, state, u)[1]
        nominal_residual = independent_residuals(model, config, state, u_nom)[1]
        feasible, u_reference = reference_optimum(A, lower, u_nom, effort)
        # The LP and the references agree on feasibility away from the boundary case radius = 0.
        if abs(radius) > 1e-9:
            assert feasible == (radius > 0.0), (where, radius)
        if feasible:
            assert not result.relaxed and result.status in CERTIFIED, where
            assert result.relaxed_families == (), where
            assert residual.min() >= -1e-6, (where, names[int(np.argmin(residual))])
            assert rows.residual(u).min() >= -1e-6, where
            assert np.abs(u - u_reference).max() <= 1e-5, (where, u - u_reference)
            if nominal_residual.min() >= 0.0 and np.all(np.abs(u_nom) <= effort):
                counts['nominal feasible'] += 1
                assert np.abs(u - u_nom).max() <= 1e-6, where
                assert result.status is FilterStatus.NOMINAL, where
            else:
                counts['nominal infeasible'] += 1
                assert result.active, where
        else:
            counts['hard QP infeasible'] += 1
            assert result.relaxed and result.status is FilterStatus.RELAXED, where
            violated = {family_of(names[i]) for i in np.flatnonzero(residual < -1e-6)}
            assert violated and set(result.relaxed_families) == violated, where
            u_relaxed = reference_relaxed_optimum(
                A, lower, row_weights(config, names), u_nom, effort
            )
            assert np.abs(u - u_relaxed).max() <= 1e-5, (where, u - u_relaxed)
    assert sum(counts.values()) >= 200
    assert counts['nominal feasible'] >= 50, counts
    assert counts['nominal infeasible'] >= 50, counts
    assert counts['hard QP infeasible'] >= 30, counts


# -- 4. states built to make the QP infeasible ---------------------------------------------


def grasp_with_joint_at(model, joint, q_target):
    """Return a grasp of the cube at its paper pose with ``q[joint] = q_target`` exactly.

    The projection onto the contacts moves every joint a little; a secant search on the
    joint's initial guess lands it where asked.
    """
    R_object = np.eye(3)

    def projected(guess):
        q = Q_PAPER.copy()
        q[joint] = guess
        return model.project_to_contact(q, P_OBJECT_PAPER, R_object)

    g0, g1 = q_target - 0.05, q_target + 0.05
    r0, r1 = projected(g0)[joint] - q_target, projected(g1)[joint] - q_target
    for _ in range(30):
        if abs(r1) < 1e-12:
            break
        g0, g1 = g1, g1 - r1 * (g1 - g0) / (r1 - r0)
        r0, r1 = r1, projected(g1)[joint] - q_target
    q = projected(g1)
    assert abs(q[joint] - q_target) < 1e-10
    return Configuration(q, np.zeros_like(q), P_OBJECT_PAPER, R_object, np.zeros(6))


def rolling(model, c, rate_of, rate):
    """``c`` set rolling with the object twist of least norm that makes ``rate_of`` = rate.

    ``rate_of(state)`` is a velocity of the state (a joint rate, a contact-coordinate rate):
    linear in the object twist, its gradient is read off the six unit twists.
    """

    def with_twist(twist):
        dq = model.rolling_joint_velocity(c.q, c.p_object, c.R_object, twist)
        return Configuration(c.q, dq, c.p_object, c.R_object, twist)

    gradient = np.array([rate_of(with_twist(e).state(model)) for e in np.eye(6)])
    driven = with_twist(rate * gradient / (gradient @ gradient))
    assert rate_of(driven.state(model)) == pytest.approx(rate, rel=1e-9)
    return driven


def only(*families):
    return replace(
        PAPER_CONFIG,
        no_slip_enabled='no_slip' in families,
        joint_limits_enabled='joint_limits' in families,
        fingertip_workspace_enabled='fingertip_workspace' in families,
    )


FINGER1_JOINT2 = 1  # abduction, upper limit pi/3, 0.30 rad above the paper's grasp


def paper_grasp_at_rest(model):
    """Return the paper's grasp at rest (and the model)."""
    return model, grasp_with_joint_at(model, FINGER1_JOINT2, Q_PAPER[FINGER1_JOINT2])


def joint_at_its_limit(rate):
    """Build finger1_joint2 0.02 rad below its upper limit, driven towards it at ``rate``."""

    def build(model):
        limit = model.joint_upper_limits[FINGER1_JOINT2]
        c = grasp_with_joint_at(model, FINGER1_JOINT2, limit - 0.02)
        return model, rolling(model, c, lambda s: s.dq[FINGER1_JOINT2], rate)

    return build


def contact_rolling_off_the_fingertip(model):
    """Contact 1's a 0.02 rad inside a_max (the box narrowed to it), rolling out at 10 rad/s."""
    _, c = paper_grasp_at_rest(model)
    a = model.contact_geometry(c.q, c.p_object, c.R_object)[0].xi_cf[0]
    narrowed = paper_model(**{'model.fingertip_workspace.a_max': float(a) + 0.02})
    return narrowed, rolling(narrowed, c, lambda s: s.xi_cf_dot[0, 0], 10.0)


#: Builder, filter configuration, the row that must be given up (None: any).
INFEASIBLE_CASES = {
    'joint rushing at its limit': (
        joint_at_its_limit(10.0),
        only('joint_limits'),
        'joint_limits/finger1_joint2/upper',
    ),
    'contact rolling off the fingertip': (
        contact_rolling_off_the_fingertip,
        only('fingertip_workspace'),
        'fingertip_workspace/finger1/a_max',
    ),
    # Every contact must push with f_n >= 40 N / (mu cos(pi/8)): beyond 5 N·m actuators.
    'grip demanded beyond the actuators': (
        paper_grasp_at_rest,
        dataclasses.replace(only('no_slip'), normal_force_margin=40.0),
        None,
    ),
    # The paper's configuration: every family, the joint moving at 1 rad/s.
    'joint at its limit, every family': (
        joint_at_its_limit(1.0),
        PAPER_CONFIG,
        None,
    ),
}


@pytest.mark.parametrize('solver', sorted(BACKENDS))
@pytest.mark.parametrize('case', list(INFEASIBLE_CASES))
def test_an_infeasible_real_state_is_relaxed_and_the_families_named(model, case, solver):
    """Assumption 5 fails (an LP proves no torque in the box satisfies every row).

    The filter relaxes: u finite and inside the box, and the families named are exactly
    those with a row violated at u (evaluated here), including the one forced to give.
    """
    build, config, given_up = INFEASIBLE_CASES[case]
    config = dataclasses.replace(config, solver=solver)
    model, c = build(model)
    state = c.state(model)
    assert np.all(np.abs(state.penetration) < 1e-12)  # a grasp: every fingertip on the cube
    filter_ = SafetyFilter.from_config(model, config)
    effort = np.asarray(model.effort_limits, dtype=float)
    names, A, lower = independent_rows(model, config, state)
    _, radius = chebyshev_radius(A, lower, effort)
    assert radius < -1e-6, radius
    for u_nom in (np.zeros(model.n_joints), state.gravity_torque, np.full(model.n_joints, 10.0)):
        feasible, _ = reference_optimum(A, lower, u_nom, effort)
        assert not feasible
        result = filter_.solve(state, u_nom)
        assert result.relaxed and result.status is FilterStatus.RELAXED
        assert np.all(np.isfinite(result.u))
        assert np.all(result.u >= -effort) and np.all(result.u <= effort)
        residual = independent_residuals(model, config, state, result.u)[1]
        violated = tuple(
            dict.fromkeys(family_of(names[i]) for i in np.flatnonzero(residual < -1e-6))
        )
        assert violated and result.relaxed_families == violated
        assert result.max_violation == pytest.approx(-residual.min(), rel=1e-9)
        u_relaxed = reference_relaxed_optimum(A, lower, row_weights(config, names), u_nom, effort)
        assert np.abs(result.u - u_relaxed).max() <= 1e-5, result.u - u_relaxed
        if given_up is not None:
            assert residual[names.index(given_up)] < -1e-6
            assert given_up in result.active


def test_a_run_of_infeasible_ticks_gives_each_ticks_own_relaxed_optimum(model):
    """Relaxed ticks in a row, warm-started: each answer is that tick's own optimum.

    A joint driven into its limit, u_nom drifting tick to tick: every tick is infeasible.
    Each answer must equal a filter without memory's and the reference relaxed optimum.
    """
    model, c = joint_at_its_limit(1.0)(model)
    state = c.state(model)
    config = PAPER_CONFIG
    names, A, lower = independent_rows(model, config, state)
    effort = np.asarray(model.effort_limits, dtype=float)
    weights = row_weights(config, names)
    filter_ = SafetyFilter.from_config(model, config)
    rng = np.random.default_rng(5)
    u_nom = state.gravity_torque.copy()
    for tick in range(12):
        u_nom = u_nom + rng.normal(0.0, 0.05, model.n_joints)
        result = filter_.solve(state, u_nom)
        memoryless = SafetyFilter.from_config(model, config).solve(state, u_nom)
        assert result.status is FilterStatus.RELAXED, tick
        assert np.abs(result.u - memoryless.u).max() <= 1e-9, tick
        u_relaxed = reference_relaxed_optimum(A, lower, weights, u_nom, effort)
        assert np.abs(result.u - u_relaxed).max() <= 1e-5, tick


def test_the_paper_runs_first_relaxed_tick_is_a_conflict_of_joint_and_workspace_rows():
    """Why the paper's run relaxes with alpha = h^3 (docs/paper_runs.md), checked where it does.

    Run the filtered scenario to its first relaxed tick. There, independently of the
    filter: the joint-limit and workspace rows alone admit no torque (daqp), the joint
    rows alone and every row but the workspace ones do; a second joint sits about 0.3 rad
    below its upper limit, where alpha_2(alpha_1(h)) = h^9 allows almost no acceleration
    towards it.
    """
    scenario = Scenario.load(config_path())
    ticks, _, _, _ = record_filtered_run(scenario, 3.0)
    first = next(i for i, tick in enumerate(ticks) if tick.status is FilterStatus.RELAXED)
    tick = ticks[first]
    model = scenario.model
    state = model.state(
        tick.t, tick.q, tick.dq, tick.p_object_in_palm, tick.R_object_to_palm, tick.twist_object
    )
    effort = np.asarray(model.effort_limits, dtype=float)

    def feasible(*families):
        config = only(*families)
        _, A, lower = independent_rows(model, config, state)
        return reference_optimum(A, lower, tick.u_nom, effort)[0]

    assert not feasible('joint_limits', 'fingertip_workspace')
    assert not feasible('no_slip', 'joint_limits', 'fingertip_workspace')
    assert feasible('joint_limits')
    assert feasible('no_slip', 'joint_limits')
    h = model.joint_upper_limits - state.q
    second = [model.joint_names.index(f'finger{i}_joint2') for i in (1, 2, 3)]
    assert 0.25 < h[second].min() < 0.35
    assert h[second].min() ** 9 < 1e-4
