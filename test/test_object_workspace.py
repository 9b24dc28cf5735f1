"""The object-workspace barrier: contact points stay on their object surface, with a margin.

Checked on real grasps of the cube, a box and the sphere object: barrier values against the
contact point's position on the object (independent of the charts), rates against finite
differences along the constrained dynamics, the filter's optimum against the exact
references of :mod:`qp_reference`, and the validation of its parameters.
"""

from __future__ import annotations

import dataclasses
from dataclasses import replace
import math

from grasp_states import moved, P_OBJECT_PAPER, paper_model, Q_PAPER, random_configuration
import numpy as np
import pytest
from qp_reference import hard_optimum, relaxed_optimum

from grasp_safety_filter.control.class_k import ClassKFunction
from grasp_safety_filter.control.constraints import ObjectWorkspaceBarrier
from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.safety_filter import (
    FilterStatus,
    SafetyFilter,
    SafetyFilterConfig,
)
from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.model.fingertip_workspace import GraspConfigError
from grasp_safety_filter.model.surfaces import FlatSurface

EPS = 1e-6
RTOL = 1e-5
HALF_EDGE = 0.2604 / 2  # the paper's cube

MODELS = {
    'cube': {},
    'box': {
        'model.object.shape': 'box',
        'model.object.edge_lengths': [0.2604, 0.3, 0.34],
        'model.contact_faces': ['nearest'],
    },
    'sphere': {'model.object.shape': 'sphere', 'model.object.size': 0.3},
}

ALPHAS = {
    'cubic': (ClassKFunction(), ClassKFunction()),
    'linear': (ClassKFunction('linear', 3.0), ClassKFunction('linear', 8.0)),
}


def bound_model(shape):
    """Return the paper's hand on ``shape``, each contact's surface chosen at its grasp."""
    model = paper_model(**MODELS[shape])
    model.bind_contacts(Q_PAPER, P_OBJECT_PAPER, np.eye(3))
    return model


def barrier_of(model, margin=0.01, half_widths=(0.6, 0.7), alphas=ALPHAS['cubic']):
    surfaces = [contact.object_surface for contact in model.contacts]
    return ObjectWorkspaceBarrier.on_surfaces(
        model.contact_names, surfaces, margin, half_widths, *alphas
    )


def assert_relative(actual, expected, what):
    scale = max(float(np.max(np.abs(expected))), 1e-3)
    error = float(np.max(np.abs(actual - expected))) / scale
    assert error <= RTOL, f'{what}: relative error {error:.2e}\n{actual}\n{expected}'


@pytest.fixture(scope='module', params=list(MODELS))
def model(request):
    return bound_model(request.param)


@pytest.mark.parametrize('alphas', list(ALPHAS))
def test_rows_are_the_zcbf_inequality_with_rates_from_finite_differences(model, alphas):
    """h, h_dot, h_ddot(u) from the rows against the definition and finite differences."""
    alpha1, alpha2 = ALPHAS[alphas]
    barrier = barrier_of(model, alphas=ALPHAS[alphas])
    rng = np.random.default_rng(29)
    for _ in range(12):
        c = random_configuration(model, rng)
        state = c.state(model)
        u = rng.normal(0.0, 1.0, model.n_joints)
        ddq, x_ddot = state.joint_acceleration(u), state.object_acceleration(u)
        h, h_dot = barrier.barrier(state)
        np.testing.assert_array_equal(barrier.values(state).h, h)
        # The definition, row by row: (x - lower_x, upper_x - x, y - lower_y, upper_y - y).
        x, x_dot = state.xi_co, state.xi_co_dot
        lo, hi = barrier.lower, barrier.upper
        expected_h = np.column_stack(
            (x[:, 0] - lo[:, 0], hi[:, 0] - x[:, 0], x[:, 1] - lo[:, 1], hi[:, 1] - x[:, 1])
        ).ravel()
        signs = np.tile([1.0, -1.0, 1.0, -1.0], model.n_contacts)
        np.testing.assert_allclose(h, expected_h, rtol=0, atol=1e-15)
        np.testing.assert_allclose(h_dot, signs * np.repeat(x_dot, 2, axis=1).ravel(), atol=1e-15)
        rows = barrier.rows(state)
        B = h_dot + alpha1.value(h)
        h_ddot = rows.residual(u) - alpha1.derivative(h) * h_dot - alpha2.value(B)
        after = barrier.barrier(moved(c, EPS, ddq, x_ddot).state(model))
        before = barrier.barrier(moved(c, -EPS, ddq, x_ddot).state(model))
        assert_relative(h_dot, (after[0] - before[0]) / (2 * EPS), 'h_dot')
        assert_relative(h_ddot, (after[1] - before[1]) / (2 * EPS), 'h_ddot(u)')


