"""Per-contact friction coefficients and fingertip workspaces, consumer by consumer.

Three contacts carry the same force ratio beta = |f_t| / f_n = 0.5 and the same fingertip
coordinates; one contact (each in turn) has a low mu or a narrow box. Every consumer must
flag that contact and only it: the friction pyramid and the workspace barrier (the filter's
rows), the simulator's event monitor, the analysis, the start-up grasp check and the
scenario document. A value given once still applies to every contact (the paper's files).
"""

from __future__ import annotations

import math

from grasp_states import P_OBJECT_PAPER, paper_model, Q_PAPER
import numpy as np
import pytest
from scipy.optimize import linprog
from synthetic_state import synthetic_state, with_fields

from grasp_safety_filter.analysis.run_data import RunData
from grasp_safety_filter.analysis.summary import constraint_log
from grasp_safety_filter.control.constraints import FingertipWorkspaceBarrier, FrictionPyramid
from grasp_safety_filter.control.filter_config import PAPER_CONFIG
from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io.parameters import NodeSchema, ParameterError, validate_parameters
from grasp_safety_filter.io.schemas import check_model_parameters, MODEL_PARAMETERS
from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.fingertip_workspace import FingertipWorkspace
from grasp_safety_filter.model.grasp_check import (
    FORCE_CLOSURE_PYRAMID_FACES,
    grasp_findings,
    squeezes_inside_friction_cones,
)
from grasp_safety_filter.model.per_contact import friction_coefficients
from grasp_safety_filter.nodes.scenario import (
    check_scenario,
    scenario_document,
    scenario_from_text,
    scenario_to_text,
    ScenarioError,
)
from hand_sim_node.config import SimConfig
from hand_sim_node.events import EventMonitor

NAMES = ('finger1', 'finger2', 'finger3')
SIM_CONFIG = SimConfig(Q_PAPER.tolist(), P_OBJECT_PAPER.tolist())
#: Contact forces (f_x, f_y, f_n), N: beta = 0.5 at every contact.
FORCES = np.array([[0.3, 0.4, 1.0], [0.0, -0.5, 1.0], [-0.5, 0.0, 1.0]])
BETA = 0.5
MU_HIGH, MU_LOW = 0.9, 0.3
#: Fingertip coordinates (a, b) of every contact, rad.
XI = np.array([[0.5, -1.5]] * 3)
WIDE = {'a_min': -1.0, 'a_max': 1.0, 'b_min': -3.0, 'b_max': -0.1}
#: Per bound, the value that puts XI outside the box by 0.1 rad.
NARROW = {'a_min': 0.6, 'a_max': 0.4, 'b_min': -1.4, 'b_max': -1.6}


def low_mu(low: int) -> list[float]:
    return [MU_LOW if i == low else MU_HIGH for i in range(3)]


def narrow_box(low: int, bound: str) -> dict[str, object]:
    box: dict[str, object] = dict(WIDE)
    box[bound] = [NARROW[bound] if i == low else WIDE[bound] for i in range(3)]
    return box


CASES = [(low, bound) for low in range(3) for bound in ('a_min', 'a_max', 'b_min', 'b_max')]


# ------------------------------------------------------------------------------ the filter
@pytest.mark.parametrize('low', range(3))
def test_the_pyramid_constrains_only_the_low_friction_contact(low):
    state = synthetic_state(np.random.default_rng(low))
    m = state.q.size
    state = with_fields(state, contact_force=AffineMap(np.zeros((9, m)), FORCES.ravel()))
    pyramid = FrictionPyramid(NAMES, low_mu(low), faces=8)
    h = pyramid.values(state, np.zeros(m)).h.reshape(3, 8)
    # Independently: the inscribed pyramid's faces hold iff beta <= mu cos(pi/8) (worst face).
    for i in range(3):
        inside = BETA <= low_mu(low)[i] * math.cos(math.pi / 8)
        assert (h[i].min() > 0) == inside == (i != low), (i, h[i])
    rows = pyramid.rows(state)
    negative = np.flatnonzero(rows.residual(np.zeros(m)) < 0)
    violated = {rows.names[k].split('/')[1] for k in negative}
    assert violated == {NAMES[low]}


@pytest.mark.parametrize(('low', 'bound'), CASES)
def test_the_workspace_barrier_uses_each_contacts_own_box(low, bound):
    state = with_fields(synthetic_state(np.random.default_rng(7)), xi_cf=XI.copy())
    barrier = FingertipWorkspaceBarrier(NAMES, **narrow_box(low, bound))
    h, _ = barrier.barrier(state)
    negative = [barrier.names[k] for k in np.flatnonzero(h < 0)]
    assert negative == [f'fingertip_workspace/{NAMES[low]}/{bound}']
    np.testing.assert_allclose(h[h < 0], -0.1, atol=1e-12)


