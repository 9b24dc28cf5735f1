"""Overrides for one node (``NODE/NAME``): a plant that is not the controllers' model."""

from __future__ import annotations

from pathlib import Path

import pytest

from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import node_overrides, override_errors
from grasp_safety_filter.model.grasp_check import load_initial_grasp
from grasp_safety_filter.run_types import RunOptions
from grasp_safety_filter.runner import build_endpoints, scenario_hand

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
MU = 'model.friction_coefficient'
MASS = 'model.object.mass'
SIM, NOMINAL, FILTER = 'hand_sim_node', 'nominal_controller_node', 'safety_filter_node'


@pytest.mark.parametrize(
    ('overrides', 'node', 'expected'),
    [
        # Plain names: every node that declares them.
        ({MU: 0.5, 'barrier.alpha1.gain': 3.0}, SIM, {MU: 0.5}),
        ({MU: 0.5, 'barrier.alpha1.gain': 3.0}, FILTER, {MU: 0.5, 'barrier.alpha1.gain': 3.0}),
        # NODE/NAME: that node only.
        ({f'{SIM}/{MU}': 0.5}, SIM, {MU: 0.5}),
        ({f'{SIM}/{MU}': 0.5}, NOMINAL, {}),
        ({f'{SIM}/{MU}': 0.5}, FILTER, {}),
        ({f'{SIM}/{MASS}': 0.2, f'{FILTER}/{MU}': 0.7}, SIM, {MASS: 0.2}),
        ({f'{SIM}/{MASS}': 0.2, f'{FILTER}/{MU}': 0.7}, FILTER, {MU: 0.7}),
        # For its node NODE/NAME beats NAME, whichever comes first.
        ({MU: 0.9, f'{SIM}/{MU}': 0.5}, SIM, {MU: 0.5}),
        ({f'{SIM}/{MU}': 0.5, MU: 0.9}, SIM, {MU: 0.5}),
        ({MU: 0.9, f'{SIM}/{MU}': 0.5}, FILTER, {MU: 0.9}),
        ({}, SIM, {}),
    ],
)
def test_node_overrides(overrides, node, expected):
    assert node_overrides(overrides, node) == expected


@pytest.mark.parametrize(
    ('key', 'message'),
    [
        (
            f'hand_sim/{MU}',
            r"override 'hand_sim/model\.friction_coefficient': unknown node 'hand_sim' "
            r"\(did you mean 'hand_sim_node'\?\)",
        ),
        (f'/{SIM}/{MU}', "unknown node ''"),
        (
            f'{SIM}/model.friction_coeficient',
            "node 'hand_sim_node' does not declare 'model.friction_coeficient' "
            r"\(did you mean 'model\.friction_coefficient'\?\)",
        ),
        (
            f'{SIM}/barrier.alpha1.gain',
            "node 'hand_sim_node' does not declare 'barrier.alpha1.gain' "
            r"\(declared by \['safety_filter_node'\]\)",
        ),
        (f'{NOMINAL}/', "node 'nominal_controller_node' does not declare ''"),
        ('barrier.alpha1.gian', "no node declares it.*did you mean 'barrier.alpha1.gain'"),
    ],
)
def test_bad_keys_name_the_problem(key, message):
    with pytest.raises(ParameterError, match=message):
        RunOptions(CONFIG, overrides={key: 1.0})
    assert len(override_errors([key, MU, f'{SIM}/{MU}'])) == 1


def test_every_bad_key_is_named_at_once():
    with pytest.raises(ParameterError, match=r"'hand_sim/.*; override 'x\.y'"):
        RunOptions(CONFIG, overrides={f'hand_sim/{MU}': 0.5, 'x.y': 1.0})


@pytest.fixture(scope='module')
def mismatched():
    """Endpoints of the paper's scenario with a plant of other μ and object mass."""
    options = RunOptions(
        CONFIG,
        overrides={MU: 0.8, f'{SIM}/{MU}': 0.5, f'{SIM}/{MASS}': 0.2, 'barrier.alpha1.gain': 9.0},
    )
    return options, build_endpoints(options, MessageNamespace.from_typestore())


def test_node_scoped_overrides_reach_only_their_node(mismatched):
    _, (sim, nominal, safety_filter) = mismatched
    assert sim.model.friction_coefficient.tolist() == [0.5] * 3
    assert sim.model.object.mass == 0.2
    for controller in (nominal, safety_filter):
        assert controller.model.friction_coefficient.tolist() == [0.8] * 3
        assert controller.model.object.mass == 0.11  # the file's
    assert safety_filter.filter.config.alpha1_gain == 9.0
    # The plant integrates with its own model.
    assert sim.plant.simulator.model is sim.model


def test_the_scenario_hand_and_the_start_up_check_are_the_plants(mismatched):
    options, _ = mismatched
    _, model = scenario_hand(options)
    assert model.friction_coefficient.tolist() == [0.5] * 3
    assert model.object.mass == 0.2
    checked, params = load_initial_grasp(CONFIG, dict(options.overrides))
    assert params[MU] == 0.5 and params[MASS] == 0.2
    assert checked.friction_coefficient.tolist() == [0.5] * 3