def test_row_names_name_the_contact_and_the_chart_coordinate(model):
    barrier = barrier_of(model)
    rows = ('a_min', 'a_max', 'b_min', 'b_max') if model.object_shape.kind == 'sphere' else (
        'u_min', 'u_max', 'v_min', 'v_max'
    )
    assert barrier.names == tuple(
        f'object_workspace/{contact}/{row}' for contact in model.contact_names for row in rows
    )


#: Object shifted in the palm's horizontal plane (m) and whether contact 'finger3' (on the
#: cube's +y face, in the x-z plane of the object) is then more than MARGIN from every edge.
MARGIN = 0.01
SHIFTS = [
    ((0.0, 0.0, 0.0), True),
    ((HALF_EDGE - MARGIN - 0.002, 0.0, 0.0), True),
    ((-(HALF_EDGE - MARGIN - 0.002), 0.0, 0.0), True),
    ((HALF_EDGE - MARGIN + 0.002, 0.0, 0.0), False),
    ((-(HALF_EDGE - MARGIN + 0.002), 0.0, 0.0), False),
    ((HALF_EDGE + 0.01, 0.0, 0.0), False),
    ((0.0, 0.0, HALF_EDGE - MARGIN - 0.002), True),
    ((0.0, 0.0, -(HALF_EDGE - MARGIN + 0.002)), False),
]


@pytest.mark.parametrize('shift,inside', SHIFTS)
def test_face_barrier_is_positive_inside_the_shrunk_face_and_negative_outside(shift, inside):
    """The sign of h against the contact point's position on the cube, in object axes."""
    model = paper_model()
    barrier = barrier_of(model, margin=MARGIN)
    p_object = P_OBJECT_PAPER + np.array(shift)
    state = model.state(0.0, Q_PAPER, np.zeros(Q_PAPER.size), p_object, np.eye(3), np.zeros(6))
    i = model.contact_names.index('finger3')
    p_contact_in_object = state.p_contact_in_palm[i] - p_object
    assert p_contact_in_object[1] == pytest.approx(HALF_EDGE, abs=1e-3)  # on the +y face
    in_plane = np.abs(p_contact_in_object[[0, 2]])
    assert (in_plane.max() < HALF_EDGE - MARGIN) == inside
    h = barrier.values(state).h.reshape(-1, 4)[i]
    assert (h.min() > 0.0) == inside, h
    # And h is the distance to the shrunk face's nearest edge.
    assert h.min() == pytest.approx(HALF_EDGE - MARGIN - in_plane.max(), abs=1e-9)


#: Rotation of the sphere object about the palm z axis (rad) and whether contact finger3's
#: chart coordinate a (the turn moves it along the equator) is inside |a| <= 0.6.
SPHERE_TURNS = [(0.0, True), (0.55, True), (-0.55, True), (0.65, False), (-0.65, False)]


@pytest.mark.parametrize('turn,inside', SPHERE_TURNS)
def test_sphere_barrier_is_positive_inside_the_chart_box_and_negative_outside(turn, inside):
    """Turning the sphere under a fixed fingertip moves the contact by the turn's angle."""
    model = bound_model('sphere')
    barrier = barrier_of(model, half_widths=(0.6, 0.7))
    c, s = math.cos(turn), math.sin(turn)
    R_object = np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])
    state = model.state(
        0.0, Q_PAPER, np.zeros(Q_PAPER.size), P_OBJECT_PAPER, R_object, np.zeros(6)
    )
    i = model.contact_names.index('finger3')
    h = barrier.values(state).h.reshape(-1, 4)[i]
    assert (h.min() > 0.0) == inside, h
    # The contact moved by |turn| along the sphere's equator: one coordinate changed by it.
    a, b = state.xi_co[i]
    assert max(abs(a), abs(b + math.pi / 2)) == pytest.approx(abs(turn), abs=1e-9)


BAD_MARGINS = [
    ('cube', HALF_EDGE, ["'object_workspace.margin'", "'finger1'", 'face -x', '0.1302']),
    ('cube', 0.2, ["'finger1'", 'face -x', '0.2']),
    ('box', 0.14, ["'finger3'", 'face +y', '0.1302', '0.14']),
]


@pytest.mark.parametrize('shape,margin,words', BAD_MARGINS)
def test_a_margin_that_leaves_no_face_is_refused_naming_contact_and_face(shape, margin, words):
    model = bound_model(shape)
    config = replace(PAPER_CONFIG, object_workspace_enabled=True, object_workspace_margin=margin)
    with pytest.raises(GraspConfigError) as error:
        SafetyFilter.from_config(model, config)
    for word in words:
        assert word in str(error.value)
    # Switched off, the family and its margin are not looked at.
    SafetyFilter.from_config(model, dataclasses.replace(config, object_workspace_enabled=False))