# ----------------------------------------------------------------- simulator and analysis
def monitor(mu: object, box: dict[str, object]) -> EventMonitor:
    return EventMonitor(
        np.full(2, -1.0), np.full(2, 1.0), tuple(box.values()), mu, ['j1', 'j2'], list(NAMES)
    )


@pytest.mark.parametrize(('low', 'bound'), CASES)
def test_the_event_monitor_flags_only_the_contact_past_its_own_limits(low, bound):
    watch = monitor(low_mu(low), narrow_box(low, bound))
    events = watch.events(watch.margins_at(0.0, np.zeros(2), XI, FORCES.ravel()))
    assert sorted((e.family, e.name, e.side) for e in events) == sorted(
        [('slip', NAMES[low], ''), ('fingertip_workspace', NAMES[low], bound)]
    )


def test_one_value_for_every_contact_is_the_same_as_n_equal_values():
    shared = monitor(MU_LOW, WIDE).margins_at(0.0, np.zeros(2), XI, FORCES.ravel())
    listed = monitor([MU_LOW] * 3, {k: [v] * 3 for k, v in WIDE.items()}).margins_at(
        0.0, np.zeros(2), XI, FORCES.ravel()
    )
    np.testing.assert_array_equal(shared.values, listed.values)
    np.testing.assert_allclose(shared.friction, MU_LOW - BETA)


@pytest.mark.parametrize(('low', 'bound'), CASES)
def test_the_analysis_judges_each_contact_against_its_own_values(low, bound):
    model = paper_model(
        **{'model.friction_coefficient': low_mu(low)},
        **{f'model.fingertip_workspace.{k}': v for k, v in narrow_box(low, bound).items()},
    )
    scenario = scenario_from_text(scenario_to_text(scenario_document(model, SIM_CONFIG)))
    steps = 4
    run = RunData(
        scenario=scenario,
        mode='nominal',
        t=np.arange(steps) * 1e-3,
        q=np.tile(Q_PAPER, (steps, 1)),
        xi_cf=np.tile(XI, (steps, 1, 1)),
        force=np.tile(FORCES, (steps, 1, 1)),
        required_friction=np.full((steps, 3), BETA),
        t_command=np.zeros(0),
        u_nominal=np.zeros((0, 9)),
        u_command=np.zeros((0, 9)),
    )
    np.testing.assert_array_equal(run.mu_per_contact, low_mu(low))
    log = constraint_log(run)
    onsets = {(e.family, e.name) for e in log.onsets}
    assert onsets == {('slip', NAMES[low]), ('fingertip_workspace', NAMES[low])}
    assert log.min_margin()['friction'] == pytest.approx(MU_LOW - BETA)


# ------------------------------------------------------------------ model and documents
def test_the_paper_scenario_keeps_one_number_per_value():
    document = scenario_document(paper_model(), SIM_CONFIG)
    assert document['friction_coefficient'] == 0.9
    assert all(isinstance(v, float) for v in document['fingertip_workspace'].values())


def test_per_contact_values_reach_the_scenario_document_in_contact_order():
    model = paper_model(**{'model.friction_coefficient': [0.9, 0.5, 0.7]})
    document = scenario_from_text(scenario_to_text(scenario_document(model, SIM_CONFIG)))
    assert document['friction_coefficient'] == [0.9, 0.5, 0.7]
    with pytest.raises(ScenarioError, match=r"'friction_coefficient': expected 1 or 3"):
        check_scenario({**document, 'friction_coefficient': [0.9, 0.5]})


@pytest.mark.parametrize('low', range(3))
def test_the_start_up_check_names_the_contact_outside_its_own_workspace(low):
    wide = paper_model()
    a, _ = wide.contact_geometry(Q_PAPER, P_OBJECT_PAPER, np.eye(3))[low].xi_cf
    a_max = [float(a) - 0.01 if i == low else 1.4 for i in range(3)]
    model = paper_model(**{'model.fingertip_workspace.a_max': a_max})
    findings = grasp_findings(model, Q_PAPER, P_OBJECT_PAPER, np.eye(3))
    assert [f.subject for f in findings] == [f"contact '{NAMES[low]}'"]
    assert 'outside its fingertip workspace' in findings[0].problem
    assert grasp_findings(wide, Q_PAPER, P_OBJECT_PAPER, np.eye(3)) == []


