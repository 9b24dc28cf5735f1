"""The grasp as markers: the endpoint on the simulator's messages, and the node over real DDS.

The markers are checked from the message alone (through CDR), against the geometry they must
show: each contact point on its fingertip sphere (the ``fingertips`` markers) and on the
object's surface (the ``object`` marker), the cones' colours against beta / mu, the active
rows' contacts and joints in red, one link marker per URDF ``<visual>`` solid. Over DDS the
node publishes at most ``markers.rate`` a second, stamped as the joint states it drew.
"""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys
import time
from typing import Any
import xml.etree.ElementTree as ElementTree

import numpy as np
import pinocchio as pin
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.diagnostic_keys import FILTER_DIAGNOSTIC, Key
from grasp_safety_filter.io.messages.markers import MARKER_TYPES
from grasp_safety_filter.io.schemas import GRASP_MARKERS_NODE, load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.grasp_markers import GraspMarkersEndpoint, MarkerConfig
from hand_sim_node.config import SimConfig
from hand_sim_node.endpoint import HandSimEndpoint

REPO = Path(__file__).resolve().parent.parent
CONFIGS = ['paper_scenario.yaml', 'four_finger_box.yaml', 'four_finger_sphere.yaml']
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = m.MessageNamespace.from_typestore(TYPESTORE)
BIN = Path(sys.executable).parent
#: How far a drawn contact point may lie off its sphere or face (the messages' float64), m.
ON_SURFACE = 1e-7


def through_cdr(msg: Any) -> Any:
    """Serialise to CDR and back, as the middleware does."""
    raw = TYPESTORE.serialize_cdr(msg, msg.__msgtype__)
    return TYPESTORE.deserialize_cdr(raw, msg.__msgtype__)


def simulator_messages(name: str) -> tuple[GraspModel, dict[str, Any]]:
    """Return the scenario's model and its simulator's messages of a step, by topic.

    The step is the first one under gravity compensation (it publishes the contact forces).
    """
    params = load_node_parameters(REPO / 'config' / name, 'hand_sim_node')
    model = GraspModel.from_parameters(params)
    sim = HandSimEndpoint(model, SimConfig.from_parameters(params), MSGS)
    first = {o.topic: o.msg for o in sim.start()}
    joints = m.joint_state_from_msg(first[topics.JOINT_STATES], model.joint_names)
    gravity = model.hand.terms(joints.position, joints.velocity).gravity_torque
    command = m.effort_to_msg(MSGS, m.header_stamp_ns(first[topics.JOINT_STATES]),
                              model.joint_names, gravity)  # fmt: skip
    return model, {o.topic: o.msg for o in sim.on_command(command)}


def endpoint_for(name: str) -> tuple[GraspMarkersEndpoint, dict[str, Any]]:
    """Return a markers endpoint of the scenario and its simulator's messages of a step."""
    params = load_node_parameters(REPO / 'config' / name, GRASP_MARKERS_NODE)
    model = GraspModel.from_parameters(params)
    _, messages = simulator_messages(name)
    return GraspMarkersEndpoint(model, MSGS, MarkerConfig.from_parameters(params)), messages


def by_namespace(array: Any) -> dict[str, list[Any]]:
    markers: dict[str, list[Any]] = {}
    for marker in array.markers:
        markers.setdefault(marker.ns, []).append(marker)
    return markers


def xyz(point: Any) -> np.ndarray:
    return np.array([point.x, point.y, point.z])


def rotation(q: Any) -> np.ndarray:
    return m.matrix_from_quaternion_xyzw(np.array([q.x, q.y, q.z, q.w]))


def diagnostics_with_active(rows: str) -> Any:
    report = m.DiagnosticReport.create(
        FILTER_DIAGNOSTIC, m.DiagnosticLevel.OK, 'QP solved', {Key.ACTIVE: rows}
    )
    return m.diagnostics_to_msg(MSGS, 0.0, report)


