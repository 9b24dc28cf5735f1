"""The one-pass packed model terms against the staged computation they replace.

``GraspModel.state`` computes the terms of spherical fingertips on flat faces in one
compiled pass into one buffer (``PackedGraspState``); the staged path (HandModel.terms, the
contact stack, contact_dynamics; itself checked against numpy formulas in
test_model_kernels.py) must give every field the same value, to the last bit (the filter's
results and the simulated run must not change); ``xi_co_ddot``, which the staged path forms
by a numpy product, to rounding.
"""

from __future__ import annotations

import dataclasses

from grasp_states import paper_model, random_configuration
import numpy as np
import pytest
from random_hands import random_hand

from grasp_safety_filter.control.safety_filter import SafetyFilter
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.packed_state import PackedGraspState

#: xi_co_ddot's largest difference from the staged numpy product, relative to its largest
#: entry: rounding only.
XI_CO_DDOT_RTOL = 1e-11

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


def _states(model, configuration, monkeypatch):
    c = configuration
    args = (0.25, c.q, c.dq, c.p_object, c.R_object, c.twist_object)
    packed = model.state(*args)
    with monkeypatch.context() as patch:
        patch.setattr(model, '_packed_layout', None)
        staged = model.state(*args)
    return packed, staged


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
        for a, b in zip(ours, theirs, strict=True):
            # The same operations in the same order: the same floating-point numbers.
            np.testing.assert_array_equal(a, b, err_msg=field.name)
    # xi_co_ddot is a view of the pass's closed form (M_co = I on a face), not of numpy's
    # batched product (object_rate_terms, then matmul): the same formula, summed in another
    # order (numpy's matmul may fuse a multiply-add), so equal to rounding, not to the bit.
    layout = packed.packed_terms[1]
    start, stop, shape = layout.places['xi_co_ddot_augmented']
    augmented = packed.packed_terms[0][start:stop].reshape(shape)
    m = packed.n_joints
    for part, view in (('matrix', augmented[:, :m]), ('offset', augmented[:, m])):
        ours, theirs = getattr(packed.xi_co_ddot, part), getattr(staged.xi_co_ddot, part)
        assert not ours.flags.writeable and np.shares_memory(ours, packed.packed_terms[0])
        np.testing.assert_array_equal(ours, view)
        scale = np.max(np.abs(theirs))
        assert np.max(np.abs(ours - theirs)) <= XI_CO_DDOT_RTOL * scale, part


@pytest.mark.parametrize('case', list(BOXES))
def test_every_field_equals_the_staged_computation(case, monkeypatch):
    model = paper_model(**BOXES[case])
    rng = np.random.default_rng(5)
    for _ in range(4):
        _assert_same_fields(*_states(model, random_configuration(model, rng), monkeypatch))


def test_a_hand_whose_joints_are_not_in_pinocchios_order_gives_the_same_fields(
    tmp_path, monkeypatch
):
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
        packed = model.state(*args)
        with monkeypatch.context() as patch:
            patch.setattr(model, '_packed_layout', None)
            staged = model.state(*args)
        _assert_same_fields(packed, staged)
    assert permuted, "no box hand of these seeds has its joints out of Pinocchio's order"


def test_a_non_finite_input_takes_the_staged_computation(monkeypatch):
    """A system numba's solve refuses (not finite) takes the staged terms, as before."""
    model = paper_model()
    c = random_configuration(model, np.random.default_rng(3))
    dq = np.array(c.dq)
    dq[0] = np.nan
    args = (0.0, c.q, dq, c.p_object, c.R_object, c.twist_object)
    state = model.state(*args)
    assert not isinstance(state, PackedGraspState)
    with monkeypatch.context() as patch:
        patch.setattr(model, '_packed_layout', None)
        staged = model.state(*args)
    np.testing.assert_array_equal(state.contact_force.offset, staged.contact_force.offset)
    assert not np.isfinite(state.contact_force.offset).all()


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
def test_rows_into_refuses_a_block_that_does_not_fit(packed, monkeypatch):
    model = paper_model()
    c = random_configuration(model, np.random.default_rng(6))
    args = (0.0, c.q, c.dq, c.p_object, c.R_object, c.twist_object)
    if not packed:
        monkeypatch.setattr(model, '_packed_layout', None)
    state = model.state(*args)
    for family in SafetyFilter.from_config(model).families:
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


def test_rows_read_from_the_buffer_equal_the_rows_of_the_fields(monkeypatch):
    """Each family's rows_into on a packed state (read in its buffer) against rows()."""
    model = paper_model()
    families = SafetyFilter.from_config(model).families
    assert all(hasattr(family, 'rows_into') for family in families)
    rng = np.random.default_rng(12)
    for _ in range(3):
        packed, staged = _states(model, random_configuration(model, rng), monkeypatch)
        assert packed.packed_terms is not None and staged.packed_terms is None
        for family in families:
            expected = family.rows(staged)
            k, m = expected.A.shape
            A, lower = np.full((k + 2, m), np.nan), np.full(k + 2, np.nan)
            family.rows_into(packed, A, lower, 1)
            np.testing.assert_array_equal(A[1:-1], expected.A, err_msg=family.family)
            np.testing.assert_array_equal(lower[1:-1], expected.lower, err_msg=family.family)
            assert np.isnan(A[[0, -1]]).all() and np.isnan(lower[[0, -1]]).all()
            np.testing.assert_array_equal(
                family.values(packed, np.zeros(m)).h, family.values(staged, np.zeros(m)).h
            )
