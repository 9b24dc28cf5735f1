"""The one-pass packed model terms against the staged computation they replace.

``GraspModel.state`` computes the terms of spherical fingertips on flat faces in one
compiled pass into one buffer (``PackedGraspState``); the staged path (HandModel.terms, the
contact stack, contact_dynamics; itself checked against numpy formulas in
test_model_kernels.py) must give every field the same value, to the last bit (the filter's
results and the simulated run must not change).
"""

from __future__ import annotations

import dataclasses

from grasp_states import paper_model, random_configuration
import numpy as np
import pytest

from grasp_safety_filter.control.safety_filter import SafetyFilter
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.packed_state import PackedGraspState

BOXES = {
    'cube': {},
    'anisotropic box': {
        'model.object.shape': 'box',
        'model.object.edge_lengths': [0.26, 0.28, 0.24],
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


@pytest.mark.parametrize('case', list(BOXES))
def test_every_field_equals_the_staged_computation(case, monkeypatch):
    model = paper_model(**BOXES[case])
    rng = np.random.default_rng(5)
    for _ in range(4):
        packed, staged = _states(model, random_configuration(model, rng), monkeypatch)
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
        np.testing.assert_array_equal(packed.xi_co_ddot.matrix, staged.xi_co_ddot.matrix)
        np.testing.assert_array_equal(packed.xi_co_ddot.offset, staged.xi_co_ddot.offset)


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
