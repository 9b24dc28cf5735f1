"""MuJoCo's friction creep follows the soft-constraint law; our model against MuJoCo.

The creep law (``tools/mujoco_creep.py``) is derived from MuJoCo's documented
constraint model, not fitted: on a held grasp the measured slip velocity must equal
``-R f_t / B`` (elliptic) or ``-(R_+ f_+ - R_- f_-) / (2 μ B)`` (pyramidal) read from MuJoCo's
own rows, and the no-slip solver must stop it. The comparison machinery is checked by
Newton–Euler on both sides and by the limit in which MuJoCo's contacts become rigid; with
soft fingers, against MuJoCo's ``condim`` 4 contacts made stiff and too rough to spin.
"""

from dataclasses import replace
import json
import math
from pathlib import Path

import numpy as np
import pytest

from grasp_safety_filter.control.nominal import NominalController
from grasp_safety_filter.errors import EXIT_CONFIG_ERROR
from grasp_tools import mujoco_compare, mujoco_creep
from grasp_tools.bench.recorded_run import Scenario
from grasp_tools.closed_loop import run_closed_loop
from grasp_tools.mujoco_compare import compare
from hand_sim_node.mjcf import MjcfOptions
from hand_sim_node.mujoco_plant import MuJoCoPlant

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'


@pytest.fixture(scope='module')
def scenario():
    return Scenario.load(CONFIG, mujoco_creep.HOLD_FILTER)


@pytest.mark.parametrize('cone', ['pyramidal', 'elliptic'])
def test_held_grasp_creeps_at_the_soft_constraint_law(scenario, cone):
    """0.6 s hold, last 0.3 s averaged: measured slip velocity = the law's, within 3 %."""
    figures = mujoco_creep.hold(scenario, MjcfOptions(cone=cone), duration=0.6, window=0.3)
    assert figures['ended'] == 'duration'
    loaded = np.array(figures['friction_force_N']) > 0.2  # fingers 1 and 2 carry the weight
    assert loaded.sum() >= 2
    assert np.all(np.array(figures['law_error'])[loaded] < 0.03), figures
    assert np.all(np.array(figures['slip_speed_mm_s'])[loaded] > 1.0)  # it really creeps
    # The 15 s run's total slip cannot be below c_min m g T, far above 3 × 5 mm.
    assert figures['run_slip_lower_bound_mm'] > 15.0


def test_noslip_solver_stops_the_creep_the_law_predicts(scenario):
    soft = mujoco_creep.hold(scenario, MjcfOptions(), duration=0.6, window=0.3)
    hard = mujoco_creep.hold(scenario, MjcfOptions(noslip_iterations=10), duration=0.6, window=0.3)
    assert 'run_slip_lower_bound_mm' not in hard  # no law without soft friction
    assert np.all(np.array(hard['slip_speed_mm_s']) < 0.01 * np.max(soft['slip_speed_mm_s']))


@pytest.fixture(scope='module')
def paper():
    return Scenario.load(CONFIG)


def newton_euler(state, force):
    """``M_o^-1 (G f + w_e - C_o x_o_dot)``: the object's acceleration under contact forces."""
    return np.linalg.solve(state.M_o, state.G @ force + state.w_e - state.C_o_twist)


def test_both_accelerations_are_newton_euler_of_their_own_forces(paper):
    """The comparison's frames: each side's object acceleration is its forces' wrench."""
    plant = MuJoCoPlant(paper.model, paper.sim_config)
    checked = []

    def check(_plant):
        report = plant.last_report
        state, u = report.grasp_state, report.effort
        ours = newton_euler(state, report.contact_force)
        mujoco = plant.last_object_acceleration_in_palm
        np.testing.assert_allclose(mujoco[:3], ours[:3], rtol=0, atol=1e-9)
        # MuJoCo applies each force inside the penetration, ours on the fingertip surface:
        # the moments differ by at most |δ_i| |f_i| per contact.
        forces = np.linalg.norm(report.contact_force.reshape(-1, 3), axis=1)
        moment = np.sum(np.abs(state.penetration) * forces)
        inverse_inertia = np.linalg.norm(np.linalg.inv(state.M_o[3:, 3:]), 2)
        assert np.linalg.norm(mujoco[3:] - ours[3:]) <= inverse_inertia * moment + 1e-9
        np.testing.assert_allclose(
            state.object_acceleration(u), newton_euler(state, state.contact_force(u)),
            rtol=0, atol=1e-9,
        )
        checked.append(True)

    run_closed_loop(
        plant, NominalController(paper.nominal_config), paper.reference(plant.observe()),
        paper.safety_filter(), 0.05, after_step=check,
    )
    assert len(checked) == 50


