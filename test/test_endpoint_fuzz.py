"""Randomised bad input to every endpoint of the lockstep graph (seeded, bounded in time).

The three endpoints run the paper's scenario wired as the ROS graph wires the nodes, every
message through CDR. At random ticks a mutated copy of a real message (a NaN, a huge value,
a wrong length, a shuffled, missing, duplicated or foreign name, a negative, far-future or
invalid stamp, a wrong frame, a non-unit quaternion, thousands of points...) is handed to
one subscriber. Whatever arrives:

- no exception leaves an endpoint;
- every command the filter sends is finite, by the model's joint names, inside the
  actuator limits; every nominal command and every state the simulator publishes is finite;
- every ``/diagnostics`` message stays small (reports are bounded);
- the run goes on: the simulator never waits for a command that no endpoint will send;
- once the bad input stops, the filter computes its commands again (no lock-out).
"""

from __future__ import annotations

from collections import deque
import copy
import dataclasses
import math
from pathlib import Path
import time
from typing import Any

import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.control.hold_policy import InputPolicyConfig
from grasp_safety_filter.control.nominal import NominalConfig
from grasp_safety_filter.control.safety_filter import SafetyFilterConfig
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.diagnostic_keys import FAILED_STATUSES, INPUT_STATUSES
from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.nominal_controller import NominalControllerEndpoint
from grasp_safety_filter.nodes.outgoing import Outgoing
from grasp_safety_filter.nodes.safety_filter import SafetyFilterEndpoint
from grasp_safety_filter.nodes.scenario import scenario_from_text, ScenarioError
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint

CONFIG = Path(__file__).resolve().parent.parent / 'config' / 'paper_scenario.yaml'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = MessageNamespace.from_typestore(TYPESTORE)

TICKS = 160
"""Lockstep ticks with bad input among them (0.16 s of the paper run)."""
CLEAN_TICKS = 80
"""Ticks of good input afterwards; more than ``input.max_age`` of sim time."""
FUZZ_PROBABILITY = 0.6
"""Chance per tick and subscriber of a mutated message."""
TIME_BUDGET = 120.0
"""Wall-clock bound of one seed's run, s (a hang fails the test instead of the suite)."""
MAX_DIAGNOSTICS_BYTES = 16_000

_INT32 = (-(2**31), -1, 0, 1, 2**31 - 1)
_UINT32 = (0, 1, 999_999_999, 1_000_000_000, 2**32 - 1)
_FLOATS = (math.nan, math.inf, -math.inf, 1e308, -1e308, 1e154, 5e-324, 0.0, -0.0, 1e3)
_STRINGS = ('', 'elbow', 'palm', 'world', 'ünïcödé', 'x' * 5000, 'finger1_joint1')


def _through_cdr(msg: Any) -> Any:
    return TYPESTORE.deserialize_cdr(
        TYPESTORE.serialize_cdr(msg, msg.__msgtype__), msg.__msgtype__
    )


def _slots(msg: Any, path: tuple[str, ...] = ()) -> list[tuple[Any, str, tuple[str, ...]]]:
    """Every mutable field of a message tree: (owner, field name, path)."""
    found = []
    for field in dataclasses.fields(msg):
        value = getattr(msg, field.name)
        here = (*path, field.name)
        if dataclasses.is_dataclass(value):
            found += _slots(value, here)
        else:
            found.append((msg, field.name, here))
            if isinstance(value, list) and value and dataclasses.is_dataclass(value[0]):
                found += _slots(value[0], (*here, '0'))
    return found


def _mutated_value(rng: np.random.Generator, name: str, value: Any, names: list[str]) -> Any:
    """Return a bad value of the same wire type as ``value``."""
    if name == 'sec':
        return int(rng.choice(_INT32)) if rng.random() < 0.7 else value + int(rng.integers(-3, 4))
    if name == 'nanosec':
        return int(rng.choice(_UINT32))
    if isinstance(value, float):
        return float(rng.choice(_FLOATS))
    if isinstance(value, str):
        return str(rng.choice([*_STRINGS, *names]))
    if isinstance(value, np.ndarray):
        kind = rng.integers(5)
        if kind == 0:  # wrong length
            return np.zeros(int(rng.choice([0, 1, max(len(value) - 1, 0), len(value) + 1, 3000])))
        out = np.array(value, dtype=np.float64, copy=True)
        if out.size == 0:
            return np.full(3, float(rng.choice(_FLOATS)))
        if kind == 1:
            out[rng.integers(out.size)] = float(rng.choice(_FLOATS))
        elif kind == 2:
            out[:] = float(rng.choice(_FLOATS))
        else:
            out = out + rng.normal(scale=10.0 ** rng.integers(-3, 3), size=out.shape)
        return out
    if isinstance(value, list):
        items = list(value)
        kind = rng.integers(6)
        if kind == 0:
            return []
        if not items:
            return items
        if kind == 1:
            rng.shuffle(items)
        elif kind == 2:
            items.pop(int(rng.integers(len(items))))
        elif kind == 3:
            items.append(items[int(rng.integers(len(items)))])
        elif kind == 4:
            items = items * int(rng.choice([2, 50, 400]))
        elif isinstance(items[0], str):
            items[int(rng.integers(len(items)))] = str(rng.choice(_STRINGS))
        else:
            items.reverse()
        return items
    return value


