"""The example hand's scenarios (config/four_finger_box.yaml, four_finger_sphere.yaml).

Each loads through ``GraspModel.from_parameters``, passes the start-up grasp check, finds
its contact surfaces from the initial grasp, has rolling rates that match finite
differences of the geometric contact coordinates, and the safety filter turns a nominal
command that does not squeeze (gravity compensation) into one that holds the object: every
normal force positive and every contact force inside its friction cone. ``grasp-demo`` on
the box gives the generic verdict (no expected outcome: exit 0) and draws the joints and
torques in a row per finger.
"""

from __future__ import annotations

import contextlib
import io
import json
from pathlib import Path

from grasp_states import Configuration, moved
import numpy as np
import pytest

from grasp_safety_filter.analysis.figures import FIGURE_FILES, joints_figure, torques_figure
from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.cli import demo_main
from grasp_safety_filter.control.filter_config import SafetyFilterConfig
from grasp_safety_filter.control.safety_filter import SafetyFilter
from grasp_safety_filter.io.schemas import load_node_parameters, SAFETY_FILTER_NODE
from grasp_safety_filter.model.grasp_check import grasp_findings, load_initial_grasp
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.quaternion import rotation_matrix
from grasp_safety_filter.model.surfaces import FlatSurface, SphereSurface
from grasp_safety_filter.runner import RunOptions, scenario_hand

CONFIG = Path(__file__).resolve().parent.parent / 'config'
SCENARIOS = ('four_finger_box.yaml', 'four_finger_sphere.yaml')
EPS = 1e-6


@pytest.fixture(scope='module', params=SCENARIOS)
def scenario(request):
    """Return the path, the checked model and the initial grasp (q, p_o, R_po) on contact."""
    path = CONFIG / request.param
    model, params = load_initial_grasp(path)
    p_o = np.array(params['initial.object_position'])
    R_o = rotation_matrix(params['initial.object_orientation'])
    q = model.project_to_contact(params['initial.joint_positions'], p_o, R_o)
    return path, model, (q, p_o, R_o)


def test_the_example_objects_are_a_box_that_is_not_a_cube_and_a_sphere(scenario):
    path, model, (q, p_o, R_o) = scenario
    assert model.n_joints == 16 and model.n_contacts == 4
    assert [tip.radius for tip in model.hand.fingertips] == [0.012] * 4
    links = [tip.link for tip in model.hand.fingertips]
    assert links == [f'finger{i}_distal' for i in (1, 2, 3, 4)]
    assert grasp_findings(model, q, p_o, R_o) == []
    geometry = model.contact_geometry(q, p_o, R_o)
    if path.name == 'four_finger_box.yaml':
        assert model.object_shape.kind == 'box'
        assert len(set(model.object_shape.edge_lengths)) > 1
        # The faces found are the ones the fingers stand in front of: -x, +x, -y, +y.
        normals = [contact.object_surface.normal for contact in model.contacts]
        expected = [[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]]
        np.testing.assert_allclose(normals, expected, atol=1e-15)
        assert all(isinstance(c.object_surface, FlatSurface) for c in model.contacts)
    else:
        assert model.object_shape.kind == 'sphere' and model.object_shape.radius == 0.025
        assert all(isinstance(c.object_surface, SphereSurface) for c in model.contacts)
        # Each chart is centred on its contact: far from its poles (a = +-pi/2).
        for g in geometry:
            assert abs(g.xi_co[0]) < 1e-3 and abs(g.xi_co[1] + np.pi / 2) < 1e-3
    for g in geometry:
        assert abs(g.penetration) < 1e-12


def test_the_rolling_rates_match_finite_differences_at_the_initial_grasp(scenario):
    _, model, (q, p_o, R_o) = scenario
    rng = np.random.default_rng(9)
    for _ in range(5):
        twist = rng.normal(0.0, 0.3, 6) * np.array([0.1, 0.1, 0.1, 1.0, 1.0, 1.0])
        dq = model.rolling_joint_velocity(q, p_o, R_o, twist)
        c = Configuration(q, dq, p_o, R_o, twist)
        state = c.state(model)

        def coordinates(x: Configuration) -> np.ndarray:
            geometry = model.contact_geometry(x.q, x.p_object, x.R_object)
            return np.array([np.concatenate([g.xi_cf, g.xi_co, [g.psi]]) for g in geometry])

        step = coordinates(moved(c, EPS)) - coordinates(moved(c, -EPS))
        # psi is an angle in (-pi, pi]: its step is taken modulo 2 pi.
        step[:, 4] = np.angle(np.exp(1j * step[:, 4]))
        rates = step / (2 * EPS)
        model_rates = np.column_stack([state.xi_cf_dot, state.xi_co_dot, state.psi_dot])
        # The object moves at |w_o| <= ~1 rad/s: every chart rate is of that order where the
        # charts are regular (at a chart's pole xi_co_dot and psi_dot grow without bound).
        assert np.max(np.abs(model_rates)) < 20.0, model_rates
        for i in range(model.n_contacts):
            scale = max(np.max(np.abs(rates[i])), 1e-3)
            error = np.max(np.abs(model_rates[i] - rates[i])) / scale
            assert error < 1e-5, f'contact {i}: relative error {error:.2e}'


