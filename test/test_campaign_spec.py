"""Campaign files: expansion into runs, their identity, and every mistake refused by name."""

from __future__ import annotations

import json
import math
from pathlib import Path
import textwrap

import numpy as np
import pytest

from grasp_safety_filter.campaign.report import wilson_interval, worst_runs
from grasp_safety_filter.campaign.run import outcome_of
from grasp_safety_filter.campaign.spec import CampaignError, load_campaign
from grasp_safety_filter.campaign.store import ResultStore
from grasp_safety_filter.io.paths import config_path

SCENARIO = config_path('paper_scenario.yaml')


def write(tmp_path: Path, text: str, name: str = 'campaign.yaml') -> Path:
    path = tmp_path / name
    path.write_text(textwrap.dedent(text).replace('SCENARIO', str(SCENARIO)))
    return path


BASE = """
    scenario: SCENARIO
    duration: 0.5
    samples: 4
    seed: 3
    grid:
      barrier.alpha1.gain: [1.0, 10.0, 100.0]
    random:
      model.friction_coefficient: {uniform: [0.5, 0.9]}
      hand_sim_node/model.object.mass: {scale: [0.5, 2.0]}
    reference:
      axes: [z, yaw]
      position: [0.01, 0.1]
      orientation: [0.1, 1.0]
      frequency: [0.5, 2.0]
"""


def test_runs_are_grid_by_samples_by_modes_with_paired_draws(tmp_path):
    runs = load_campaign(write(tmp_path, BASE)).runs()
    assert len(runs) == 3 * 4 * 2
    assert [run.index for run in runs] == list(range(len(runs)))
    assert len({run.key for run in runs}) == len(runs)
    for nominal, filtered in zip(runs[::2], runs[1::2], strict=True):
        # The two modes of a draw are adjacent and differ in nothing else.
        assert (nominal.mode, filtered.mode) == ('nominal', 'filtered')
        assert nominal.overrides == filtered.overrides
    # The same draw in every grid cell: sample s has one friction whatever the gain.
    by_sample: dict[int, set[float]] = {}
    for run in runs:
        by_sample.setdefault(run.sample, set()).add(run.overrides['model.friction_coefficient'])
    assert all(len(values) == 1 for values in by_sample.values())
    assert len({next(iter(v)) for v in by_sample.values()}) == 4


def test_draws_lie_in_their_ranges_and_scale_multiplies_the_scenario_value(tmp_path):
    runs = load_campaign(write(tmp_path, BASE)).runs()
    scenario_mass = 0.11  # config/paper_scenario.yaml's model.object.mass
    for run in runs:
        assert 0.5 <= run.overrides['model.friction_coefficient'] <= 0.9
        mass = run.overrides['hand_sim_node/model.object.mass']
        assert 0.5 * scenario_mass <= mass <= 2.0 * scenario_mass
        amplitude = np.array(run.overrides['reference.amplitude'])
        assert np.count_nonzero(amplitude[[0, 1, 3, 4]]) == 0  # only z and yaw move
        assert 0.01 <= abs(amplitude[2]) <= 0.1
        assert 0.1 <= abs(amplitude[5]) <= 1.0
        assert 0.5 <= run.overrides['reference.frequency'] <= 2.0
        assert math.isclose(run.varied['reference.position'], abs(amplitude[2]))


def test_more_samples_keep_the_earlier_runs(tmp_path):
    few = load_campaign(write(tmp_path, BASE)).runs()
    more = load_campaign(write(tmp_path, BASE.replace('samples: 4', 'samples: 7'))).runs()
    assert {run.key for run in few} <= {run.key for run in more}
    other_seed = load_campaign(write(tmp_path, BASE.replace('seed: 3', 'seed: 4'))).runs()
    assert not {run.key for run in few} & {run.key for run in other_seed}


@pytest.mark.parametrize(
    ('change', 'message'),
    [
        (('duration: 0.5', 'duratoin: 0.5'), "unknown key 'duratoin'"),
        (('duration: 0.5', 'duration: -1.0'), "'duration' must be a number of seconds > 0"),
        (('samples: 4', 'samples: 0'), "'samples' must be an integer >= 1"),
        (('scenario: SCENARIO', 'scenario: nowhere.yaml'), "scenario 'nowhere.yaml'"),
        (('barrier.alpha1.gain', 'barrier.alpha1.gian'), "'barrier.alpha1.gian': no node"),
        (('hand_sim_node/model', 'hand_sim/model'), "unknown node 'hand_sim'"),
        (('[1.0, 10.0, 100.0]', '[1.0, "ten"]'), "parameter 'barrier.alpha1.gain'"),
        (('[1.0, 10.0, 100.0]', '[]'), 'non-empty list'),
        (('{uniform: [0.5, 0.9]}', '{normal: [0.5, 0.9]}'), "random 'model.friction_coefficient'"),
        (('{uniform: [0.5, 0.9]}', '{uniform: [0.9, 0.5]}'), 'lo <= hi'),
        (('{uniform: [0.5, 0.9]}', '{uniform: [-0.5, 0.9]}'), 'friction_coefficient'),
        (('axes: [z, yaw]', 'axes: [z, spin]'), "reference 'axes'"),
        (('frequency: [0.5, 2.0]', 'frequency: [2.0, 0.5]'), "reference 'frequency'"),
    ],
)
def test_a_bad_campaign_is_refused_naming_the_problem(tmp_path, change, message):
    old, new = change
    assert old in BASE
    with pytest.raises(CampaignError, match=message.replace('[', r'\[')):
        load_campaign(write(tmp_path, BASE.replace(old, new)))