BAD_VALUES = [
    (
        {'model.friction_coefficient': [0.9, 0.9, -0.1]},
        r'model\.friction_coefficient\[2\] \(contact finger3\): expected > 0, got -0\.1',
    ),
    ({'model.friction_coefficient': [0.9, 0.9]}, r'friction_coefficient: expected 1 or 3 values'),
    (
        {'model.fingertip_workspace.b_max': [0.0, -3.5, 0.0]},
        r'b_min/b_max\[1\] \(contact finger2\): expected b_min < b_max, got b_min=-3\.14',
    ),
    (
        {'model.fingertip_workspace.a_min': [-1.0, -1.0, -1.0, -1.0]},
        r'fingertip_workspace\.a_min: expected 1 or 3 values',
    ),
]


@pytest.mark.parametrize(('overrides', 'message'), BAD_VALUES)
def test_the_model_refuses_a_bad_value_naming_the_contact(overrides, message):
    with pytest.raises(ConfigError, match=message):
        paper_model(**overrides)


@pytest.mark.parametrize(
    ('overrides', 'message'),
    [
        ({'model.friction_coefficient': [0.9, 0.9]}, 'friction_coefficient.*expected 1 or 3'),
        ({'model.fingertip_workspace.a_min': [-1.0] * 4}, 'a_min.*expected 1 or 3 values'),
        (
            {'model.fingertip_workspace.b_max': [0.0, -3.5, 0.0]},
            'b_max.* element 1: expected b_min < b_max',
        ),
    ],
)
def test_the_parameter_check_refuses_a_wrong_count_or_an_empty_box(overrides, message):
    values = {spec.name: spec.default for spec in MODEL_PARAMETERS}
    values.update({'model.object.shape': 'cube', **overrides})
    with pytest.raises(ParameterError, match=message):
        check_model_parameters(values)


@pytest.mark.parametrize(
    ('value', 'accepted'),
    [(0.9, 0.9), ([0.9, 0.5, 0.7], [0.9, 0.5, 0.7]), ([1, 0.5], None), ([], None), ([0.0], None)],
)
def test_the_schema_takes_one_double_or_a_list_of_doubles(value, accepted):
    spec = next(s for s in MODEL_PARAMETERS if s.name == 'model.friction_coefficient')
    schema = NodeSchema('node', (spec,))
    if accepted is None:
        with pytest.raises(ParameterError, match=r'model\.friction_coefficient'):
            validate_parameters(schema, {spec.name: value})
    else:
        assert validate_parameters(schema, {spec.name: value})[spec.name] == accepted


def test_a_shared_value_broadcasts_and_a_list_is_kept_in_contact_order():
    np.testing.assert_array_equal(friction_coefficients(0.5, NAMES), [0.5] * 3)
    np.testing.assert_array_equal(friction_coefficients([0.1, 0.2, 0.3], NAMES), [0.1, 0.2, 0.3])
    box = FingertipWorkspace.for_contacts(NAMES, **narrow_box(1, 'a_max'))
    np.testing.assert_array_equal(box.per_contact(3)[:, 1], [1.0, 0.4, 1.0])
    np.testing.assert_allclose(box.margins(XI)[:, 1], [0.5, -0.1, 0.5], atol=1e-15)


# ------------------------------------------------------------- force closure, per-contact mu
def random_grasp_map(rng: np.random.Generator, n: int) -> np.ndarray:
    """G of n contacts on a unit sphere, contact z axes pointing into it, random x axes."""
    blocks = []
    for _ in range(n):
        p = rng.normal(size=3)
        p /= np.linalg.norm(p)
        z = -p
        x = np.cross(z, rng.normal(size=3))
        x /= np.linalg.norm(x)
        R = np.column_stack((x, np.cross(z, x), z))
        p_skew = np.array([[0, -p[2], p[1]], [p[2], 0, -p[0]], [-p[1], p[0], 0]])
        blocks.append(np.vstack((R, p_skew @ R)))
    return np.hstack(blocks)