def mutate(rng: np.random.Generator, msg: Any, names: list[str]) -> Any | None:
    """Return a copy of ``msg`` with one to three bad fields; None if it cannot be sent."""
    bad = copy.deepcopy(msg)
    slots = _slots(bad)
    for _ in range(int(rng.integers(1, 4))):
        owner, name, _path = slots[int(rng.integers(len(slots)))]
        setattr(owner, name, _mutated_value(rng, name, getattr(owner, name), names))
    try:
        return _through_cdr(bad)
    except Exception:  # a value its wire type cannot carry is never received
        return None


@dataclasses.dataclass
class FuzzGraph:
    """The three endpoints wired as in the ROS graph, with a hook for bad messages."""

    sim: HandSimEndpoint
    nominal: NominalControllerEndpoint
    safety_filter: SafetyFilterEndpoint
    log: list[Outgoing] = dataclasses.field(default_factory=list)
    commands: list[Any] = dataclasses.field(default_factory=list)
    wall: float = 0.0

    def handlers(self) -> dict[str, list[Any]]:
        return {
            topics.JOINT_STATES: [
                self.nominal.on_joint_states,
                self.safety_filter.on_joint_states,
            ],
            topics.OBJECT_ODOM: [self.nominal.on_odom, self.safety_filter.on_odom],
            topics.OBJECT_REFERENCE: [self.nominal.on_reference],
            topics.EFFORT_NOMINAL: [self.safety_filter.on_effort_nominal],
            topics.EFFORT_COMMAND: [self.sim_command],
        }

    def sim_command(self, msg: Any) -> list[Outgoing]:
        """Hold a command for the simulator until the test has sent this tick's bad input."""
        self.commands.append(msg)
        return []

    def step(self) -> None:
        """Hand the held commands to the simulator: it steps on the awaited one."""
        commands, self.commands = self.commands, []
        for msg in commands:
            self.deliver(self.sim.on_command(msg, now=self.wall))

    def deliver(self, outgoing: list[Outgoing]) -> None:
        queue = deque(outgoing)
        handlers = self.handlers()
        while queue:
            topic, stamp_ns, msg = queue.popleft()
            received = _through_cdr(msg)
            self.log.append(Outgoing(topic, stamp_ns, received))
            for handler in handlers.get(topic, []):
                queue.extend(handler(received))


def _reference_msg(state_msg: Any, t: float) -> Any:
    """Return a valid two-point planner reference holding the current object pose."""
    odometry = m.odometry_from_msg(state_msg)
    hold = m.ObjectReference(
        odometry.p_object_in_palm, odometry.R_object_to_palm, np.zeros(6), np.zeros(6)
    )
    return m.reference_to_msg(MSGS, t, [0.0, 0.5], [hold, hold])


def _check_invariants(graph: FuzzGraph, model: GraspModel, start: int) -> None:
    names = list(model.joint_names)
    limits = np.asarray(model.effort_limits)
    for topic, _stamp, msg in graph.log[start:]:
        if topic == topics.EFFORT_COMMAND:
            u = m.effort_from_msg(msg, names).effort
            assert list(msg.name) == names
            assert np.all(np.isfinite(u)), u
            assert np.all(np.abs(u) <= limits * (1 + 1e-9)), (u, limits)
        elif topic == topics.EFFORT_NOMINAL:
            assert np.all(np.isfinite(m.effort_from_msg(msg, names).effort))
        elif topic == topics.JOINT_STATES:
            state = m.joint_state_from_msg(msg, names)
            assert np.all(np.isfinite(state.position)) and np.all(np.isfinite(state.velocity))
        elif topic == topics.DIAGNOSTICS:
            size = len(TYPESTORE.serialize_cdr(msg, msg.__msgtype__))
            assert size <= MAX_DIAGNOSTICS_BYTES, size


def _filter_statuses(log: list[Outgoing]) -> list[str]:
    return [
        report.values['status']
        for o in log
        if o.topic == topics.DIAGNOSTICS
        for report in m.diagnostics_from_msg(o.msg).reports
        if report.name == 'safety_filter' and 'status' in report.values
    ]