def test_faces_chosen_at_the_first_state_give_the_bounds_then():
    """A box's nearest faces are chosen at the first state: the bounds follow them."""
    model = paper_model(**MODELS['box'])
    assert not model.contacts_bound
    with pytest.raises(GraspConfigError, match=r"margin'.*smallest 0\.1302 m, got 0\.14 m"):
        wide = replace(PAPER_CONFIG, object_workspace_enabled=True, object_workspace_margin=0.14)
        SafetyFilter.from_config(model, wide)
    filter_ = SafetyFilter.from_config(
        model, replace(PAPER_CONFIG, object_workspace_enabled=True, object_workspace_margin=0.02)
    )
    state = model.state(
        0.0, Q_PAPER, np.zeros(Q_PAPER.size), P_OBJECT_PAPER, np.eye(3), np.zeros(6)
    )
    margins = filter_.margins(state, np.zeros(model.n_joints))
    expected = barrier_of(model, margin=0.02).values(state)
    assert [margins[name] for name in expected.names] == expected.h.tolist()
    # finger3 is on the +y face: 0.34 / 2 - 0.02 m along z, 0.1302 - 0.02 m along x.
    finger3 = [margins[f'object_workspace/finger3/{row}'] for row in ('u_max', 'v_max')]
    np.testing.assert_allclose(finger3, [0.17 - 0.02, 0.1302 - 0.02], atol=2e-3)


@pytest.mark.parametrize(
    'half_widths,word',
    [((math.pi / 2, 1.0), 'sphere_a_half_width'), ((1.0, 1.6), 'sphere_b_half_width')],
)
def test_a_chart_box_reaching_the_pole_or_cut_is_refused(half_widths, word):
    model = bound_model('sphere')
    surfaces = [contact.object_surface for contact in model.contacts]
    with pytest.raises(GraspConfigError, match=f"{word}'.*'finger1'.*sphere"):
        ObjectWorkspaceBarrier.on_surfaces(model.contact_names, surfaces, 0.01, half_widths)
    # The parameter schema stops them earlier, at pi/2 - 0.15 rad.
    with pytest.raises(ConfigError, match=word):
        SafetyFilterConfig(**{f'object_workspace_{word}': 1.5})


def test_an_unbounded_plane_is_refused():
    with pytest.raises(GraspConfigError, match='unbounded'):
        ObjectWorkspaceBarrier.on_surfaces(
            ['c1'], [FlatSurface(np.zeros(3), np.eye(3)[0], np.eye(3)[1])], 0.01, (1.0, 1.0)
        )


@pytest.mark.parametrize('shape', ['cube', 'sphere'])
def test_filter_with_the_family_on_matches_the_exact_reference(shape):
    """Every row of u* holds and u* is the exact optimum (or the exact relaxed one).

    A tight box (cube: 80 mm around each face's centre; sphere: 0.7 rad) makes the family's
    rows restrict u on many of the random grasps, and leaves some without a safe torque.
    """
    model = bound_model(shape)
    config = replace(
        PAPER_CONFIG,
        object_workspace_enabled=True,
        object_workspace_margin=0.05,
        object_workspace_sphere_a_half_width=0.7,
        object_workspace_sphere_b_half_width=0.7,
        alpha1_kind='linear',
        alpha1_gain=3.0,
        alpha2_kind='linear',
        alpha2_gain=8.0,
    )
    filter_ = SafetyFilter.from_config(model, config)
    assert 'object_workspace' in {family.family for family in filter_.families}
    effort = np.asarray(model.effort_limits, dtype=float)
    weights = {
        'no_slip': config.no_slip_weight,
        'joint_limits': config.joint_limits_weight,
        'fingertip_workspace': config.fingertip_workspace_weight,
        'object_workspace': config.object_workspace_weight,
    }
    rng = np.random.default_rng(31)
    restricted, feasible_count = 0, 0
    for _ in range(60):
        state = random_configuration(model, rng, 0.25, 1.0).state(model)
        rows = filter_.constraint_rows(state)
        u_nom = rng.normal(0.0, 1.5, model.n_joints)
        result = filter_.solve(state, u_nom)
        feasible, u_reference = hard_optimum(rows.A, rows.lower, u_nom, -effort, effort)
        family_rows = np.array([name.startswith('object_workspace/') for name in rows.names])
        restricted += bool(rows.residual(u_nom)[family_rows].min() < 0.0)
        feasible_count += feasible
        if feasible:
            assert result.status is not FilterStatus.RELAXED
            assert rows.residual(result.u).min() >= -1e-6
            assert np.abs(result.u - u_reference).max() <= 1e-5
        else:
            row_weights = np.array([weights[name.split('/')[0]] for name in rows.names])
            u_relaxed, _ = relaxed_optimum(
                rows.A, rows.lower, row_weights, u_nom, -effort, effort
            )
            assert result.status is FilterStatus.RELAXED
            assert np.abs(result.u - u_relaxed).max() <= 1e-5
    # u_nom breaks one of the family's rows on many draws: the family shapes u*.
    assert restricted >= 10, restricted
    assert 5 <= feasible_count <= 55, feasible_count