def summary(completed=True, violations=None, friction=0.1, events=None) -> dict:
    families = ('fingertip_workspace', 'joint_limits', 'slip', 'separation', 'object_face')
    record = {family: {'count': 0, 'first_t': None} for family in families}
    for family, t in (violations or {}).items():
        record[family] = {'count': 3, 'first_t': t}
    document = {
        'completed': completed,
        't_end': 1.0,
        'duration_requested': 1.0,
        'stop_reason': None if completed else 'slip',
        'violations': record,
        'min_margin': {'fingertip_workspace': 0.2, 'joint_limits': 0.3, 'friction': friction},
        'filter': {'steps': 1000, 'relaxed_steps': 4, 'failed_steps': 0},
        'object_tracking': {'position_error_m': {'rms': 0.01}},
    }
    if events is not None:  # MuJoCo's measured contact events
        document['plant'] = 'mujoco'
        document['contact_events'] = events
    return document


def mujoco_events(lost=None, dropped=None) -> dict:
    return {
        'contact_lost': {'finger1': lost, 'finger2': None},
        'object_dropped': dropped,
        'slip_distance': {'finger1': 0.002, 'finger2': 0.0005},
    }


@pytest.mark.parametrize(
    ('case', 'held', 'first', 'first_t'),
    [
        (summary(), True, '', None),
        (summary(completed=False), False, '', None),
        (summary(violations={'slip': 0.4, 'joint_limits': 0.2}), False, 'joint_limits', 0.2),
        (summary(violations={'object_face': 0.9}), False, 'object_face', 0.9),
        # MuJoCo: slip (beta > mu from its forces) is reported; a lost contact decides.
        (summary(violations={'slip': 0.3}, events=mujoco_events()), True, 'slip', 0.3),
        (summary(events=mujoco_events(lost=0.7)), False, '', None),
        (summary(events=mujoco_events(dropped=0.8)), False, '', None),
        (
            summary(violations={'joint_limits': 0.5}, events=mujoco_events()),
            False,
            'joint_limits',
            0.5,
        ),
    ],
)
def test_a_run_holds_only_to_its_end_with_nothing_violated(case, held, first, first_t):
    outcome = outcome_of(case)
    assert outcome['held'] is held
    assert outcome['first_violation'] == first
    assert outcome['first_violation_t'] == first_t
    assert outcome['orientation_error_rms'] is None
    assert outcome['max_slip'] == (0.002 if 'contact_events' in case else None)


@pytest.mark.parametrize(('held', 'runs'), [(0, 10), (10, 10), (97, 100), (1, 3), (500, 1000)])
def test_wilson_interval_against_its_formula(held, runs):
    z = 1.959963984540054
    p = held / runs
    centre = (p + z * z / (2 * runs)) / (1 + z * z / runs)
    half = z / (1 + z * z / runs) * math.sqrt(p * (1 - p) / runs + z * z / (4 * runs * runs))
    low, high = wilson_interval(held, runs)
    assert low == pytest.approx(max(0.0, centre - half), abs=1e-9)
    assert high == pytest.approx(min(1.0, centre + half), abs=1e-9)


def test_worst_runs_are_the_earliest_losses_then_the_closest_to_slipping():
    rows = [
        {'mode': 'filtered', 'held': True, 'first_violation_t': None, 'min_margin.friction': 0.3},
        {'mode': 'filtered', 'held': False, 'first_violation_t': 2.0, 'min_margin.friction': -1},
        {'mode': 'filtered', 'held': True, 'first_violation_t': None, 'min_margin.friction': 0.01},
        {'mode': 'filtered', 'held': False, 'first_violation_t': 0.5, 'min_margin.friction': 0},
        {'mode': 'filtered', 'held': None, 'error': 'ValueError: x', 'first_violation_t': None},
        {'mode': 'nominal', 'held': False, 'first_violation_t': 0.1, 'min_margin.friction': -1},
    ]
    worst = worst_runs(rows, 'filtered', 3)
    assert [row['first_violation_t'] for row in worst] == [0.5, 2.0, None]
    assert worst[2]['min_margin.friction'] == 0.01