@pytest.mark.parametrize('seed', [0, 1])
def test_no_bad_message_crashes_locks_out_or_reaches_the_hand(seed):
    rng = np.random.default_rng(seed)
    params = {
        node: load_node_parameters(CONFIG, node)
        for node in ('hand_sim_node', 'nominal_controller_node', 'safety_filter_node')
    }
    model = GraspModel.from_parameters(params['hand_sim_node'])
    sim_config = SimConfig.from_parameters(params['hand_sim_node'])
    sim_config = dataclasses.replace(
        sim_config, duration=(TICKS + CLEAN_TICKS) * sim_config.time_step,
        command_timeout=0.5,
    )
    filter_values = {**params['safety_filter_node'], 'diagnostics.period': 0.0}
    graph = FuzzGraph(
        HandSimEndpoint(model, sim_config, MSGS),
        NominalControllerEndpoint(
            GraspModel.from_parameters(params['nominal_controller_node']),
            NominalConfig.from_parameters(params['nominal_controller_node']),
            MSGS,
        ),
        SafetyFilterEndpoint(
            GraspModel.from_parameters(filter_values),
            SafetyFilterConfig.from_parameters(filter_values),
            InputPolicyConfig.from_parameters(filter_values),
            MSGS,
        ),
    )
    names = list(model.joint_names)
    handlers = graph.handlers()
    deadline = time.monotonic() + TIME_BUDGET
    graph.deliver(graph.sim.start(now=graph.wall))
    mutated = rejected_by_wire = stalls = 0
    last_step = -1
    while not graph.sim.finished:
        assert time.monotonic() < deadline, 'the run did not finish in its time budget'
        step = graph.sim.simulator.step_index
        last = {o.topic: o.msg for o in graph.log if o.topic in handlers}
        graph.wall += 1e-3
        if step < TICKS and step != last_step and topics.JOINT_STATES in last:
            last[topics.OBJECT_REFERENCE] = _reference_msg(last[topics.OBJECT_ODOM], graph.sim.t)
            for topic, subscribers in handlers.items():
                if topic not in last or rng.random() > FUZZ_PROBABILITY:
                    continue
                bad = mutate(rng, last[topic], names)
                if bad is None:
                    rejected_by_wire += 1
                    continue
                mutated += 1
                for handler in subscribers:
                    graph.deliver(handler(bad))
            graph.deliver(graph.safety_filter.watchdog(graph.wall, graph.sim.t))
        graph.step()
        if graph.sim.simulator.step_index == step and not graph.sim.finished:
            # Nothing answered this state (yet): the simulator's own timeout sends it again.
            stalls += 1
            assert stalls < 20 * (TICKS + CLEAN_TICKS), 'the graph stopped making progress'
            graph.wall += sim_config.command_timeout
            graph.deliver(graph.sim.timeout(now=graph.wall))
        last_step = step
    _check_invariants(graph, model, 0)
    assert mutated > 0.5 * FUZZ_PROBABILITY * TICKS * len(handlers) * 0.5
    assert graph.sim.stop_reason == 'duration'
    # Good input again: the last ticks are computed by the QP, not held or defaulted.
    tail = _filter_statuses(graph.log)[-CLEAN_TICKS // 4:]
    assert tail, 'no filter status at the end of the run'
    stuck = {s for s in tail if s in {*INPUT_STATUSES, *FAILED_STATUSES}}
    assert not stuck, (stuck, tail)
    # ... and the simulator applies them: each state's effort is the command of the one before.
    sent = {o.stamp_ns: o.msg for o in graph.log if o.topic == topics.EFFORT_COMMAND}
    states = [o for o in graph.log if o.topic == topics.JOINT_STATES][-CLEAN_TICKS // 4:]
    dt_ns = m.seconds_to_nanoseconds(sim_config.time_step)
    for o in states:
        applied = m.joint_state_from_msg(o.msg, names).effort
        command = m.effort_from_msg(sent[o.stamp_ns - dt_ns], names).effort
        np.testing.assert_array_equal(applied, command)


@pytest.mark.parametrize('seed', range(4))
def test_scenario_parser_refuses_mutated_documents_with_its_own_error(seed):
    rng = np.random.default_rng(100 + seed)
    params = load_node_parameters(CONFIG, 'hand_sim_node')
    model = GraspModel.from_parameters(params)
    text = HandSimEndpoint(model, SimConfig.from_parameters(params), MSGS).scenario_text
    for _ in range(200):
        chars = list(text)
        for _ in range(int(rng.integers(1, 6))):
            i = int(rng.integers(len(chars)))
            chars[i] = str(rng.choice(['', '{', '"', '-', '1e999', 'nan', '[', '0', 'x']))
        try:
            scenario_from_text(''.join(chars))
        except ScenarioError:
            pass
