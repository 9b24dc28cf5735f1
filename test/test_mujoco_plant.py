"""The plant interface, the MuJoCo plant's measurements, and the closed loop written once.

MuJoCo's contact measurements are checked against our model's geometry at the same states
(distance = -penetration; slip speed = the tangential part of our rolling-constraint residual,
up to where in the penetration each puts the contact point), and free fall against the exact
semi-implicit Euler solution. The closed loop on our rigid plant reproduces the benchmark's
recorded run tick by tick; on MuJoCo, the paper's scenario runs 0.3 s with the filter.
"""

import json
from pathlib import Path
import sys

import numpy as np
import pytest

from grasp_safety_filter.control.filter_result import FilterStatus
from grasp_safety_filter.control.nominal import NominalController
from grasp_safety_filter.errors import EXIT_CONFIG_ERROR
from grasp_tools import mujoco_run
from grasp_tools.bench.recorded_run import record_filtered_run, Scenario
from grasp_tools.closed_loop import DURATION, run_closed_loop
from hand_sim_node.mjcf import mjcf_from_model, MjcfError, MjcfOptions
from hand_sim_node.mujoco_plant import MuJoCoPlant, MuJoCoUnavailableError, OBJECT_DROPPED
from hand_sim_node.plant import Plant, PlantConfig, RigidPlant
from hand_sim_node.simulator import contact_velocity_residual, SimState

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'


@pytest.fixture(scope='module')
def scenario():
    return Scenario.load(CONFIG)


def mujoco_plant(scenario, **options):
    return MuJoCoPlant(scenario.model, scenario.sim_config, **options)


def test_both_plants_are_plants_from_the_same_grasp(scenario):
    rigid = PlantConfig('rigid').build(scenario.model, scenario.sim_config)
    soft = PlantConfig('mujoco').build(scenario.model, scenario.sim_config)
    assert isinstance(rigid, RigidPlant) and isinstance(soft, MuJoCoPlant)
    for plant in (rigid, soft):
        assert isinstance(plant, Plant)
        assert plant.time_step == scenario.sim_config.time_step
    a, b = rigid.observe(), soft.observe()
    for name in ('q', 'dq', 'p_object_in_palm', 'quaternion_object', 'twist_object'):
        np.testing.assert_allclose(getattr(b, name), getattr(a, name), rtol=0, atol=1e-15)


def test_without_mujoco_the_plant_names_the_extra(scenario, monkeypatch):
    monkeypatch.setitem(sys.modules, 'mujoco', None)  # import mujoco now raises ImportError
    assert '<mujoco' in mjcf_from_model(scenario.model)  # generation needs no mujoco
    PlantConfig('rigid').build(scenario.model, scenario.sim_config)
    with pytest.raises(MuJoCoUnavailableError, match=r'grasp_safety_filter\[mujoco\]'):
        PlantConfig('mujoco').build(scenario.model, scenario.sim_config)


@pytest.mark.parametrize(
    'options, match',
    [
        ({'timestep': 0.0003}, 'whole number of MuJoCo steps'),
        ({'cone': 'round'}, 'mujoco.cone'),
        ({'condim': 2}, 'mujoco.condim'),
        ({'solref': (0.0, 1.0)}, 'mujoco.solref'),
        ({'solimp': (0.95, 0.9, 0.001, 0.5, 2.0)}, 'mujoco.solimp'),
        ({'integrator': 'euler'}, 'mujoco.integrator'),
        ({'friction_coefficient': -0.1}, 'mujoco.friction_coefficient'),
        ({'impratio': 0.0}, 'mujoco.impratio'),
        ({'noslip_iterations': -1}, 'mujoco.noslip_iterations'),
    ],
)
def test_bad_options_are_refused(scenario, options, match):
    with pytest.raises(MjcfError, match=match):
        mujoco_plant(scenario, options=MjcfOptions(**options))


def test_step_checks_its_torque_and_the_stop(scenario):
    plant = mujoco_plant(scenario)
    with pytest.raises(ValueError, match='9 finite joint torques'):
        plant.step(np.zeros(8))
    with pytest.raises(ValueError, match='finite'):
        plant.step(np.full(9, np.nan))
    with pytest.raises(ValueError, match="parameter 'plant'"):
        PlantConfig('soft').build(scenario.model, scenario.sim_config)