@pytest.mark.parametrize('d', [0.9, 0.9999])
def test_at_rest_mujoco_forces_approach_ours_as_its_contacts_stiffen(paper, d):
    """First tick (no penetration, at rest): MuJoCo's force is ``(A + R)^-1 A`` ours.

    With ``R = (1 - d)/d · A_ii`` the relative force error is of the order ``(1 - d)/d``:
    at ``d = 0.9999`` within 10 × 1e-4, at MuJoCo's ``dmin = 0.9`` between half and twice
    0.111 (the rigid model is then a 10 % approximation even at rest).
    """
    options = MjcfOptions(cone='elliptic', solimp=(d, d, 0.001, 0.5, 2.0))
    comparison, _ = compare(paper, options, 'nominal', 0.001)
    error = np.linalg.norm(comparison.force_model[0] - comparison.force_mujoco[0])
    relative = error / np.linalg.norm(comparison.force_model[0])
    ratio = (1 - d) / d
    if d > 0.999:
        assert relative < 10 * ratio
    else:
        assert 0.5 * ratio < relative < 2 * ratio


def test_a_squeeze_that_loads_the_faces_does_not_slow_the_creep(scenario):
    """A 3× squeeze lowers |f_t| / f_n but raises |f_t| and so, by the law, the creep."""
    squeeze = replace(scenario, nominal_config=replace(scenario.nominal_config, kf=30.0))
    base = mujoco_creep.hold(scenario, MjcfOptions(), duration=0.6, window=0.3)
    hard = mujoco_creep.hold(squeeze, MjcfOptions(), duration=0.6, window=0.3)
    ratio = np.array(base['friction_force_N'][:2]) / np.array(base['normal_force_N'][:2])
    ratio_hard = np.array(hard['friction_force_N'][:2]) / np.array(hard['normal_force_N'][:2])
    assert np.all(ratio_hard < ratio)
    assert np.all(np.array(hard['slip_speed_mm_s'][:2]) > np.array(base['slip_speed_mm_s'][:2]))


def test_creep_command_prints_the_table_of_every_setting(tmp_path, capsys):
    out = tmp_path / 'creep.json'
    argv = ['--config', str(CONFIG), '--duration', '0.1', '--window', '0.05', '--json', str(out)]
    assert mujoco_creep.main(argv) == 0
    rows = json.loads(out.read_text())
    assert [row['setting'] for row in rows] == [setting[0] for setting in mujoco_creep.SETTINGS]
    table = capsys.readouterr().out.splitlines()
    assert len(table) == 2 + len(rows) and table[2].startswith('| default contacts |')
    # The bound is reported exactly where the law applies: without the no-slip solver.
    for row, (_, options, _, _) in zip(rows, mujoco_creep.SETTINGS, strict=True):
        assert ('run_slip_lower_bound_mm' in row) == ('noslip_iterations' not in options)


def test_compare_command_writes_statistics_and_figure(tmp_path, capsys):
    figure, out = tmp_path / 'compare.png', tmp_path / 'compare.json'
    argv = ['--config', str(CONFIG), '--duration', '0.02', '--figure', str(figure)]
    assert mujoco_compare.main([*argv, '--json', str(out)]) == 0
    figures = json.loads(out.read_text())
    assert json.loads(capsys.readouterr().out) == figures
    assert figures['stop_reason'] == 'duration' and figures['mode'] == 'filtered'
    for name in ('force_N', 'linear_acceleration_m_s2', 'angular_acceleration_rad_s2'):
        stats = figures[name]['error']
        assert 0.0 <= stats['median'] <= stats['p99'] <= stats['max']
    assert figure.read_bytes()[:8] == b'\x89PNG\r\n\x1a\n'
    assert mujoco_compare.main([*argv, '--solref', '0', '1']) == EXIT_CONFIG_ERROR
    assert capsys.readouterr().err.startswith('mujoco_compare: mujoco.solref')


