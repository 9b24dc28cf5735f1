"""The filter on the paper's hand with soft fingers: the no-slip rows bound the spin torque.

The rows are read from the model's packed state by compiled code (as every tick does) and
from its ``contact_force`` map; both must agree to the bit. A solved step's contact
wrench ``f_c(u*)`` must then lie in the soft-finger cone: ``|f_t| <= mu f_n`` and
``|tau| <= mu_t f_n``, checked on the wrench itself, not on the rows.
"""

from __future__ import annotations

from dataclasses import replace

from grasp_states import paper_model, random_configuration
import numpy as np
import pytest

from grasp_safety_filter.control.constraints import FrictionPyramid
from grasp_safety_filter.control.constraints.friction_cone import DIAMOND, INSCRIBED
from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.control.filter_result import FilterStatus
from grasp_safety_filter.control.safety_filter import SafetyFilter

MU_T = 0.005  # m
SOFT = {'model.torsional_friction': MU_T}
SOLVED = {FilterStatus.NOMINAL, FilterStatus.SOLVED}


@pytest.fixture(scope='module')
def soft_model():
    return paper_model(**SOFT)


@pytest.mark.parametrize('cone', [INSCRIBED, DIAMOND])
def test_packed_rows_are_the_contact_force_maps_rows_to_the_bit(soft_model, cone):
    model, n = soft_model, len(soft_model.contact_names)
    family = FrictionPyramid(
        model.contact_names, model.friction_coefficient, 8, 0.01, 0.1, cone,
        model.torsional_friction,
    )
    rng = np.random.default_rng(4)
    for tick in range(8):
        state = random_configuration(model, rng).state(model, tick * 1e-3)
        assert state.packed_terms is not None and state.contact_force.offset.shape == (4 * n,)
        rows = family.rows(state)
        A = np.full((len(family.names) + 2, model.n_joints), np.nan)
        lower = np.full(len(family.names) + 2, np.nan)
        family.rows_into(state, A, lower, 1)
        np.testing.assert_array_equal(A[1:-1], rows.A)
        np.testing.assert_array_equal(lower[1:-1], rows.lower)
        u = rng.normal(0.0, 0.3, model.n_joints)
        np.testing.assert_allclose(
            family.values(state, u).h, rows.residual(u) + 0.01, rtol=0, atol=1e-9
        )
        # the torsion rows read the torques: a "+" and a "-" row differ by the torque term
        pairs = rows.residual(u).reshape(n, -1, 2)
        tau = state.contact_force(u)[3 * n:]
        pyramid = np.cos(np.pi / 8) if cone == INSCRIBED else 1.0
        apothem = 0.9 * model.friction_coefficient * pyramid
        np.testing.assert_allclose(
            pairs[:, :, 1] - pairs[:, :, 0],
            (2 * apothem / (0.9 * model.torsional_friction) * tau)[:, None]
            * np.ones(pairs.shape[1]),
            rtol=1e-9, atol=1e-9,
        )


@pytest.mark.parametrize('metric', ['identity', 'inverse_inertia'])
def test_a_solved_step_keeps_every_contact_wrench_in_the_soft_finger_cone(soft_model, metric):
    model, n = soft_model, len(soft_model.contact_names)
    settings = replace(PAPER_CONFIG, metric=metric)
    safety_filter = SafetyFilter.from_config(model, settings)
    point = SafetyFilter.from_config(paper_model(), settings)
    assert len(safety_filter.row_names) - len(point.row_names) == 8 * n
    mu, mu_t = model.friction_coefficient, model.torsional_friction
    rng = np.random.default_rng(8)
    solved = bounded = 0
    for tick in range(40):
        state = random_configuration(model, rng, speed=0.05).state(model, tick * 1e-3)
        u_nom = rng.normal(0.0, 0.4, model.n_joints)
        result = safety_filter.solve(state, u_nom)
        wrench = state.contact_force(result.u)
        f_t = np.hypot(wrench[0:3 * n:3], wrench[1:3 * n:3])
        f_n, tau = wrench[2:3 * n:3], wrench[3 * n:]
        nominal_tau = state.contact_force(u_nom)[3 * n:]
        if result.status not in SOLVED:
            continue
        solved += 1
        bounded += np.any(np.abs(nominal_tau) > mu_t * state.contact_force(u_nom)[2:3 * n:3])
        # eps = 0.01 N and the solver's tolerance on a row of ~1 N per N·m
        assert np.all(f_n > 0.0), tick
        assert np.all(f_t <= mu * f_n + 1e-6), tick
        assert np.all(np.abs(tau) <= mu_t * f_n + 1e-6 * mu_t / mu), tick
        no_slip = [name for name in safety_filter.row_names if name.startswith('no_slip/')]
        h = np.array([result.margins[name] for name in no_slip])
        assert h.min() >= 0.01 - 1e-6, tick
    assert solved >= 10
    assert bounded >= 3  # the torsion rows had something to do
