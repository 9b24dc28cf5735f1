"""Soft-finger contacts in the model: the parameter, the nominal law, the grasp check."""

from __future__ import annotations

import json

from grasp_states import P_OBJECT_PAPER, paper_model, Q_PAPER, random_configuration
import numpy as np
import pytest

from grasp_safety_filter.control.nominal import NominalController
from grasp_safety_filter.control.reference import PaperReference, Pose
from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.model.grasp_check import grasp_findings
from grasp_safety_filter.nodes.scenario import (
    scenario_document,
    scenario_from_text,
    scenario_to_text,
    ScenarioError,
    TORSIONAL_COMPLIANCE_KEY,
    TORSIONAL_FRICTION_KEY,
)
from hand_sim_node.config import SimConfig

SOFT = {'model.torsional_friction': 0.005}

BAD_VALUES = [
    ({'model.torsional_compliance': -0.1}, 'model.torsional_compliance: expected a finite number'),
    ({'model.torsional_compliance': float('inf')}, 'torsional_compliance: expected a finite'),
    (-0.001, 'model.torsional_friction: expected >= 0, got -0.001'),
    ([0.0, 0.005, 0.005], 'expected 0 for every contact (point contacts with friction) or > 0'),
    ([0.005, 0.005], 'model.torsional_friction: expected 1 or 3 values'),
    (float('nan'), 'model.torsional_friction: expected >= 0, got nan'),
]


@pytest.mark.parametrize(('value', 'message'), BAD_VALUES, ids=[m for _, m in BAD_VALUES])
def test_a_bad_torsional_friction_or_compliance_is_refused_by_name(value, message):
    overrides = value if isinstance(value, dict) else {'model.torsional_friction': value}
    with pytest.raises(ConfigError, match=message.replace('(', r'\(').replace(')', r'\)')):
        paper_model(**overrides)


@pytest.mark.parametrize(('value', 'expected'), [(0.0, None), (0.005, [0.005] * 3)])
def test_zero_is_the_point_contact_and_a_positive_value_the_soft_finger(value, expected):
    model = paper_model(**{'model.torsional_friction': value})
    assert model.soft_finger == (expected is not None)
    assert model.wrench_size == (12 if expected else 9)
    if expected is None:
        assert model.torsional_friction is None
    else:
        np.testing.assert_array_equal(model.torsional_friction, expected)
        assert not model.torsional_friction.flags.writeable
    # The compiled pass's layout took it when the contacts were bound: it cannot change.
    with pytest.raises(AttributeError):
        model.torsional_compliance = 0.0


def test_the_point_contact_rows_of_a_soft_finger_state_are_the_point_contacts():
    """Adding the spin rows changes no force row of J_h, G or their rates."""
    rng = np.random.default_rng(2)
    soft, point = paper_model(**SOFT), paper_model()
    for _ in range(5):
        c = random_configuration(soft, rng)
        s, p = c.state(soft), c.state(point)
        np.testing.assert_array_equal(s.J_h[:9], p.J_h)
        np.testing.assert_array_equal(s.G[:, :9], p.G)
        np.testing.assert_array_equal(s.Jh_dot_dq[:9], p.Jh_dot_dq)
        np.testing.assert_array_equal(s.G_dot_T_twist[:9], p.G_dot_T_twist)
        # The extra constraint can only stiffen the grasp: B_ho's force block is the same.
        np.testing.assert_array_equal(s.B_ho[:9, :9], p.B_ho)


def test_the_nominal_law_plans_on_the_force_rows_of_a_soft_finger_state():
    rng = np.random.default_rng(6)
    soft, point = paper_model(**SOFT), paper_model()
    c = random_configuration(soft, rng)
    reference = PaperReference(Pose(c.p_object, c.R_object)).sample(0.3)
    u_soft = NominalController().compute(c.state(soft), reference).u
    u_point = NominalController().compute(c.state(point), reference).u
    np.testing.assert_array_equal(u_soft, u_point)


def test_the_grasp_check_accepts_the_papers_grasp_with_soft_fingers():
    rng = np.random.default_rng(8)
    model = paper_model(**SOFT)
    c = random_configuration(model, rng)
    assert grasp_findings(model, c.q, c.p_object, c.R_object, 1e-6) == []


@pytest.mark.parametrize('torsional_friction', [0.0, 0.005, [0.004, 0.005, 0.006]])
def test_the_scenario_document_says_which_contact_model_a_run_had(torsional_friction):
    model = paper_model(**{'model.torsional_friction': torsional_friction})
    config = SimConfig(Q_PAPER.tolist(), P_OBJECT_PAPER.tolist())
    document = scenario_from_text(scenario_to_text(scenario_document(model, config)))
    if torsional_friction == 0.0:
        assert TORSIONAL_FRICTION_KEY not in document
    else:
        assert document[TORSIONAL_FRICTION_KEY] == torsional_friction
        assert document[TORSIONAL_COMPLIANCE_KEY] == model.torsional_compliance == 0.1
        document[TORSIONAL_FRICTION_KEY] = -0.005
        with pytest.raises(ScenarioError, match="'torsional_friction'"):
            scenario_from_text(json.dumps(document))