#: The paper's grasp turned 0.2 rad about the palm z axis: at the paper's own grasp B_ho of
#: soft fingers is singular (fingers 1 and 2 forbid the same object spin twice).
TURNED = {'initial.object_orientation': [0.0, 0.0, math.sin(0.1), math.cos(0.1)]}
SOFT_FINGERS = {**TURNED, 'model.torsional_friction': 0.05, 'model.torsional_compliance': 0.0}
#: Stiff contacts; with condim 4 a torsional friction so large that nothing spins: MuJoCo's
#: torsion is a soft constraint whose regulariser grows as 1 / mu_t², so at 0.05 m it creeps.
STIFF = {'cone': 'elliptic', 'solref': (0.004, 1.0), 'solimp': (0.99, 0.99, 0.001, 0.5, 2.0)}
SOFT_FINGER_CONTACTS = {**STIFF, 'condim': 4, 'torsional_friction': 5.0}


@pytest.mark.parametrize(
    'overrides, options',
    [(TURNED, STIFF), (SOFT_FINGERS, SOFT_FINGER_CONTACTS)],
    ids=['point contacts, condim 3', 'soft fingers, condim 4'],
)
def test_our_contacts_match_mujocos_stiff_contacts_of_the_same_kind(overrides, options):
    """0.1 s nominal run; the ticks after 50 ms (MuJoCo's contacts settle on the first ones).

    Soft fingers against MuJoCo's condim 4 as closely as point contacts against condim 3:
    force error below 1e-4 of the force; the torsion (about 0.05 N·m on fingers 1 and 2)
    within 1e-3 of it, so its sign and axis are ours.
    """
    scenario = Scenario.load(CONFIG, plant_overrides=overrides)
    comparison, stop_reason = compare(scenario, MjcfOptions(**options), 'nominal', 0.1)
    assert stop_reason == 'duration'
    settled = comparison.t >= 0.05
    errors, scales = comparison.errors(), comparison.scales()
    force = np.median(scales['force_N'][settled])
    assert np.median(errors['force_N'][settled]) < 1e-4 * force
    assert np.max(errors['force_N'][settled]) < 1e-3 * force
    angular = np.median(scales['angular_acceleration_rad_s2'][settled])
    assert np.max(errors['angular_acceleration_rad_s2'][settled]) < 1e-3 * angular
    assert ('torsion_Nm' in errors) == scenario.model.soft_finger
    if scenario.model.soft_finger:
        torsion = np.max(scales['torsion_Nm'][settled], axis=0)
        assert np.all(torsion[:2] > 0.03)  # N·m: fingers 1 and 2 twist the cube
        assert np.max(errors['torsion_Nm'][settled]) < 1e-3 * torsion.max()


def test_mujocos_object_acceleration_is_newton_euler_of_its_forces_and_torsions():
    """Torsions as the plant reads them from MuJoCo act as ``n_i tau_i`` on the object."""
    scenario = Scenario.load(CONFIG, plant_overrides=SOFT_FINGERS)
    plant = MuJoCoPlant(scenario.model, scenario.sim_config, MjcfOptions(**SOFT_FINGER_CONTACTS))
    n = scenario.model.n_contacts
    torsions = []

    def check(_plant):
        report = plant.last_report
        state, wrench = report.grasp_state, report.contact_force
        assert wrench.shape == (4 * n,)
        mujoco, ours = plant.last_object_acceleration_in_palm, newton_euler(state, wrench)
        np.testing.assert_allclose(mujoco[:3], ours[:3], rtol=0, atol=1e-9)
        forces = np.linalg.norm(wrench[: 3 * n].reshape(-1, 3), axis=1)
        moment = np.sum(np.abs(state.penetration) * forces)
        inverse_inertia = np.linalg.norm(np.linalg.inv(state.M_o[3:, 3:]), 2)
        assert np.linalg.norm(mujoco[3:] - ours[3:]) <= inverse_inertia * moment + 1e-9
        torsions.append(wrench[3 * n :].copy())

    run_closed_loop(
        plant, NominalController(scenario.nominal_config), scenario.reference(plant.observe()),
        None, 0.05, after_step=check,
    )
    # The torsions matter: without them (or with their sign flipped) the moments differ by
    # far more than the bound.
    assert np.max(np.abs(torsions[-1])) > 0.03