@pytest.mark.parametrize('name', CONFIGS)
def test_contact_points_are_drawn_on_the_fingertips_and_on_the_object(name):
    endpoint, messages = endpoint_for(name)
    assert endpoint.markers() is None  # nothing before a state and a pose
    endpoint.on_joint_states(messages[topics.JOINT_STATES])
    assert endpoint.markers() is None
    endpoint.on_odom(messages[topics.OBJECT_ODOM])
    endpoint.on_contacts(messages[topics.CONTACTS])
    array = through_cdr(endpoint.markers())
    markers = by_namespace(array)
    stamp = m.header_stamp_ns(messages[topics.JOINT_STATES])
    assert all(m.header_stamp_ns(marker) == stamp for marker in array.markers)
    assert {marker.header.frame_id for marker in array.markers} == {endpoint.model.palm_frame}
    (contacts,) = markers['contacts']
    points = np.array([xyz(p) for p in contacts.points])
    tips = markers['fingertips']
    assert len(points) == len(tips) == endpoint.model.n_contacts
    for point, tip in zip(points, tips, strict=True):
        assert tip.type == MARKER_TYPES['sphere']
        radius = tip.scale.x / 2.0
        assert abs(np.linalg.norm(point - xyz(tip.pose.position)) - radius) < ON_SURFACE
    (body,) = markers['object']
    in_object = (points - xyz(body.pose.position)) @ rotation(body.pose.orientation)
    if body.type == MARKER_TYPES['sphere']:
        assert np.allclose(np.linalg.norm(in_object, axis=1), body.scale.x / 2, atol=ON_SURFACE)
    else:
        half = np.array([body.scale.x, body.scale.y, body.scale.z]) / 2.0
        assert np.allclose((np.abs(in_object) - half).max(axis=1), 0.0, atol=ON_SURFACE)
    # Force arrows: on the object, from each contact point.
    for arrow, point in zip(markers['forces'], points, strict=True):
        assert np.allclose(xyz(arrow.points[0]), point)
    # Friction cones, drawn in their contact frames: apex at the contact point, axis into
    # the object, every rim point at the cone's half angle atan(mu) from the axis.
    mu = endpoint.model.friction_coefficient
    for cone, point, mu_i in zip(markers['cones'], points, mu, strict=True):
        R, p = rotation(cone.pose.orientation), xyz(cone.pose.position)
        assert np.allclose(p, point)
        axis = R[:, 2]
        assert np.dot(xyz(body.pose.position) - point, axis) > 0.0
        in_palm = np.array([xyz(q) for q in cone.points]) @ R.T + p
        rays = in_palm - point
        rays = rays[np.linalg.norm(rays, axis=1) > 1e-12]
        tangent = np.linalg.norm(np.cross(rays, axis), axis=1) / (rays @ axis)
        assert np.allclose(tangent, mu_i)


@pytest.mark.parametrize('name', CONFIGS)
def test_one_link_marker_per_urdf_visual_solid(name):
    endpoint, messages = endpoint_for(name)
    endpoint.on_joint_states(messages[topics.JOINT_STATES])
    endpoint.on_odom(messages[topics.OBJECT_ODOM])
    links = by_namespace(endpoint.markers())['links']
    urdf = ElementTree.parse(endpoint.model.hand.urdf_path).getroot()
    solids = [
        geometry.tag
        for visual in urdf.iter('visual')
        for geometry in visual.find('geometry')
        if geometry.tag in ('box', 'sphere', 'cylinder')
    ]
    kinds = {'box': 'cube', 'sphere': 'sphere', 'cylinder': 'cylinder'}
    expected = sorted(MARKER_TYPES[kinds[solid]] for solid in solids)
    assert sorted(marker.type for marker in links) == expected
    assert [marker.id for marker in links] == list(range(len(links)))


