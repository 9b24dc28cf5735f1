"""The one-pass packed model terms against the staged numpy oracle, and the state's contract.

``GraspModel.state`` computes the terms of spherical fingertips on flat faces in one
compiled pass into one buffer (``PackedGraspState``); the oracle (``model_oracles.
staged_state``: HandModel.terms, numpy contact kinematics, the dynamics kernels, themselves
checked against numpy formulas in test_model_kernels.py) must give every field to rounding.
"""

from __future__ import annotations

import dataclasses

from grasp_states import paper_model, random_configuration
from model_oracles import staged_state
import numpy as np
import pytest
from random_hands import random_hand

from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.safety_filter import SafetyFilter
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.packed_state import PackedGraspState

#: A term's largest difference from the oracle's, relative to its largest entry: rounding.
RTOL = 1e-11
#: Penetrations are ~0 on the contact manifold: their scale is a length of the grasp, m.
LENGTH_SCALE = 1e-3
#: The scale of terms that are ~0 at some instants: penetrations (m) and an isotropic
#: object's gyroscopic torque (exactly 0 in the model, rounding in numpy's cross product),
#: N·m.
FLOORS = {'penetration': LENGTH_SCALE, 'C_o_twist': 1e-6}

BOXES = {
    'cube': {},
    'anisotropic box': {
        'model.object.shape': 'box',
        'model.object.edge_lengths': [0.26, 0.28, 0.24],
    },
    'anisotropic box, soft fingers': {
        'model.object.shape': 'box',
        'model.object.edge_lengths': [0.26, 0.28, 0.24],
        'model.torsional_friction': 0.005,
    },
}


def _states(model, configuration):
    c = configuration
    args = (0.25, c.q, c.dq, c.p_object, c.R_object, c.twist_object)
    return model.state(*args), staged_state(model, *args)


def _assert_close(actual, expected, what, floor=1e-300):
    scale = max(float(np.max(np.abs(expected), initial=0.0)), floor)
    error = float(np.max(np.abs(np.asarray(actual) - expected), initial=0.0)) / scale
    assert error <= RTOL, f'{what}: relative difference {error:.2e} > {RTOL:g}'


def _assert_same_fields(packed, staged):
    assert isinstance(packed, PackedGraspState) and not isinstance(staged, PackedGraspState)
    for field in dataclasses.fields(GraspState):
        ours, theirs = getattr(packed, field.name), getattr(staged, field.name)
        if field.name == 'xi_co_rate_terms':
            ours, theirs = ours(), theirs()
        elif field.name == 't':
            assert ours == theirs
            continue
        elif hasattr(theirs, 'matrix'):
            assert not ours.matrix.flags.writeable and not ours.offset.flags.writeable
            ours, theirs = (ours.matrix, ours.offset), (theirs.matrix, theirs.offset)
        else:
            assert not ours.flags.writeable, field.name
            assert ours.shape == theirs.shape, field.name
            ours, theirs = (ours,), (theirs,)
        floor = FLOORS.get(field.name, 1e-300)
        for a, b in zip(ours, theirs, strict=True):
            _assert_close(a, b, field.name, floor)
    # xi_co_ddot is a view of the pass's closed form (M_co = I on a face).
    layout = packed.packed_terms[1]
    start, stop, shape = layout.places['xi_co_ddot_augmented']
    augmented = packed.packed_terms[0][start:stop].reshape(shape)
    m = packed.n_joints
    for part, view in (('matrix', augmented[:, :m]), ('offset', augmented[:, m])):
        ours, theirs = getattr(packed.xi_co_ddot, part), getattr(staged.xi_co_ddot, part)
        assert not ours.flags.writeable and np.shares_memory(ours, packed.packed_terms[0])
        np.testing.assert_array_equal(ours, view)
        _assert_close(ours, theirs, f'xi_co_ddot.{part}')


@pytest.mark.parametrize('case', list(BOXES))
def test_every_field_equals_the_staged_oracle(case):
    model = paper_model(**BOXES[case])
    rng = np.random.default_rng(5)
    for _ in range(4):
        _assert_same_fields(*_states(model, random_configuration(model, rng)))


def test_a_hand_whose_joints_are_not_in_pinocchios_order_gives_the_same_fields(tmp_path):
    """The compiled pass gathers J, M_h, M_h^-1, C_h dq + g and g into the model's order."""
    permuted = 0
    for seed in range(8):
        hand = random_hand(seed)
        if hand.shape != 'box':
            continue
        (tmp_path / str(seed)).mkdir()
        path = hand.write(tmp_path / str(seed))
        model = GraspModel.from_parameters(
            {**hand.model_parameters(path), **hand.initial_parameters()}
        )
        permuted += not model.hand._in_pin_order
        rng = np.random.default_rng(seed)
        q = model.project_to_contact(
            hand.q0 + rng.uniform(-0.02, 0.02, hand.q0.size), hand.p_object, hand.R_object
        )
        twist = rng.normal(0.0, 0.3, 6)
        dq = model.rolling_joint_velocity(q, hand.p_object, hand.R_object, twist)
        args = (0.1, q, dq, hand.p_object, hand.R_object, twist)
        _assert_same_fields(model.state(*args), staged_state(model, *args))
    assert permuted, "no box hand of these seeds has its joints out of Pinocchio's order"


