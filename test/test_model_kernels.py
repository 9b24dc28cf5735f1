"""The compiled model kernels against the same equations written as numpy expressions.

The oracle (test/numpy_model_terms.py) evaluates the formulas of
:mod:`grasp_safety_filter.model.dynamics_kernel` with stacked numpy operations and M_h^-1
from numpy's inverse of M_h (the kernel gets Pinocchio's, from its tree Cholesky factor);
the physics of both is checked against finite differences in test_model.py and
test_random_hands.py. Cases: the paper's hand with its cube and with a sphere, and random
hands (3–5 fingers, box or sphere objects, joint orders unlike the URDF's).
"""

from __future__ import annotations

import dataclasses

from grasp_states import Configuration, paper_model, random_configuration, random_hand_grasps
from model_oracles import ContactStack
import numpy as np
from numpy_model_terms import numpy_model_terms
import pinocchio as pin
import pytest

from grasp_safety_filter.model.rolling_kernels import sphere_on_plane_contacts
from grasp_safety_filter.model.wrench_solve import contact_wrench

PAPER_CASES = {
    'cube': {},
    'sphere': {'model.object.shape': 'sphere', 'model.object.size': 0.3},
}
RANDOM_SEEDS = (0, 1, 2, 3, 4, 5)
#: Largest difference allowed, relative to the term's largest entry: rounding only.
RTOL = 1e-11
AFFINE_TERMS = ('contact_force', 'joint_acceleration', 'object_acceleration', 'xi_cf_ddot')


def _random_hand_cases(tmp_path_factory, seed):
    return random_hand_grasps(seed, tmp_path_factory.mktemp(f'kernel_hand{seed}'))


def _assert_close(actual, expected, what):
    scale = max(float(np.max(np.abs(expected))), 1e-12)
    error = float(np.max(np.abs(np.asarray(actual) - expected))) / scale
    assert error <= RTOL, f'{what}: relative difference {error:.2e} > {RTOL:g}'


def _check(model, configurations, label):
    for k, c in enumerate(configurations):
        state = c.state(model)
        expected = numpy_model_terms(model, c.q, c.dq, c.p_object, c.R_object, c.twist_object)
        for name in ('J_h', 'G', 'Jh_dot_dq', 'G_dot_T_twist', 'B_ho'):
            _assert_close(getattr(state, name), expected[name], f'{label} #{k}: {name}')
        for name in AFFINE_TERMS:
            affine = getattr(state, name)
            _assert_close(
                np.column_stack([affine.matrix, affine.offset]),
                expected[name],
                f'{label} #{k}: {name}',
            )
            assert not affine.matrix.flags.writeable and not affine.offset.flags.writeable


@pytest.mark.parametrize('shape', list(PAPER_CASES))
def test_paper_hand_terms_match_the_numpy_formulas(shape):
    model = paper_model(**PAPER_CASES[shape])
    rng = np.random.default_rng(11)
    _check(model, [random_configuration(model, rng) for _ in range(4)], shape)


@pytest.mark.parametrize('seed', RANDOM_SEEDS)
def test_random_hand_terms_match_the_numpy_formulas(seed, tmp_path_factory):
    model, configurations = _random_hand_cases(tmp_path_factory, seed)
    _check(model, configurations, f'seed {seed}')


def test_a_rotated_object_with_an_anisotropic_inertia_matches():
    """A box (anisotropic inertia: M_o^-1 and C_o x_o_dot depend on R_o), turned and spinning."""
    model = paper_model(
        **{'model.object.shape': 'box', 'model.object.edge_lengths': [0.2604, 0.28, 0.24]}
    )
    rng = np.random.default_rng(5)
    c = random_configuration(model, rng)
    assert not model.object.isotropic
    _check(model, [c], 'box')
    turned = pin.exp3(np.array([0.1, -0.2, 0.05])) @ c.R_object
    spun = Configuration(c.q, c.dq, c.p_object, turned, c.twist_object)
    _check(model, [spun], 'box turned')


def test_a_singular_B_ho_raises_as_numpy_solve_does():
    """No inertia anywhere: B_ho = 0, which the start-up check reports as singular."""
    n, m = 3, 9
    zeros = np.zeros
    with pytest.raises(np.linalg.LinAlgError, match='B_ho is singular'):
        contact_wrench(zeros((3 * n, 3 * n)), zeros((3 * n, m + 1)), False, 0.0)
    with pytest.raises(np.linalg.LinAlgError, match='Singular matrix'):
        np.linalg.solve(zeros((3 * n, 3 * n)), zeros((3 * n, m + 1)))


def test_the_compiled_sphere_on_plane_kinematics_match_the_numpy_oracle():
    """sphere_on_plane_contacts (one kernel) against the oracle ContactStack's formulas."""
    model = paper_model()
    rng = np.random.default_rng(2)
    general = ContactStack(model.contacts)
    surfaces = model._compiled_contacts.surface_arrays
    for _ in range(4):
        c = random_configuration(model, rng)
        hand = model.hand.terms(c.q, c.dq)
        arguments = (
            hand.p_fingertip_in_palm,
            hand.R_fingertip_to_palm,
            hand.twist_fingertip,
            c.p_object,
            c.R_object,
            c.twist_object,
        )
        ours = iter(sphere_on_plane_contacts(*arguments, *surfaces))
        for theirs in general.kinematics(*arguments):
            for field in dataclasses.fields(theirs):
                np.testing.assert_allclose(
                    next(ours),
                    getattr(theirs, field.name),
                    rtol=0.0,
                    atol=1e-12,
                    err_msg=field.name,
                )


def _layouts(config: Configuration) -> dict[str, Configuration]:
    """Return the same configuration as each kind of caller passes it."""
    def read_only(array: np.ndarray) -> np.ndarray:
        array = np.array(array)
        array.flags.writeable = False
        return array

    def strided(array: np.ndarray) -> np.ndarray:  # a row of a recorded run's columns
        wide = np.zeros((*array.shape, 2))
        wide[..., 0] = array
        return wide[..., 0]

    fields = dataclasses.fields(config)
    return {
        name: Configuration(*(make(getattr(config, f.name)) for f in fields))
        for name, make in (('writable', np.array), ('read-only', read_only), ('strided', strided))
    }


def test_every_kind_of_caller_shares_one_compiled_pass():
    """A simulator (read-only state), a node (parsed messages), a bag's rows: one kernel."""
    model = paper_model()
    configs = _layouts(random_configuration(model, np.random.default_rng(7)))
    first = configs.pop('writable').state(model)
    kernel = model._compiled_contacts.terms_kernel
    compiled = set(kernel.signatures)
    for name, config in configs.items():
        state = config.state(model)
        assert set(kernel.signatures) == compiled, name  # no other specialisation
        assert np.array_equal(state.contact_force_augmented, first.contact_force_augmented)
