"""The MuJoCo plant behind ``hand_sim_node``: topics, contact events, summary and verdict.

The endpoint's MuJoCo output is checked against independent evidence: the contact forces it
publishes in our contact frames against MuJoCo's own motion of the object (Newton–Euler),
a short runner run against a replay of its bag's torques on a fresh plant, and the contact
events against the plant's own reports under the same torques.
"""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.analysis.verdict import expected_verdict, run_verdict
from grasp_safety_filter.control.nominal import NominalController
from grasp_safety_filter.io.messages import (
    diagnostics_from_msg,
    effort_to_msg,
    MessageNamespace,
    nanoseconds_to_seconds,
)
from grasp_safety_filter.io.plant_schema import PLANT_PARAMETERS
from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters, PAPER_OUTCOME
from grasp_safety_filter.io.sim_diagnostic_keys import PlantEvents, SIM_DIAGNOSTIC, SimKey
from grasp_safety_filter.io.topics import DIAGNOSTICS
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.runner import run, RunOptions
from grasp_tools.bench.recorded_run import Scenario
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint
from hand_sim_node.mjcf import MjcfError, MjcfOptions
from hand_sim_node.mujoco_plant import MuJoCoPlant, OBJECT_DROPPED
from hand_sim_node.plant import PlantConfig

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = MessageNamespace.from_typestore(TYPESTORE)
#: Simulated time of the runner run, s.
RUN_DURATION = 0.2


@pytest.fixture(scope='module')
def params():
    return load_node_parameters(CONFIG, HAND_SIM_NODE)


@pytest.fixture(scope='module')
def model(params):
    return GraspModel.from_parameters(params)


def mujoco_endpoint(params, model, duration):
    config = dataclasses.replace(SimConfig.from_parameters(params), duration=duration)
    return HandSimEndpoint(model, config, MSGS, plant_config=PlantConfig('mujoco'))


# ---------------------------------------------------------------------------- parameters
def test_mujoco_options_come_from_the_parameters_with_the_schema_defaults():
    assert MjcfOptions.from_parameters({}) == MjcfOptions()
    for spec in PLANT_PARAMETERS:
        if spec.name.startswith('mujoco.') and spec.name != 'mujoco.friction_coefficient':
            field = spec.name.removeprefix('mujoco.')
            default = getattr(MjcfOptions(), field)
            assert default == (
                tuple(spec.default) if isinstance(spec.default, list) else spec.default
            )
    options = MjcfOptions.from_parameters(
        {'mujoco': {'cone': 'elliptic', 'solref': [0.004, 1.0], 'friction_coefficient': 0.5}}
    )
    assert (options.cone, options.solref, options.friction_coefficient) == (
        'elliptic',
        (0.004, 1.0),
        0.5,
    )
    assert (
        MjcfOptions.from_parameters({'mujoco.friction_coefficient': 0.0}).friction_coefficient
        is None
    )
    with pytest.raises(MjcfError, match=r'mujoco\.condim'):
        MjcfOptions.from_parameters({'mujoco.condim': 2})


def test_every_config_file_runs_the_rigid_plant_by_default(params):
    assert PlantConfig.from_parameters(params) == PlantConfig()
    assert PlantConfig.from_parameters({**params, 'plant': 'mujoco'}).kind == 'mujoco'


# ------------------------------------------------------------------------ contact forces
def test_published_forces_in_our_contact_frames_move_the_object_as_mujoco_does(params, model):
    """Newton's law on the object: G f_c + w_e from /hand/contacts = MuJoCo's M_o a_o + C_o."""
    sim = mujoco_endpoint(params, model, duration=0.05)
    sim.start()
    scenario = Scenario.load(CONFIG)
    controller = NominalController(scenario.nominal_config)
    reference = scenario.reference(sim.plant.observe())
    for _ in range(20):
        before = sim.plant.observe()
        u = controller.compute(sim.plant.grasp_state(), reference.sample(before.t)).u
        sim.on_command(effort_to_msg(MSGS, sim.t, model.joint_names, u))
        report = sim.plant.last_report
        after = sim.plant.observe()
        state = report.grasp_state
        a_object = (after.twist_object - before.twist_object) / sim.config.time_step
        wrench = state.G @ report.contact_force + state.w_e
        inertial = state.M_o @ a_object + state.C_o_twist
        # Forces exactly (semi-implicit Euler's acceleration is the start state's); torques
        # up to where in the penetration each engine puts the contact point (< 1 mm).
        np.testing.assert_allclose(wrench[:3], inertial[:3], atol=1e-9)
        np.testing.assert_allclose(wrench[3:], inertial[3:], atol=2e-3)
        assert np.all(report.contact_force.reshape(-1, 3)[:, 2] > 0.0)


