"""The model's one-pass terms against the general numpy evaluation (model_oracles).

Spherical fingertips on flat faces and on a sphere object are evaluated by compiled closed
forms: ``GraspModel.state`` computes every term of them in one pass (``PackedGraspState``).
The staged computation with the oracle ``ContactStack`` (Montana's formulas as stacked numpy
calls, any surfaces) must agree with every field to rounding. Cases per surface type: the
paper's hand on its cube and on a sphere, point contacts and soft fingers, the four-finger
examples on their box and sphere and random hands holding spheres.
"""

from __future__ import annotations

import dataclasses

from grasp_states import CONFIG_DIR, paper_model, random_configuration, rolling_motion
from model_oracles import ContactStack, staged_state
import numpy as np
import pytest
from random_hands import random_hand

from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.packed_state import PackedGraspState

#: Largest difference allowed, relative to the term's largest entry: rounding only.
RTOL = 1e-11
#: Penetrations are ~0 on the contact manifold: their scale is a length of the grasp, m.
LENGTH_SCALE = 1e-3
#: The scale of terms that are ~0 at some instants: penetrations (m) and an isotropic
#: object's gyroscopic torque (exactly 0 in the model, rounding in numpy's cross product),
#: N·m.
FLOORS = {'penetration': LENGTH_SCALE, 'C_o_twist': 1e-6}
SOFT = {'model.torsional_friction': 0.005}
SPHERE = {'model.object.shape': 'sphere', 'model.object.size': 0.3}
#: Per case: the model's overrides of the paper's, and whether its object surfaces are flat.
PAPER_CASES = {
    'cube': ({}, True),
    'cube, soft fingers': (SOFT, True),
    'sphere': (SPHERE, False),
    'sphere, soft fingers': ({**SPHERE, **SOFT}, False),
}
FOUR_FINGER_CASES = {'point contacts': {}, 'soft fingers': SOFT}
SPHERE_SEEDS = (1, 3, 5)


def _near(model, rng, q0, p_object, R_object, count=3):
    """Return grasps rolling near ``q0`` at the object pose (point contacts or soft fingers)."""
    configurations = []
    for _ in range(count):
        q = model.project_to_contact(q0 + rng.uniform(-0.02, 0.02, q0.size), p_object, R_object)
        twist = rng.normal(0.0, 0.3, 6)
        if model.soft_finger:
            dq, twist = rolling_motion(model, q, p_object, R_object, twist)
        else:
            dq = model.rolling_joint_velocity(q, p_object, R_object, twist)
        configurations.append((q, dq, p_object, R_object, twist))
    return configurations


def _four_finger(overrides, config='four_finger_sphere.yaml'):
    params = load_node_parameters(CONFIG_DIR / config, HAND_SIM_NODE)
    model_params = {k: v for k, v in params.items() if k.startswith('model.')}
    model = GraspModel.from_parameters({**model_params, **overrides}, CONFIG_DIR)
    q0 = np.array(params['initial.joint_positions'])
    p_object = np.array(params['initial.object_position'])
    return model, _near(model, np.random.default_rng(7), q0, p_object, np.eye(3))


def _random_sphere_hand(seed, tmp_path):
    hand = random_hand(seed)
    assert hand.shape == 'sphere'
    path = hand.write(tmp_path)
    params = {**hand.model_parameters(path), **hand.initial_parameters()}
    model = GraspModel.from_parameters(params)
    rng = np.random.default_rng(seed)
    return model, _near(model, rng, hand.q0, hand.p_object, hand.R_object)


def _assert_close(actual, expected, what, floor=1e-300):
    actual, expected = np.asarray(actual), np.asarray(expected)
    assert actual.shape == expected.shape, what
    scale = max(float(np.max(np.abs(expected), initial=0.0)), floor)
    error = float(np.max(np.abs(actual - expected), initial=0.0)) / scale
    assert error <= RTOL, f'{what}: relative difference {error:.2e} > {RTOL:g}'