def test_cones_are_coloured_by_the_friction_used_and_active_rows_red():
    endpoint, messages = endpoint_for('paper_scenario.yaml')
    endpoint.on_joint_states(messages[topics.JOINT_STATES])
    endpoint.on_odom(messages[topics.OBJECT_ODOM])
    grey = by_namespace(endpoint.markers())['cones']
    assert all(abs(c.color.r - c.color.g) < 1e-9 for c in grey)  # no forces: grey
    contacts = m.contacts_from_msg(messages[topics.CONTACTS], endpoint.model.contact_names)
    endpoint.on_contacts(messages[topics.CONTACTS])
    first = endpoint.model.contact_names[0]
    joint = endpoint.model.joint_names[1]
    endpoint.on_diagnostics(
        diagnostics_with_active(f'no_slip/{first}/face0,joint_limits/{joint}/upper')
    )
    markers = by_namespace(through_cdr(endpoint.markers()))
    used = contacts.required_friction / endpoint.model.friction_coefficient
    cones = markers['cones']
    # More of the cone used: redder (the colour map runs green -> red).
    order = np.argsort(used)
    redness = np.array([c.color.r - c.color.g for c in cones])
    assert np.all(np.diff(redness[order]) >= -1e-9)
    (contact_dots,) = markers['contacts']
    colours = [(c.r, c.g, c.b) for c in contact_dots.colors]
    assert colours[0] == pytest.approx((0.84, 0.15, 0.16))
    assert all(colour == (0.0, 0.0, 0.0) for colour in colours[1:])
    # The joint's origin, by Pinocchio's forward kinematics at the published state.
    hand = endpoint.model.hand
    q = m.joint_state_from_msg(messages[topics.JOINT_STATES], hand.joint_names).position
    q_pin = np.empty(hand.model.nq)
    q_pin[hand.pinocchio_index] = q
    data = hand.model.createData()
    pin.forwardKinematics(hand.model, data, q_pin)
    (point,) = markers['active'][0].points
    assert np.allclose(xyz(point), data.oMi[hand.model.getJointId(joint)].translation)
    assert f'joint_limits/{joint}/upper' in markers['active'][1].text


def test_input_that_does_not_parse_is_counted_not_raised():
    endpoint, messages = endpoint_for('paper_scenario.yaml')
    state = messages[topics.JOINT_STATES]
    state.position[0] = float('nan')
    endpoint.on_joint_states(state)
    endpoint.on_odom(messages[topics.OBJECT_ODOM])
    assert endpoint.markers() is None
    assert endpoint.rejected == {topics.JOINT_STATES: 1}
    assert topics.JOINT_STATES in endpoint.last_error


# ----------------------------------------------------------------------------------------
# The node over DDS