@pytest.mark.parametrize('n_substeps', [1, 4])
def test_free_fall_is_exact_and_reported_as_a_drop(scenario, n_substeps):
    """Lifted 1 m off the fingers, the object falls as MuJoCo's Euler step says, exactly."""
    dt = scenario.sim_config.time_step / n_substeps
    plant = mujoco_plant(scenario, options=MjcfOptions(timestep=dt), stop_on_drop=False)
    start = plant.observe()
    lifted = SimState(
        0.0, start.q, start.dq, start.p_object_in_palm + np.array([0.0, 0.0, 1.0]),
        start.quaternion_object, start.twist_object,
    )
    plant.reset(lifted)
    g = scenario.model.object.gravity
    for _ in range(20):
        state = plant.step(np.zeros(scenario.model.n_joints))
    k = 20 * n_substeps  # v_k = k g dt, p_k = p_0 + g dt^2 k (k + 1) / 2
    np.testing.assert_allclose(state.twist_object, np.r_[k * dt * g, np.zeros(3)], atol=1e-14)
    expected = lifted.p_object_in_palm + g * dt**2 * k * (k + 1) / 2
    np.testing.assert_allclose(state.p_object_in_palm, expected, rtol=0, atol=1e-14)
    assert state.t == pytest.approx(0.02, abs=1e-15)
    report = plant.contact_report()
    assert report.object_dropped and not report.present.any()
    assert np.all(report.normal_force == 0.0) and np.all(report.slip_distance == 0.0)
    # The distance of each fingertip sphere from the box: |p - clamp(p, -l/2, l/2)| - R.
    p_f, _, _ = scenario.model.hand.fingertip_placements(state.q)
    p_in_object = (p_f - state.p_object_in_palm) @ state.R_object_to_palm
    half = 0.5 * np.array(scenario.model.object_shape.edge_lengths)
    radii = np.array([tip.radius for tip in scenario.model.hand.fingertips])
    gap = np.linalg.norm(p_in_object - np.clip(p_in_object, -half, half), axis=1) - radii
    np.testing.assert_allclose(report.distance, gap, rtol=1e-12)
    stopping = mujoco_plant(scenario)
    stopping.reset(lifted)
    stopping.step(np.zeros(scenario.model.n_joints))
    assert stopping.stop_reason == OBJECT_DROPPED
    with pytest.raises(RuntimeError, match='object_dropped'):
        stopping.step(np.zeros(scenario.model.n_joints))


def test_contact_measurements_agree_with_our_geometry(scenario):
    """On a nominal run: MuJoCo's distance and slip speed are our model's at the same state."""
    plant = mujoco_plant(scenario)
    checked = []

    def check(plant):
        state = plant.grasp_state()
        report = plant.contact_report()
        np.testing.assert_allclose(report.distance, -state.penetration, rtol=0, atol=1e-9)
        assert report.present.all() and np.all(report.normal_force > 0.0)
        residual = contact_velocity_residual(state).reshape(-1, 3)
        ours = np.linalg.norm(residual[:, :2], axis=1)
        # MuJoCo's contact point lies inside the penetration, ours on the object's surface:
        # the relative velocity differs by (w_f - w_o) × (that offset), |offset| <= |δ|.
        w_relative = state.twist_fingertip[:, 3:] - state.twist_object[3:]
        bound = np.linalg.norm(w_relative, axis=1) * np.abs(state.penetration) + 1e-9
        assert np.all(np.abs(report.slip_speed - ours) <= bound)
        checked.append(report)

    run = run_closed_loop(
        plant, NominalController(scenario.nominal_config), scenario.reference(plant.observe()),
        None, 0.2, after_step=check,
    )
    assert run.stop_reason == DURATION and len(checked) == 200
    # The slip distance is the slip speed integrated over MuJoCo's steps.
    speeds = np.array([report.slip_speed for report in checked])
    np.testing.assert_allclose(
        checked[-1].slip_distance, speeds.sum(axis=0) * plant.options.timestep, rtol=1e-12
    )
    assert np.all(speeds.max(axis=0) > 0.0)


