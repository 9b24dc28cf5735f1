"""A controller node's tick on a spare model at start-up (nodes/tick_kernels.py), without ROS.

That it leaves nothing to load at a node's first tick is tested on the nodes themselves
(test_node_shells.py); here, that it runs for every shipped scenario and ends quietly
when the made-up state is refused.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.safety_filter import SafetyFilter, SafetyFilterConfig
from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.nodes.tick_kernels import load_filter_kernels, load_nominal_kernels

REPO = Path(__file__).resolve().parent.parent
CONFIGS = sorted((REPO / 'config').glob('*.yaml'))
MSGS = MessageNamespace.from_typestore(get_typestore(Stores.ROS2_JAZZY))


def _filter_run(config: Path) -> bool:
    parameters = load_node_parameters(config, 'safety_filter_node')
    filter_config = SafetyFilterConfig.from_parameters(parameters)
    return load_filter_kernels(parameters, config.parent, filter_config, MSGS)


def _nominal_run(config: Path) -> bool:
    parameters = load_node_parameters(config, 'nominal_controller_node')
    nominal_config = NominalConfig.from_parameters(parameters)
    return load_nominal_kernels(parameters, config.parent, nominal_config, MSGS)


#: Per controller: its spare run, and the core call that a refusal comes from.
RUNS = {
    'safety filter': (_filter_run, (SafetyFilter, 'solve')),
    'nominal controller': (_nominal_run, (NominalController, 'compute')),
}


@pytest.mark.parametrize('config', CONFIGS, ids=[c.stem for c in CONFIGS])
@pytest.mark.parametrize('run, _', RUNS.values(), ids=RUNS)
def test_the_spare_tick_runs_for_every_scenario(run, _, config):
    assert run(config)


@pytest.mark.parametrize('error', [ValueError, np.linalg.LinAlgError, FloatingPointError])
@pytest.mark.parametrize('run, refusing', RUNS.values(), ids=RUNS)
def test_a_refused_made_up_state_ends_the_spare_tick_quietly(run, refusing, error, monkeypatch):
    def refuse(*args, **kwargs):
        raise error('refused')

    monkeypatch.setattr(*refusing, refuse)
    assert not run(REPO / 'config' / 'paper_scenario.yaml')
