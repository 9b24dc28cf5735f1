"""The simulator's command delay (``command_delay``): the plant applies each command later."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import read_bag
from grasp_safety_filter.io.messages import (
    effort_from_msg,
    effort_to_msg,
    header_stamp_ns,
    MessageNamespace,
)
from grasp_safety_filter.io.parameters import ParameterError
from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.run_types import RunOptions
from grasp_safety_filter.runner import build_endpoints, record_run
from hand_sim_node.command_delay import CommandDelay
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
MSGS = MessageNamespace.from_typestore(get_typestore(Stores.ROS2_JAZZY))
STEPS = 12


@pytest.mark.parametrize(
    ('steps', 'expected'),
    [
        (0, [0, 1, 2, 3, 4, 5]),
        (1, [0, 0, 1, 2, 3, 4]),
        (3, [0, 0, 0, 0, 1, 2]),
        (6, [0, 0, 0, 0, 0, 0]),
    ],
)
def test_delay_line(steps, expected):
    delay = CommandDelay(steps)
    for _ in range(2):  # a reset starts over
        assert [float(delay(np.array([n]))[0]) for n in range(6)] == expected
        delay.reset()


@pytest.fixture(scope='module')
def params():
    return load_node_parameters(CONFIG, HAND_SIM_NODE)


@pytest.fixture(scope='module')
def model(params):
    return GraspModel.from_parameters(params)


def commands(model, count):
    """Distinct torques per tick, well inside the effort limits, N·m."""
    phases = np.arange(model.n_joints)
    return [0.05 * np.sin(0.7 * n + phases) for n in range(count)]


def run_plant(params, model, commands, delay_steps):
    """Send ``commands`` one per tick to a lockstep simulator; return its final state.

    Also the effort of its last joint states: the torque applied over the last step.
    """
    config = SimConfig.from_parameters(params)
    config = dataclasses.replace(
        config,
        duration=len(commands) * config.time_step,
        command_delay=delay_steps * config.time_step,
    )
    sim = HandSimEndpoint(model, config, MSGS)
    sim.start()
    for command in commands:
        outgoing = sim.on_command(effort_to_msg(MSGS, sim.t, model.joint_names, command))
    assert sim.finished and sim.stop_reason == 'duration'
    state = sim.plant.observe()
    (last,) = [o.msg for o in outgoing if o.topic == topics.JOINT_STATES]
    final = np.concatenate([state.q, state.dq, state.p_object_in_palm, state.twist_object])
    return final, np.array(last.effort)


@pytest.mark.parametrize('k', [0, 1, 3])
def test_a_delayed_plant_is_the_undelayed_one_fed_the_shifted_commands(params, model, k):
    c = commands(model, STEPS)
    delayed, applied = run_plant(params, model, c, k)
    # What the delay must amount to: c_0 for the first k steps, then c_0, c_1, ... late by k.
    shifted, _ = run_plant(params, model, [c[0]] * k + c[: STEPS - k], 0)
    np.testing.assert_allclose(delayed, shifted, rtol=0, atol=1e-9)
    np.testing.assert_array_equal(applied, c[STEPS - 1 - k])
    if k:
        undelayed, _ = run_plant(params, model, c, 0)
        assert np.abs(delayed - undelayed).max() > 1e-6


@pytest.mark.parametrize(
    ('fields', 'message'),
    [
        ({'command_delay': -0.001}, r"parameter 'command_delay': expected >= 0"),
        (
            {'command_delay': 0.0025},
            r"parameters 'command_delay' and 'time_step': expected the delay to be a whole "
            r'number of time_step, got command_delay = 0\.0025 s and time_step = 0\.001 s',
        ),
        (
            {'command_delay': 0.003, 'time_step': 0.002},
            r'command_delay = 0\.003 s and time_step = 0\.002 s \(1\.5 steps\)',
        ),
        (
            {'command_delay': 0.003, 'lockstep': False},
            r"parameters 'command_delay' and 'lockstep': the hardware mode \(lockstep false\) "
            r'has no command delay',
        ),
    ],
)
def test_a_bad_delay_fails_at_start_up(params, fields, message):
    with pytest.raises(ParameterError, match=message):
        SimConfig.from_parameters({**params, **fields})


@pytest.mark.parametrize(
    ('delay', 'time_step', 'steps'),
    [(0.0, None, 0), (0.003, None, 3), (0.003, 0.0015, 2), (0.001, 0.0001, 10)],
)
def test_the_runner_takes_the_delay_in_steps_of_its_time_step(delay, time_step, steps):
    options = RunOptions(
        CONFIG, duration=0.1, time_step=time_step, overrides={'command_delay': delay}
    )
    sim, _, _ = build_endpoints(options, MSGS)
    assert sim.config.command_delay_steps == steps


def test_the_runner_refuses_a_delay_its_time_step_does_not_divide():
    options = RunOptions(CONFIG, time_step=0.002, overrides={'command_delay': 0.003})
    with pytest.raises(ParameterError, match=r"'command_delay' and 'time_step'"):
        build_endpoints(options, MSGS)


def test_the_runner_runs_a_hardware_mode_file_with_a_delay_in_lockstep():
    options = RunOptions(CONFIG, overrides={'lockstep': False, 'command_delay': 0.002})
    sim, _, _ = build_endpoints(options, MSGS)
    assert sim.config.lockstep and sim.config.command_delay_steps == 2


def test_a_short_delayed_run_completes(tmp_path):
    options = RunOptions(CONFIG, duration=0.3, overrides={'command_delay': 0.003})
    recording = record_run(options, tmp_path / 'bag')
    assert recording.interrupted is None and recording.stop_reason == 'duration'
    assert recording.t_end == pytest.approx(0.3)
    # In the bag: the effort of the state stamped t_n+1 is the command stamped t_n-3 (t_0
    # while n < 3), clipped to the effort limits as the simulator clips.
    bag = read_bag(tmp_path / 'bag', [topics.JOINT_STATES, topics.EFFORT_COMMAND])
    model = GraspModel.from_parameters(load_node_parameters(CONFIG, HAND_SIM_NODE))
    limits = np.asarray(model.effort_limits, dtype=float)
    sent = [
        (header_stamp_ns(msg), effort_from_msg(msg, model.joint_names).effort)
        for _, msg in bag[topics.EFFORT_COMMAND]
    ]
    states = [(header_stamp_ns(msg), np.array(msg.effort)) for _, msg in bag[topics.JOINT_STATES]]
    # One command per state, in order (the bag is in timestamp order); the last is not applied.
    assert [stamp for stamp, _ in sent] == [stamp for stamp, _ in states]
    for n, (_, effort) in enumerate(states[1:]):
        np.testing.assert_allclose(effort, np.clip(sent[max(n - 3, 0)][1], -limits, limits))
    assert len(states) == 301