def test_soft_friction_creeps_with_the_load_and_the_noslip_solver_stops_it(scenario):
    """Slip on a held grasp: soft friction creeps, most where the friction force is largest."""

    def slip_after(options):
        plant = mujoco_plant(scenario, options=options)
        run_closed_loop(
            plant, NominalController(scenario.nominal_config),
            scenario.reference(plant.observe()), None, 0.1,
        )
        return plant.contact_report()

    soft = slip_after(MjcfOptions())
    # Fingers 1 and 2 carry ~0.7 N of friction, finger 3 ~0.05 N: it creeps far less.
    assert soft.tangential_force[2] < 0.2 * soft.tangential_force[:2].min()
    assert soft.slip_distance[2] < 0.2 * soft.slip_distance[:2].min()
    hard = slip_after(MjcfOptions(noslip_iterations=10))
    assert np.all(hard.slip_distance < 0.1 * soft.slip_distance)
    assert hard.present.all()


def test_closed_loop_on_our_plant_is_the_recorded_run(scenario):
    """The loop written once over the interface is the benchmark's loop on our simulator."""
    duration = 0.03
    ticks, _, _, _ = record_filtered_run(scenario, duration)
    plant = RigidPlant(scenario.model, scenario.sim_config)
    run = run_closed_loop(
        plant, NominalController(scenario.nominal_config), scenario.reference(plant.observe()),
        scenario.safety_filter(), duration,
    )
    assert len(run.ticks) == len(ticks) == 30
    for ours, theirs in zip(run.ticks, ticks, strict=True):
        np.testing.assert_array_equal(ours.observation.q, theirs.q)
        np.testing.assert_array_equal(ours.u_nom, theirs.u_nom)
        np.testing.assert_array_equal(ours.u, theirs.u)
        assert ours.status == theirs.status


def test_filtered_paper_run_on_mujoco_keeps_every_contact(scenario):
    """0.3 s of the paper's filtered run on MuJoCo: finite torques in limits, no contact lost."""
    plant = mujoco_plant(scenario)
    reports = []
    run = run_closed_loop(
        plant, NominalController(scenario.nominal_config), scenario.reference(plant.observe()),
        scenario.safety_filter(), 0.3, after_step=lambda p: reports.append(p.contact_report()),
    )
    assert run.stop_reason == DURATION and len(run.ticks) == 300
    u = run.array('u')
    assert np.all(np.isfinite(u))
    assert np.all(np.abs(u) <= scenario.model.effort_limits + 1e-9)
    statuses = {tick.status for tick in run.ticks}
    assert statuses <= {
        FilterStatus.NOMINAL, FilterStatus.SOLVED, FilterStatus.RELAXED,
    }, statuses
    assert all(report.present.all() and not report.object_dropped for report in reports)
    slip = np.array([report.slip_distance for report in reports])
    assert np.all(np.isfinite(slip)) and np.all(np.diff(slip, axis=0) >= 0.0)
    assert np.all(slip[-1] > 0.0)  # soft contacts creep: MuJoCo reports it


def test_measurement_command_writes_its_figures(tmp_path, capsys):
    """``python -m grasp_tools.mujoco_run``: both runs, the figures on stdout and in JSON."""
    out = tmp_path / 'figures.json'
    argv = ['--config', str(CONFIG), '--mode', 'both', '--duration', '0.02', '--json', str(out)]
    assert mujoco_run.main(argv) == 0
    figures = json.loads(out.read_text())
    assert json.loads(capsys.readouterr().out) == figures
    assert figures['mujoco']['solref'] == [0.02, 1.0]
    for mode in ('nominal', 'filtered'):
        run = figures[mode]
        assert run['stop_reason'] == DURATION and run['t_end_s'] == pytest.approx(0.02)
        assert run['contact_first_lost_s'] == dict.fromkeys(('finger1', 'finger2', 'finger3'))
        assert run['object_dropped_s'] is None
    assert sum(figures['filtered']['filter_statuses'].values()) == 20
    assert figures['nominal']['filter_statuses'] == {}


def test_measurement_command_refuses_bad_options(capsys):
    assert mujoco_run.main(['--config', str(CONFIG), '--solref', '0', '1']) == EXIT_CONFIG_ERROR
    error = capsys.readouterr().err
    assert error.startswith('mujoco_run: mujoco.solref') and error.count('\n') == 1