def test_a_non_finite_input_gives_non_finite_terms():
    """A system the solve cannot take (not finite): NaN wrench and accelerations, no error."""
    model = paper_model()
    c = random_configuration(model, np.random.default_rng(3))
    dq = np.array(c.dq)
    dq[0] = np.nan
    state = model.state(0.0, c.q, dq, c.p_object, c.R_object, c.twist_object)
    assert isinstance(state, PackedGraspState)
    assert np.isnan(state.contact_force.offset).all()
    assert np.isnan(state.joint_acceleration.matrix).all()
    assert np.isfinite(state.M_h).all()  # the terms before the solve are kept


WRONG_SHAPES = {
    'q': lambda c: (c.q[:-1], c.dq, c.p_object, c.R_object, c.twist_object),
    'dq': lambda c: (c.q, np.append(c.dq, 0.0), c.p_object, c.R_object, c.twist_object),
    'p_object_in_palm': lambda c: (c.q, c.dq, np.append(c.p_object, 0.0), c.R_object,
                                   c.twist_object),
    'R_object_to_palm': lambda c: (c.q, c.dq, c.p_object, np.eye(3, 4), c.twist_object),
    'twist_object': lambda c: (c.q, c.dq, c.p_object, c.R_object, c.twist_object[:3]),
}


@pytest.mark.parametrize('name', list(WRONG_SHAPES))
def test_an_input_of_the_wrong_shape_is_refused_by_name(name):
    """The compiled pass writes its inputs without bounds checks: shapes are checked first."""
    model = paper_model()
    c = random_configuration(model, np.random.default_rng(4))
    with pytest.raises(ValueError, match=f'{name}: expected shape'):
        model.state(0.0, *WRONG_SHAPES[name](c))


@pytest.mark.parametrize('packed', [True, False])
def test_rows_into_refuses_a_block_that_does_not_fit(packed):
    model = paper_model()
    c = random_configuration(model, np.random.default_rng(6))
    args = (0.0, c.q, c.dq, c.p_object, c.R_object, c.twist_object)
    state = model.state(*args)
    if not packed:
        state = dataclasses.replace(state)  # every field given: no buffer
        assert state.packed_terms is None
    for family in SafetyFilter.from_config(model, PAPER_CONFIG).families:
        k, m = family.rows(state).A.shape
        for A, lower, start in (
            (np.zeros((k, m)), np.zeros(k), 1),  # past the end
            (np.zeros((k, m + 1)), np.zeros(k), 0),  # another row width
            (np.zeros((k, m)), np.zeros(k + 1), 0),  # lower not A's rows
        ):
            with pytest.raises(ValueError, match=family.family):
                family.rows_into(state, A, lower, start)


def test_a_field_is_made_once_and_a_replaced_copy_keeps_its_changes():
    model = paper_model()
    c = random_configuration(model, np.random.default_rng(8))
    state = model.state(0.0, c.q, c.dq, c.p_object, c.R_object, c.twist_object)
    assert state.contact_force is state.contact_force
    q = np.zeros_like(c.q)
    copy = dataclasses.replace(state, q=q)
    assert copy.q is q and copy.J_h is state.J_h and copy.t == state.t
    with pytest.raises(ValueError):
        state.q[0] = 1.0


def test_rows_read_from_the_buffer_equal_the_rows_of_the_fields():
    """Each family's rows_into on a packed state (read in its buffer) against rows()."""
    model = paper_model()
    families = SafetyFilter.from_config(model, PAPER_CONFIG).families
    assert all(hasattr(family, 'rows_into') for family in families)
    rng = np.random.default_rng(12)
    for _ in range(3):
        c = random_configuration(model, rng)
        packed = model.state(0.25, c.q, c.dq, c.p_object, c.R_object, c.twist_object)
        fields = dataclasses.replace(packed)  # the same values, every field given
        assert packed.packed_terms is not None and fields.packed_terms is None
        for family in families:
            expected = family.rows(fields)
            k, m = expected.A.shape
            A, lower = np.full((k + 2, m), np.nan), np.full(k + 2, np.nan)
            family.rows_into(packed, A, lower, 1)
            _assert_close(A[1:-1], expected.A, f'{family.family}: A')
            _assert_close(lower[1:-1], expected.lower, f'{family.family}: lower')
            assert np.isnan(A[[0, -1]]).all() and np.isnan(lower[[0, -1]]).all()
            _assert_close(
                family.values(packed, np.zeros(m)).h,
                family.values(fields, np.zeros(m)).h,
                f'{family.family}: h',
            )