def test_the_node_draws_the_newest_state_at_most_at_its_rate(tmp_path):
    import rclpy
    from rclpy.executors import SingleThreadedExecutor

    rate = 20.0
    log = tmp_path / 'grasp_markers_node.log'
    command = [
        str(BIN / 'grasp_markers_node'), '--ros-args', '--params-file',
        str(REPO / 'config' / 'paper_scenario.yaml'), '-p', f'markers.rate:={rate}',
    ]  # fmt: skip
    model, messages = simulator_messages('paper_scenario.yaml')
    msgs = m.MessageNamespace.from_rclpy()
    joints = m.joint_state_from_msg(messages[topics.JOINT_STATES], model.joint_names)
    pose = m.odometry_from_msg(messages[topics.OBJECT_ODOM])
    context = rclpy.Context()
    rclpy.init(context=context)
    node = rclpy.create_node('markers_probe', context=context)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    received: list[tuple[float, int]] = []
    published: list[int] = []

    def qos(topic: str) -> Any:
        return topics.topic_spec(topic).qos.to_rclpy()

    def cls(topic: str) -> Any:
        return m.rclpy_message_class(topics.topic_spec(topic).msgtype)

    node.create_subscription(
        cls(topics.MARKERS), topics.MARKERS,
        lambda msg: received.append((time.monotonic(), m.header_stamp_ns(msg.markers[0]))),
        qos(topics.MARKERS),
    )  # fmt: skip
    publishers = {
        t: node.create_publisher(cls(t), t, qos(t))
        for t in (topics.JOINT_STATES, topics.OBJECT_ODOM)
    }

    def publish() -> None:  # the grasp's state and pose stamped now, every 10 ms at most
        stamp = node.get_clock().now().nanoseconds
        if published and stamp - published[-1] < 10_000_000:
            return
        publishers[topics.JOINT_STATES].publish(
            m.joint_state_to_msg(
                msgs, stamp, model.joint_names, joints.position, joints.velocity, None
            )
        )
        publishers[topics.OBJECT_ODOM].publish(
            m.odometry_to_msg(
                msgs, stamp, pose.p_object_in_palm, pose.R_object_to_palm, pose.twist_object
            )
        )
        published.append(stamp)

    with log.open('w') as out:
        process = subprocess.Popen(command, stdout=out, stderr=subprocess.STDOUT, cwd=tmp_path)
    try:
        start = time.monotonic()
        while time.monotonic() - start < 20.0 and len(received) < 3:
            publish()
            executor.spin_once(timeout_sec=0.01)
        assert received, log.read_text()
        cpu_before, wall_before = _cpu_seconds(process.pid), time.monotonic()
        received.clear()
        while time.monotonic() - wall_before < 3.0:
            publish()
            executor.spin_once(timeout_sec=0.005)
        cpu = (_cpu_seconds(process.pid) - cpu_before) / (time.monotonic() - wall_before)
    finally:
        process.terminate()
        process.wait(timeout=30)
        executor.shutdown()
        node.destroy_node()
        rclpy.shutdown(context=context)
    # At most the rate (one period of slack for the window's ends), and not far below it.
    assert 0.5 * rate * 3.0 <= len(received) <= rate * 3.0 + 2, len(received)
    assert {stamp for _, stamp in received} <= set(published)  # stamped as a state it drew
    print(f'grasp_markers_node at {rate:g} Hz: {100 * cpu:.1f} % of one core')
    assert cpu < 0.5  # far from the control loop's core


def _cpu_seconds(pid: int) -> float:
    """User + system CPU time of a process, s (Linux)."""
    fields = Path(f'/proc/{pid}/stat').read_text().rsplit(')', 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf('SC_CLK_TCK')


@pytest.mark.parametrize('executor_name', ['wait_set_executor', 'make_executor'])
def test_polled_streams_give_their_newest_message_without_waking_the_executor(executor_name):
    import rclpy

    from grasp_safety_filter.nodes import spin_node
    from grasp_safety_filter.nodes.grasp_markers_node import GraspMarkersNode

    context = rclpy.Context()
    rclpy.init(context=context)
    node = GraspMarkersNode(
        context=context,
        global_arguments=[
            '--ros-args',
            '--params-file',
            str(REPO / 'config' / 'paper_scenario.yaml'),
        ],
    )
    driver = rclpy.create_node('polled_probe', context=context)
    executor = getattr(spin_node, executor_name)(context)
    executor.add_node(node)
    node._timer.cancel()  # the test takes the stream, not the node's drawing
    try:
        polled, _ = node._streams[0]
        spec = topics.topic_spec(topics.JOINT_STATES)
        publisher = driver.create_publisher(
            m.rclpy_message_class(spec.msgtype), topics.JOINT_STATES, spec.qos.to_rclpy()
        )
        deadline = time.monotonic() + 10.0
        while publisher.get_subscription_count() == 0 and time.monotonic() < deadline:
            time.sleep(0.01)
        msgs = m.MessageNamespace.from_rclpy()
        for k in range(1, 6):
            publisher.publish(m.joint_state_to_msg(msgs, k * 1_000_000, ['j'], [0.0], [0.0], None))
            executor.spin_once(timeout_sec=0.02)
        time.sleep(0.2)
        executor.spin_once(timeout_sec=0.02)
        if executor_name == 'wait_set_executor':
            assert polled._kept is None  # the executor never ran its callback
        newest = polled.take_newest()
        assert newest is not None and m.header_stamp_ns(newest) == 5_000_000
        assert polled.take_newest() is None
    finally:
        executor.shutdown()
        node.destroy_node()
        driver.destroy_node()
        rclpy.shutdown(context=context)