def squeeze_margin_lp(G: np.ndarray, mu: np.ndarray, faces: int) -> float:
    """Largest t with G f = 0, sum_i f_n,i = 1 and every face margin >= t (scipy's LP).

    Scale-free (the normal forces sum to 1): t > 0 iff a squeeze inside every pyramid exists.
    """
    n = mu.size
    theta = 2 * np.pi * np.arange(faces) / faces
    A = np.zeros((n * faces, 3 * n))
    for i in range(n):
        for j in range(faces):
            A[i * faces + j, 3 * i : 3 * i + 3] = (
                -np.cos(theta[j]),
                -np.sin(theta[j]),
                mu[i] * np.cos(np.pi / faces),
            )
    cost = np.zeros(3 * n + 1)
    cost[-1] = -1.0
    normal_sum = np.zeros(3 * n + 1)
    normal_sum[2 : 3 * n : 3] = 1.0
    result = linprog(
        cost,
        A_ub=np.column_stack((-A, np.ones(n * faces))),
        b_ub=np.zeros(n * faces),
        A_eq=np.vstack((np.column_stack((G, np.zeros(6))), normal_sum)),
        b_eq=np.eye(7)[6],
        bounds=[(None, None)] * (3 * n + 1),
    )
    assert result.status == 0, result.message
    return float(result.x[-1])


def closed(margin: float) -> bool:
    """Force closure by the LP's t*; t* = 0 exactly: a contact can only carry no force."""
    assert not 1e-10 < abs(margin) < 1e-6, f'a borderline grasp (t* = {margin}): another seed'
    return margin > 1e-6


@pytest.mark.parametrize('seed', range(40))
def test_force_closure_agrees_with_an_lp_and_uses_each_contacts_mu(seed):
    rng = np.random.default_rng(seed)
    n = 3 + seed % 2
    G = random_grasp_map(rng, n)
    mu = rng.uniform(0.05, 1.0, n)
    margin = squeeze_margin_lp(G, mu, FORCE_CLOSURE_PYRAMID_FACES)
    assert squeezes_inside_friction_cones(G, mu) == closed(margin)
    # Enough friction at every contact closes any grasp of rank 6 ...
    assert squeezes_inside_friction_cones(G, np.full(n, 50.0))
    # ... and lowering one contact's mu is judged with that contact's own value.
    if margin > 0:
        weakest = mu.copy()
        weakest[seed % n] = 0.01
        expected = squeeze_margin_lp(G, weakest, FORCE_CLOSURE_PYRAMID_FACES)
        assert squeezes_inside_friction_cones(G, weakest) == closed(expected)


def test_both_outcomes_occur_in_the_table():
    outcomes = set()
    for seed in range(40):
        rng = np.random.default_rng(seed)
        n = 3 + seed % 2
        G, mu = random_grasp_map(rng, n), rng.uniform(0.05, 1.0, n)
        outcomes.add(squeezes_inside_friction_cones(G, mu))
    assert outcomes == {True, False}


def test_a_ros_node_declares_one_value_or_a_list_per_contact():
    import rclpy
    from rclpy.exceptions import InvalidParameterValueException
    from rclpy.parameter import Parameter

    from grasp_safety_filter.io.parameters import declare_node_parameters
    from grasp_safety_filter.io.schemas import NODE_SCHEMAS, SAFETY_FILTER_NODE

    schema = NODE_SCHEMAS[SAFETY_FILTER_NODE]
    rclpy.init()
    try:
        overrides = [
            Parameter('model.friction_coefficient', value=[0.8, 0.8, 0.6]),
            Parameter('model.fingertip_workspace.a_max', value=1.2),
        ]
        node = rclpy.create_node('safety_filter_node', parameter_overrides=overrides)
        values = declare_node_parameters(node, schema)
        assert values['model.friction_coefficient'] == [0.8, 0.8, 0.6]
        assert values['model.fingertip_workspace.a_max'] == 1.2
        # Read-only, as every model parameter; a list element out of range is refused.
        assert node.describe_parameter('model.friction_coefficient').read_only
        node.destroy_node()
        bad = rclpy.create_node(
            'safety_filter_node',
            parameter_overrides=[Parameter('model.friction_coefficient', value=[0.8, -0.1])],
        )
        message = r"friction_coefficient' element 1: expected > 0"
        with pytest.raises(InvalidParameterValueException, match=message):
            declare_node_parameters(bad, schema)
        bad.destroy_node()
    finally:
        rclpy.try_shutdown()


def test_the_filter_of_a_model_takes_each_contacts_values():
    from grasp_safety_filter.control.safety_filter import SafetyFilter

    model = paper_model(
        **{
            'model.friction_coefficient': [0.9, 0.3, 0.7],
            'model.fingertip_workspace.a_max': [1.4, 1.0, 1.2],
        }
    )
    no_slip, _, workspace = SafetyFilter.from_config(model, PAPER_CONFIG).families
    np.testing.assert_array_equal(no_slip.mu, [0.9, 0.3, 0.7])
    np.testing.assert_array_equal(workspace.a_max, [1.4, 1.0, 1.2])
    np.testing.assert_array_equal(workspace.a_min, [model.fingertip_workspace.a_min] * 3)