# ------------------------------------------------------------------------- contact events
def test_an_open_hand_reports_each_contact_lost_and_the_drop(params, model):
    """Zero torque: the fingers fall away; the statuses say when, as the plant measured it."""
    sim = mujoco_endpoint(params, model, duration=0.5)
    sim.start()
    reference = MuJoCoPlant(model, sim.config)
    first_lost = {}
    dropped = None
    statuses = []
    zero = np.zeros(model.n_joints)
    while not sim.finished:
        for topic, stamp_ns, msg in sim.on_command(
            effort_to_msg(MSGS, sim.t, model.joint_names, zero)
        ):
            if topic == DIAGNOSTICS:
                statuses += [(stamp_ns, r) for r in diagnostics_from_msg(msg).reports]
        reference.step(zero)
        contacts = reference.contact_report()
        for name, present in zip(model.contact_names, contacts.present, strict=True):
            if not present:
                first_lost.setdefault(name, contacts.t)
        if contacts.object_dropped and dropped is None:
            dropped = contacts.t
    assert sim.stop_reason == OBJECT_DROPPED == reference.stop_reason
    assert set(first_lost) == set(model.contact_names) and dropped is not None
    onsets = [
        (s, r)
        for s, r in statuses
        if r.name == SIM_DIAGNOSTIC
        and SimKey.PLANT in r.values
        and SimKey.RUN_STOP_REASON not in r.values
    ]
    # One WARN per step with an onset, stamped with the state it was measured at.
    onset_times = sorted({*first_lost.values(), dropped})
    assert [nanoseconds_to_seconds(s) for s, _ in onsets] == pytest.approx(onset_times, abs=1e-12)
    final = PlantEvents.from_values(onsets[-1][1].values, model.contact_names)
    assert final.contact_lost == pytest.approx(first_lost, abs=1e-12)
    assert final.object_dropped == pytest.approx(dropped, abs=1e-12)
    slip = dict(zip(model.contact_names, reference.contact_report().slip_distance, strict=True))
    assert final.slip_distance == pytest.approx(slip, rel=1e-12)
    end = [r for _, r in statuses if SimKey.RUN_STOP_REASON in r.values]
    assert len(end) == 1 and end[0].values[SimKey.RUN_STOP_REASON] == OBJECT_DROPPED
    assert PlantEvents.from_values(end[0].values, model.contact_names) == final


def test_plant_events_read_back_what_they_wrote():
    events = PlantEvents('mujoco', {'c2': 0.25}, 0.5, {'c1': 1e-3, 'c2': 2.5e-3})
    text = {k: repr(v) if isinstance(v, float) else v for k, v in events.to_values().items()}
    assert PlantEvents.from_values(text, ['c1', 'c2']) == events
    assert PlantEvents.from_values({**text, 'contact.lost.other': '0.1'}, ['c1', 'c2']) == events
    assert PlantEvents.from_values({'t': '0.1'}, ['c1']) is None


# --------------------------------------------------------------------------- the runner
@pytest.fixture(scope='module')
def mujoco_run(tmp_path_factory):
    options = RunOptions(CONFIG, 'filtered', duration=RUN_DURATION, overrides={'plant': 'mujoco'})
    return run(options, tmp_path_factory.mktemp('mujoco'))


def test_a_short_mujoco_run_is_recorded_and_summarised_with_its_contact_events(
    mujoco_run, model, params
):
    summary = json.loads((mujoco_run.out_dir / 'summary.json').read_text())
    assert summary['plant'] == 'mujoco' and summary['completed']
    events = summary['contact_events']
    assert events['contact_lost'] == dict.fromkeys(model.contact_names)
    assert events['object_dropped'] is None
    # Replay the bag's commanded torques on a fresh plant: the same slip and forces.
    data = load_run(mujoco_run.bag)
    plant = MuJoCoPlant(
        model, dataclasses.replace(SimConfig.from_parameters(params), duration=RUN_DURATION)
    )
    steps = round(RUN_DURATION / plant.time_step)
    # One contact sample per step; the controllers also answer the final state (not applied).
    assert len(data.t) == steps and len(data.u_command) == steps + 1
    forces = []
    for u in data.u_command[:steps]:
        plant.step(u)
        forces.append(plant.last_report.contact_force.reshape(-1, 3))
    slip = dict(zip(model.contact_names, plant.contact_report().slip_distance, strict=True))
    assert events['slip_distance'] == pytest.approx(slip, rel=1e-12)
    assert all(d > 0.0 for d in slip.values())
    np.testing.assert_allclose(data.force, np.array(forces), rtol=0, atol=1e-12)
    verdict = run_verdict(summary)
    assert verdict.held and verdict.plant == 'mujoco'
    assert 'slip' in verdict.text() and 'contacts lost: none' in verdict.text()
    paper = expected_verdict(PAPER_OUTCOME, 'filtered', summary)
    assert paper.met is None and 'not judged' in paper.text


# ---------------------------------------------------------------------------- verdicts
def _summary(lost=None, dropped=None, joint_limits=0, slip=0, completed=True):
    return {
        'completed': completed,
        'stop_reason': None if completed else OBJECT_DROPPED,
        't_end': 1.0,
        'duration_requested': 1.0,
        'violations': {
            'joint_limits': {'count': joint_limits, 'first_t': 0.5 if joint_limits else None},
            'slip': {'count': slip, 'first_t': 0.5 if slip else None},
        },
        'plant': 'mujoco',
        'contact_events': {
            'contact_lost': {'c1': lost, 'c2': None},
            'object_dropped': dropped,
            'slip_distance': {'c1': 1e-3, 'c2': 2e-3},
        },
    }


@pytest.mark.parametrize(
    ('case', 'held'),
    [
        ({}, True),
        ({'slip': 3}, True),  # beta > mu from MuJoCo's forces is reported, not judged
        ({'lost': 0.4}, False),
        ({'dropped': 0.6, 'completed': False}, False),
        ({'joint_limits': 2}, False),
        ({'completed': False}, False),
    ],
)
def test_a_mujoco_run_held_when_no_contact_lost_no_drop_no_joint_limit(case, held):
    verdict = run_verdict(_summary(**case))
    assert verdict.held is held
    assert verdict.text().startswith(f'held for the duration: {"yes" if held else "no"}')
    assert verdict.to_json()['contact_events']['slip_distance'] == {'c1': 1e-3, 'c2': 2e-3}
