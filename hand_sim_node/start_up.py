"""When the simulator node may start the run: the graph's readiness (:func:`start_blockers`).

Pure Python: :mod:`hand_sim_node.node` takes a :class:`GraphSnapshot` from rclpy's graph API.
Before it subscribes, the node also steps a spare simulator once
(:func:`load_step_kernels`), so that the run's first step costs what the others cost.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages import effort_to_msg
from grasp_safety_filter.io.topics import (
    CLOCK,
    CONTACTS,
    DIAGNOSTICS,
    EFFORT_COMMAND,
    JOINT_STATES,
    OBJECT_ODOM,
    OBJECT_POSE,
    OBJECT_REFERENCE,
    OBJECT_TRUE_ODOM,
    SCENARIO,
    TOPICS,
)
from hand_sim_node.endpoint import HandSimEndpoint

#: What the graph API gives as a node's name until the node's own announcement arrives.
UNKNOWN_NODE_NAME = '_NODE_NAME_UNKNOWN_'

#: Topics the simulator publishes in lockstep mode.
LOCKSTEP_TOPICS = frozenset((SCENARIO, CLOCK, JOINT_STATES, OBJECT_ODOM, CONTACTS, DIAGNOSTICS))

#: Topics the simulator may publish, in either mode (it does not wait for other publishers of
#: these): the hardware mode adds the tracker's ``/object/pose`` and ``/object/true_odom``
#: (and has no ``/clock``).
SIMULATOR_TOPICS = LOCKSTEP_TOPICS | {OBJECT_POSE, OBJECT_TRUE_ODOM}


@dataclass(frozen=True)
class GraphSnapshot:
    """Who publishes and subscribes each topic of the topic table, at one instant.

    Node names are fully qualified (``"/safety_filter_node"``); the simulator's own node is
    left out.

    Attributes:
        publishers: Topic -> the nodes publishing it (topics without any may be missing).
        subscribers: Topic -> the nodes subscribed to it.
        matched: Simulator topic -> subscriptions matched by the simulator's own publisher.

    """

    publishers: Mapping[str, frozenset[str]] = field(default_factory=dict)
    subscribers: Mapping[str, frozenset[str]] = field(default_factory=dict)
    matched: Mapping[str, int] = field(default_factory=dict)

    def published_by(self, topic: str) -> frozenset[str]:
        """Return the nodes publishing ``topic``."""
        return self.publishers.get(topic, frozenset())

    def subscribed_by(self, topic: str) -> frozenset[str]:
        """Return the nodes subscribed to ``topic``."""
        return self.subscribers.get(topic, frozenset())

    def topics_of(self, node: str) -> list[str]:
        """Return the table topics ``node`` subscribes to, in table order."""
        return [spec.name for spec in TOPICS if node in self.subscribed_by(spec.name)]


def same_node(name: str, qualified: str) -> bool:
    """Whether ``name`` (``"rosbag2_recorder"`` or ``"/ns/rosbag2_recorder"``) is ``qualified``."""
    if name.startswith('/'):
        return name == qualified
    return qualified.rsplit('/', 1)[-1] == name


def start_blockers(
    graph: GraphSnapshot,
    recorder: str = '',
    published: Collection[str] = LOCKSTEP_TOPICS,
    controllers: bool = True,
) -> list[str]:
    """Return what the simulator still waits for before it starts the run (empty: start).

    - With ``controllers`` (lockstep; the hardware mode's driver waits for none): a
      controller, a node publishing ``/hand/effort_command``. That node and every node
      whose topics it needs (the publishers of the table topics it subscribes to, other than
      the simulator's and the optional ``/object/reference``, recursively: the nominal
      controller behind the safety filter) must be subscribed to ``/hand/joint_states``,
      each such topic must have a publisher, and the simulator's state topics must have
      matched subscriptions. Otherwise the first state would reach only part of the graph.
    - With ``recorder`` (a node name): that node subscribed to every table topic that has a
      publisher, the simulator's own (``published``) included, so the bag holds the run from
      its first tick.

    - Every endpoint's node name known: DDS discovers an endpoint before the name of its node,
      and until then two nodes are indistinguishable.

    Args:
        graph: The graph as the simulator sees it.
        recorder: Node name of the recorder; empty: none to wait for.
        published: The topics the simulator publishes.
        controllers: Whether to wait for the controllers.

    """
    blockers: list[str] = []
    unknown = sorted(
        topic
        for topic, nodes in (*graph.publishers.items(), *graph.subscribers.items())
        if any(UNKNOWN_NODE_NAME in node for node in nodes)
    )
    if unknown:
        blockers.append(f'the names of the nodes on {", ".join(dict.fromkeys(unknown))}')
    if controllers:
        blockers += _controller_blockers(graph)
    if recorder:
        missing = [
            spec.name
            for spec in TOPICS
            if (spec.name in published or graph.published_by(spec.name))
            and not any(same_node(recorder, n) for n in graph.subscribed_by(spec.name))
        ]
        if missing:
            blockers.append(f"recorder '{recorder}' subscribed to {', '.join(missing)}")
    return blockers


def _controller_blockers(graph: GraphSnapshot) -> list[str]:
    """Return what the controllers still lack (:func:`start_blockers`)."""
    blockers: list[str] = []
    controllers = sorted(graph.published_by(EFFORT_COMMAND))
    if not controllers:
        blockers.append(f'a publisher on {EFFORT_COMMAND}')
    chain, seen = list(controllers), set(controllers)
    while chain:
        node = chain.pop(0)
        subscribed = graph.topics_of(node)
        if JOINT_STATES not in subscribed:
            blockers.append(f'{node} subscribed to {JOINT_STATES}')
        for topic in subscribed:
            if topic in SIMULATOR_TOPICS or topic == OBJECT_REFERENCE:
                continue
            upstream = graph.published_by(topic)
            if not upstream:
                blockers.append(f'a publisher on {topic} (for {node})')
            for other in sorted(upstream - seen):
                seen.add(other)
                chain.append(other)
    for topic in (JOINT_STATES, OBJECT_ODOM):
        if graph.matched.get(topic, 0) == 0:
            blockers.append(f'a subscription on {topic}')
    return blockers


def load_step_kernels(endpoint: Any) -> None:
    """Step a spare copy of ``endpoint``'s simulator once, with zero torque; drop it.

    ``endpoint``: the lockstep or the hardware mode's (its model, configuration, message
    classes, scenario and plant are copied).

    numba loads a cached kernel at its first call: the plant's first step takes about
    0.3 s of CPU, several seconds of wall time on a loaded machine, while the controllers'
    wall-clock watchdogs (the filter's ``input.hold_timeout``) wait for the next state.
    Called before the run starts, it costs the run nothing. ``endpoint`` is not touched.
    """
    spare = HandSimEndpoint(
        endpoint.model,
        endpoint.config,
        endpoint.msgs,
        scenario_text=endpoint.scenario_text,
        plant_config=endpoint.plant_config,
    )
    spare.start()
    joints = list(endpoint.model.joint_names)
    spare.on_command(effort_to_msg(endpoint.msgs, spare.t, joints, np.zeros(len(joints))))