def _check_state(model, configuration, flat, label):
    """Check that GraspModel.state is one packed pass, equal to the staged numpy evaluation."""
    args = (0.5, *configuration)
    packed = model.state(*args)
    assert isinstance(packed, PackedGraspState), label
    assert model._compiled_contacts.flat is flat
    staged = staged_state(model, *args)
    for field in dataclasses.fields(GraspState):
        ours, theirs = getattr(packed, field.name), getattr(staged, field.name)
        if field.name in ('t', 'w_e'):
            np.testing.assert_array_equal(ours, theirs)
            continue
        if field.name == 'xi_co_rate_terms':
            ours, theirs = ours(), theirs()
        elif hasattr(theirs, 'matrix'):
            ours, theirs = (ours.matrix, ours.offset), (theirs.matrix, theirs.offset)
        else:
            assert not ours.flags.writeable, field.name
            ours, theirs = (ours,), (theirs,)
        floor = FLOORS.get(field.name, 1e-300)
        for a, b in zip(ours, theirs, strict=True):
            _assert_close(a, b, f'{label}: {field.name}', floor)
    # xi_co_ddot is a view of the buffer's xi_co_ddot_augmented (the pass's closed form).
    terms, layout = packed.packed_terms
    start, stop, shape = layout.places['xi_co_ddot_augmented']
    np.testing.assert_array_equal(
        np.column_stack((packed.xi_co_ddot.matrix, packed.xi_co_ddot.offset)),
        terms[start:stop].reshape(shape),
    )
    for part in ('matrix', 'offset'):
        assert not getattr(packed.xi_co_ddot, part).flags.writeable
        assert np.shares_memory(getattr(packed.xi_co_ddot, part), terms)
        _assert_close(
            getattr(packed.xi_co_ddot, part),
            getattr(staged.xi_co_ddot, part),
            f'{label}: xi_co_ddot.{part}',
        )


def _check_stack(model, configuration, flat, label):
    """Check the pass's contact kinematics (in its buffer) against the oracle's."""
    q, dq, p_object, R_object, twist_object = configuration
    packed = model.state(0.5, *configuration)
    assert model._compiled_contacts.flat is flat
    hand = model.hand.terms(q, dq)
    pose = (hand.p_fingertip_in_palm, hand.R_fingertip_to_palm)
    oracle = ContactStack(model.contacts)
    theirs = oracle.kinematics(*pose, hand.twist_fingertip, p_object, R_object, twist_object)
    for terms in theirs:
        for field in dataclasses.fields(terms):
            floor = LENGTH_SCALE if field.name == 'penetration' else 1e-300
            _assert_close(
                getattr(packed, field.name), getattr(terms, field.name),
                f'{label}: {field.name}', floor,
            )


@pytest.mark.parametrize('check', [_check_state, _check_stack])
@pytest.mark.parametrize('case', list(PAPER_CASES))
def test_the_paper_hand_matches_the_general_evaluation(case, check):
    overrides, flat = PAPER_CASES[case]
    model = paper_model(**overrides)
    rng = np.random.default_rng(11)
    for k in range(4):
        c = random_configuration(model, rng)
        configuration = (c.q, c.dq, c.p_object, c.R_object, c.twist_object)
        check(model, configuration, flat, f'{case} #{k}')


@pytest.mark.parametrize('case', list(FOUR_FINGER_CASES))
def test_the_four_finger_hand_on_its_sphere_matches_the_general_evaluation(case):
    model, configurations = _four_finger(FOUR_FINGER_CASES[case])
    for k, configuration in enumerate(configurations):
        _check_stack(model, configuration, False, f'{case} #{k}')
        _check_state(model, configuration, False, f'{case} #{k}')


@pytest.mark.parametrize('case', list(FOUR_FINGER_CASES))
def test_the_four_finger_hand_on_its_box_matches_the_general_evaluation(case):
    model, configurations = _four_finger(FOUR_FINGER_CASES[case], 'four_finger_box.yaml')
    for k, configuration in enumerate(configurations):
        _check_stack(model, configuration, True, f'{case} #{k}')
        _check_state(model, configuration, True, f'{case} #{k}')


@pytest.mark.parametrize('seed', SPHERE_SEEDS)
def test_random_hands_on_spheres_match_the_general_evaluation(seed, tmp_path):
    model, configurations = _random_sphere_hand(seed, tmp_path)
    for k, configuration in enumerate(configurations):
        _check_stack(model, configuration, False, f'seed {seed} #{k}')
        _check_state(model, configuration, False, f'seed {seed} #{k}')


def test_a_fingertip_at_the_sphere_centre_is_refused():
    """The radial projection has no direction there: the numpy evaluation raises too."""
    model = paper_model(**SPHERE)
    c = random_configuration(model, np.random.default_rng(3))
    hand = model.hand.terms(c.q, c.dq)
    pose = (hand.p_fingertip_in_palm, hand.R_fingertip_to_palm)
    p_object = hand.p_fingertip_in_palm[0]
    with pytest.raises(ValueError, match='centre'):
        model.state(0.0, c.q, c.dq, p_object, c.R_object, c.twist_object)
    with pytest.raises(ValueError, match='centre'):
        ContactStack(model.contacts).geometry(*pose, p_object, c.R_object)