def test_the_filter_turns_gravity_compensation_into_a_grasp_that_holds(scenario):
    path, model, (q, p_o, R_o) = scenario
    params = load_node_parameters(path, SAFETY_FILTER_NODE)
    filter_model = GraspModel.from_parameters(params, path.parent)
    safety_filter = SafetyFilter.from_config(
        filter_model, SafetyFilterConfig.from_parameters(params)
    )
    state = filter_model.state(0.0, q, np.zeros(16), p_o, R_o, np.zeros(6))
    u_nom = np.array(state.gravity_torque)
    # Without a squeeze the fingertips press on nothing: u_nom is not a safe command.
    forces_nom = state.contact_force(u_nom).reshape(4, 3)
    assert np.min(forces_nom[:, 2]) < 0.01
    result = safety_filter.solve(state, u_nom)
    assert result.status == 'solved', result.status
    assert not result.relaxed
    assert np.all(np.isfinite(result.u))
    assert np.all(np.abs(result.u) <= model.effort_limits + 1e-9)
    forces = state.contact_force(result.u).reshape(4, 3)
    mu = model.friction_coefficient
    assert np.all(forces[:, 2] > 0.0)
    assert np.all(np.linalg.norm(forces[:, :2], axis=1) <= mu * forces[:, 2])
    assert min(result.margins.values()) >= -1e-6


# ----------------------------------------------------------------------------------------
# grasp-demo on the example hand: a generic verdict, figures per finger


@pytest.fixture(scope='module')
def box_demo(tmp_path_factory):
    """Run ``grasp-demo --mode both --duration 0.5`` on the box; its exit code and output."""
    out = tmp_path_factory.mktemp('box_demo')
    argv = ['--config', str(CONFIG / 'four_finger_box.yaml'), '--mode', 'both']
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        code = demo_main([*argv, '--duration', '0.5', '--out', str(out)])
    return code, printed.getvalue(), out


def test_grasp_demo_on_the_example_gives_the_generic_verdict_and_exits_0(box_demo):
    code, printed, out = box_demo
    assert code == 0, printed
    assert printed.count('held for the duration: ') == 2
    assert 'paper outcome' not in printed
    verdicts = json.loads((out / 'verdict.json').read_text())
    for mode in ('nominal', 'filtered'):
        summary = json.loads((out / mode / 'summary.json').read_text())
        verdict = verdicts[mode]
        assert verdict['expected_outcome'] is None and 'reproduced' not in verdict
        violated = {f for f, v in summary['violations'].items() if v['count']}
        assert set(verdict['first_violations']) == violated
        assert verdict['held'] is (summary['completed'] and not violated)
        for figure in FIGURE_FILES:
            assert (out / mode / figure).stat().st_size > 0


@pytest.mark.parametrize('which', ['joints', 'torques'])
def test_the_joint_figures_have_a_row_per_finger_with_its_own_joints(box_demo, which):
    _, _, out = box_demo
    run = load_run(out / 'filtered' / 'bag')
    fingers, _ = scenario_hand(RunOptions(CONFIG / 'four_finger_box.yaml'))
    figure = joints_figure(run, fingers) if which == 'joints' else torques_figure(run, fingers)
    panels = [axes for axes in figure.axes if axes.get_visible()]
    rows: dict[str, list[str]] = {}
    label = None
    for axes in panels:
        if axes.get_ylabel():
            label = axes.get_ylabel().splitlines()[0]
        rows.setdefault(label, []).append(axes.get_title(loc='right'))
    assert rows == {f.label: list(f.joint_names) for f in fingers}
    assert list(rows) == ['finger1', 'finger2', 'finger3', 'finger4']
    for axes in panels:
        j = run.joint_names.index(axes.get_title(loc='right'))
        drawn = axes.get_lines()[0 if which == 'joints' else 1].get_ydata()
        expected = run.q[:, j] if which == 'joints' else run.u_command[:, j]
        np.testing.assert_array_equal(drawn, expected)
        if which == 'joints':
            # The grey beyond this joint's own limits.
            low, high = axes.get_ylim()
            assert low <= run.joint_lower_limits[j] and high >= run.joint_upper_limits[j]