def test_the_store_keeps_what_finished_and_ignores_a_line_cut_short(tmp_path):
    store = ResultStore(tmp_path)
    store.append({'key': 'a', 'held': True})
    store.append({'key': 'b', 'held': False})
    with (tmp_path / 'results.jsonl').open('a') as file:
        file.write('{"key": "c", "he')  # a stop in the middle of a write
    again = ResultStore(tmp_path)
    assert sorted(again.finished) == ['a', 'b']
    again.append({'key': 'c', 'held': True})
    lines = (tmp_path / 'results.jsonl').read_text().splitlines()
    assert [json.loads(line)['key'] for line in lines if line.endswith('}')] == ['a', 'b', 'c']
    assert sorted(ResultStore(tmp_path).finished) == ['a', 'b', 'c']


TWO_SCENARIOS = """
    scenario: [SCENARIO, four_finger_box.yaml]
    duration: 0.5
    samples: 3
    seed: 3
    grid:
      barrier.alpha1.gain: [1.0, 10.0]
    random:
      hand_sim_node/model.object.mass: {scale: [0.5, 2.0]}
    reference:
      axes: [z, yaw]
      position: [0.01, 0.1]
      orientation: [0.1, 1.0]
      frequency: [0.5, 2.0]
"""


def test_a_list_of_scenarios_is_one_more_grid_axis_on_the_same_draws(tmp_path):
    campaign = load_campaign(write(tmp_path, TWO_SCENARIOS))
    runs = campaign.runs()
    box = config_path('four_finger_box.yaml').resolve()
    assert len(runs) == 2 * 2 * 3 * 2
    assert len({run.key for run in runs}) == len(runs)
    assert campaign.varied_columns[0] == 'scenario'
    by_config = {str(SCENARIO.resolve()): 0.11, str(box): 0.1}  # each file's object mass
    for run in runs:
        assert run.varied['scenario'] == (
            str(SCENARIO) if run.config == str(SCENARIO.resolve()) else 'four_finger_box.yaml'
        )
        # A scale multiplies the run's own scenario's value.
        mass = run.overrides['hand_sim_node/model.object.mass']
        assert 0.5 * by_config[run.config] <= mass <= 2.0 * by_config[run.config]
        assert run.varied['hand_sim_node/model.object.mass'] == mass
    # A grid cell is one scenario and one gain; each scenario has its own cells.
    cells = {run.cell: (run.config, run.overrides['barrier.alpha1.gain']) for run in runs}
    assert len(cells) == 4 and len(set(cells.values())) == 4
    for nominal, filtered in zip(runs[::2], runs[1::2], strict=True):
        assert (nominal.mode, filtered.mode) == ('nominal', 'filtered')
        assert (nominal.config, nominal.overrides) == (filtered.config, filtered.overrides)
    # Sample s has one reference and one mass factor, whatever the scenario.
    references, factors = {}, {}
    for run in runs:
        amplitude = tuple(run.overrides['reference.amplitude'])
        references.setdefault(run.sample, set()).add(amplitude)
        factor = run.overrides['hand_sim_node/model.object.mass'] / by_config[run.config]
        factors.setdefault(run.sample, []).append(factor)
    assert all(len(values) == 1 for values in references.values())
    assert all(np.ptp(values) < 1e-12 for values in factors.values())
    assert len({values[0] for values in factors.values()}) == 3


def test_one_scenario_in_a_list_runs_as_the_file_alone(tmp_path):
    alone = load_campaign(write(tmp_path, BASE)).runs()
    listed = load_campaign(write(tmp_path, BASE.replace('SCENARIO', '[SCENARIO]'))).runs()
    assert [run.key for run in listed] == [run.key for run in alone]
    assert all('scenario' not in run.varied for run in listed)


@pytest.mark.parametrize(
    ('change', 'message'),
    [
        ('four_finger_box.yaml]', "scenario 'nowhere.yaml'"),
        ('SCENARIO]', 'names a file twice'),
        ('3]', "'scenario' must be a file name or a list of them, got 3"),
    ],
)
def test_a_bad_scenario_list_is_refused(tmp_path, change, message):
    old = 'four_finger_box.yaml]'
    text = TWO_SCENARIOS.replace(old, change.replace('four_finger_box.yaml', 'nowhere.yaml'))
    with pytest.raises(CampaignError, match=message):
        load_campaign(write(tmp_path, text))


@pytest.mark.parametrize(
    'name', sorted(p.name for p in (Path(config_path()).parent / 'campaigns').glob('*.yaml'))
)
def test_every_example_campaign_loads_with_both_modes_paired(name):
    campaign = load_campaign(Path(config_path()).parent / 'campaigns' / name)
    runs = campaign.runs()
    cells = {run.cell for run in runs}
    assert len(runs) == campaign.samples * len(campaign.modes) * len(cells)
    assert set(campaign.modes) == {'nominal', 'filtered'}
    by_draw = {}
    for run in runs:
        by_draw.setdefault((run.cell, run.sample), []).append(run)
    # Each draw runs in both modes with the same overrides: the modes are paired.
    for pair in by_draw.values():
        assert sorted(run.mode for run in pair) == ['filtered', 'nominal']
        assert pair[0].overrides == pair[1].overrides
