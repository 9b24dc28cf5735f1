"""Message conversion: exact round trips through CDR, and rejection of every kind of bad input."""

from __future__ import annotations

from fractions import Fraction
import math
import warnings

from grasp_states import paper_model, random_configuration
import numpy as np
import pinocchio as pin
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.control.hold_policy import Fallback, HoldPolicy
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io.messages import (
    CONTACT_QUANTITIES,
    ContactData,
    DiagnosticLevel,
    DiagnosticReport,
    MessageError,
    MessageNamespace,
    ObjectReference,
    OutOfOrderError,
    StaleInputError,
    StampGuard,
)

JOINTS = [f'finger{i}_joint{j}' for i in (1, 2, 3) for j in (1, 2, 3)]
CONTACT_NAMES = ['finger1', 'finger2', 'finger3']
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = MessageNamespace.from_typestore(TYPESTORE)
# The rclpy representation (lists of floats, bytes for byte fields) on rosbags classes, which
# accept any field value: checks what the conversion hands to rclpy.
LIST_MSGS = MessageNamespace(
    **{name: getattr(MSGS, name) for name in m.MESSAGE_TYPES},
    sequences_as_lists=True,
    byte_as_bytes=True,
)


def through_cdr(msg):
    """Serialise to CDR and back, as a bag or the ROS middleware does."""
    data = TYPESTORE.serialize_cdr(msg, msg.__msgtype__)
    return TYPESTORE.deserialize_cdr(data, msg.__msgtype__)


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q @ np.diag(np.sign(np.diag(r)))
    return q if np.linalg.det(q) > 0 else -q


def rotation(axis: str, angle: float) -> np.ndarray:
    return pin.rpy.rpyToMatrix(*(angle if a == axis else 0.0 for a in 'xyz'))


def assert_bitwise_equal(a: np.ndarray, b: np.ndarray) -> None:
    a, b = np.asarray(a), np.asarray(b)
    assert a.shape == b.shape
    assert a.tobytes() == b.tobytes()


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(7)


def contact_data(
    rng: np.random.Generator, t: float = 1.25, torsion: bool = False
) -> ContactData:
    """Random contacts; with ``torsion``, a soft finger's torques about the normals too."""
    n = len(CONTACT_NAMES)
    force = rng.normal(size=(n, 3))
    force[:, 2] = np.abs(force[:, 2]) + 0.1
    required = np.hypot(force[:, 0], force[:, 1]) / force[:, 2]
    required[1] = math.inf  # a separating contact
    return ContactData(
        t=t,
        xi_cf=rng.normal(size=(n, 2)),
        xi_co=rng.normal(size=(n, 2)),
        psi=rng.normal(size=n),
        xi_cf_dot=rng.normal(size=(n, 2)),
        xi_co_dot=rng.normal(size=(n, 2)),
        psi_dot=rng.normal(size=n),
        force=force,
        required_friction=required,
        penetration=rng.normal(size=n) * 1e-4,
        torsion=rng.normal(size=n) * 1e-3 if torsion else None,
    )


def reference_points(rng: np.random.Generator, k: int) -> list[ObjectReference]:
    return [
        ObjectReference(
            p_object_in_palm=rng.normal(size=3),
            R_object_to_palm=random_rotation(rng),
            twist_object=rng.normal(size=6),
            acceleration_object=rng.normal(size=6),
        )
        for _ in range(k)
    ]


# ----------------------------------------------------------------------------------------
# Time


def test_time_round_trip_is_exact_for_every_nanosecond_time(rng):
    nanoseconds = [0, 1, 999_999_999, 10**9, 2**23 * 10**9 - 1, *rng.integers(0, 2**52, 500)]
    for ns in nanoseconds:
        t = m.nanoseconds_to_seconds(int(ns))
        msg = through_cdr(m.time_to_msg(MSGS, t))
        assert m.time_msg_to_nanoseconds(msg) == ns
        assert m.time_from_msg(msg) == t
        assert 0 <= msg.nanosec < 10**9


def test_time_rounds_to_the_nearest_nanosecond():
    assert m.seconds_to_nanoseconds(0.1 + 0.2) == 300_000_000
    assert m.seconds_to_nanoseconds(1e-10) == 0


def test_time_rounds_exact_halves_of_a_nanosecond_to_even(rng):
    # k / 1024 s is exactly k * 976562.5 ns: a tie, rounded half to even as round() does.
    assert m.seconds_to_nanoseconds(1 / 1024) == 976_562
    assert m.seconds_to_nanoseconds(3 / 1024) == 2_929_688
    times = [k / 2048 for k in range(1, 4096)] + list(rng.uniform(0.0, 2.0**31 - 1, 2000))
    for t in times:
        assert m.seconds_to_nanoseconds(t) == round(Fraction(t) * 10**9)


@pytest.mark.parametrize('t', [-1e-9, math.nan, math.inf, 2.0**31])
def test_time_outside_builtin_interfaces_is_rejected(t):
    with pytest.raises(MessageError, match='time'):
        m.time_to_msg(MSGS, t)


def test_time_with_nanosec_out_of_range_is_rejected():
    with pytest.raises(MessageError, match='nanosec'):
        m.time_from_msg(MSGS.Time(sec=1, nanosec=10**9))


# ----------------------------------------------------------------------------------------
# Round trips, numpy -> message -> CDR -> message -> numpy


def test_joint_state_round_trip_is_exact(rng):
    q, dq, effort = rng.normal(size=(3, len(JOINTS)))
    msg = through_cdr(m.joint_state_to_msg(MSGS, 0.5, JOINTS, q, dq, effort))
    data = m.joint_state_from_msg(msg, JOINTS)
    assert data.t == 0.5
    for received, sent in ((data.position, q), (data.velocity, dq), (data.effort, effort)):
        assert_bitwise_equal(received, sent)


def test_joint_state_is_matched_by_name_in_any_order(rng):
    q, dq, effort = rng.normal(size=(3, len(JOINTS)))
    order = rng.permutation(len(JOINTS))
    shuffled = [JOINTS[i] for i in order]
    msg = m.joint_state_to_msg(MSGS, 0.5, shuffled, q[order], dq[order], effort[order])
    data = m.joint_state_from_msg(through_cdr(msg), JOINTS)
    assert_bitwise_equal(data.position, q)
    assert_bitwise_equal(data.velocity, dq)
    assert_bitwise_equal(data.effort, effort)


def test_a_name_list_that_matched_once_is_still_checked_when_it_changes(rng):
    effort = rng.normal(size=len(JOINTS))
    good = through_cdr(m.effort_to_msg(MSGS, 2.0, JOINTS, effort))
    for _ in range(2):  # the second time from the memory of matched name lists
        assert_bitwise_equal(m.effort_from_msg(good, JOINTS).effort, effort)
    renamed = through_cdr(m.effort_to_msg(MSGS, 2.0, [*JOINTS[:-1], 'other'], effort))
    duplicated = through_cdr(m.effort_to_msg(MSGS, 2.0, JOINTS, effort))
    duplicated.name = [*JOINTS[:-1], JOINTS[0]]
    for _ in range(2):  # a refused list is refused every time
        with pytest.raises(MessageError, match='unknown joint names'):
            m.effort_from_msg(renamed, JOINTS)
        with pytest.raises(MessageError, match='duplicate joint names'):
            m.effort_from_msg(duplicated, JOINTS)
    with pytest.raises(MessageError, match='missing joint names'):
        m.effort_from_msg(good, [*JOINTS, 'extra'])


def test_names_that_equal_the_last_matched_but_spell_differently_are_refused():
    # Names are matched by their text: 1 and 1.0 are equal objects, not equal names.
    expected = ('1', '2')
    for last in ([1, 2], ['1', '2']):
        assert list(m.match_names('test', last, expected, 'joint')) == [0, 1]
        with pytest.raises(MessageError, match='unknown joint names'):
            m.match_names('test', [1.0, 2.0], expected, 'joint')
    assert list(m.match_names('test', ['2', '1'], expected, 'joint')) == [1, 0]


def test_effort_round_trip_is_exact_and_carries_effort_only(rng):
    effort = rng.normal(size=len(JOINTS))
    msg = through_cdr(m.effort_to_msg(MSGS, 2.0, JOINTS, effort))
    assert len(msg.position) == 0
    assert len(msg.velocity) == 0
    data = m.effort_from_msg(msg, list(reversed(JOINTS)))
    assert data.t == 2.0
    assert_bitwise_equal(data.effort, effort[::-1])


@pytest.mark.parametrize(
    'R',
    [
        np.eye(3),
        rotation('x', math.pi),
        rotation('y', math.pi),
        rotation('z', math.pi),
        rotation('z', math.pi / 2),
        rotation('x', -3.0),
        *(random_rotation(np.random.default_rng(seed)) for seed in range(8)),
    ],
)
def test_quaternion_matches_pinocchio_and_converts_back(R):
    quaternion = m.quaternion_xyzw_from_matrix(R)
    expected = pin.Quaternion(R).coeffs()  # (x, y, z, w), an independent implementation
    sign = 1.0 if np.dot(quaternion, expected) >= 0 else -1.0
    np.testing.assert_allclose(quaternion, sign * expected, atol=1e-15)
    assert quaternion[3] >= 0.0
    np.testing.assert_allclose(m.matrix_from_quaternion_xyzw(quaternion), R, atol=1e-15)


def test_quaternion_of_a_non_rotation_is_rejected():
    with pytest.raises(MessageError, match='rotation matrix'):
        m.quaternion_xyzw_from_matrix(np.diag([1.0, 1.0, -1.0]))


def test_odometry_round_trip(rng):
    p = rng.normal(size=3)
    R = random_rotation(rng)
    twist = rng.normal(size=6)
    msg = m.odometry_to_msg(MSGS, 3.0, p, R, twist)
    received = through_cdr(msg)
    # The message itself survives CDR bit for bit.
    for field in ('x', 'y', 'z', 'w'):
        assert getattr(received.pose.pose.orientation, field) == getattr(
            msg.pose.pose.orientation, field
        )
    data = m.odometry_from_msg(received)
    assert data.t == 3.0
    assert_bitwise_equal(data.p_object_in_palm, p)
    # Rotations and the frame change of the twist cost a few ulp, no more.
    np.testing.assert_allclose(data.R_object_to_palm, R, rtol=0, atol=1e-15)
    np.testing.assert_allclose(data.twist_object, twist, rtol=0, atol=1e-14)
    assert received.header.frame_id == 'palm'
    assert received.child_frame_id == 'object'
    assert not np.any(received.pose.covariance)
    assert not np.any(received.twist.covariance)


def test_odometry_twist_is_expressed_in_the_object_frame():
    # Object turned +90 deg about palm z: palm x is object -y, palm z is object z.
    R = rotation('z', math.pi / 2)
    twist_in_palm = np.array([1.0, 0.0, 0.0, 0.0, 0.0, 2.0])
    msg = m.odometry_to_msg(MSGS, 0.0, np.zeros(3), R, twist_in_palm)
    linear, angular = msg.twist.twist.linear, msg.twist.twist.angular
    np.testing.assert_allclose([linear.x, linear.y, linear.z], [0.0, -1.0, 0.0], atol=1e-15)
    np.testing.assert_allclose([angular.x, angular.y, angular.z], [0.0, 0.0, 2.0], atol=1e-15)
    orientation = msg.pose.pose.orientation
    half = math.sqrt(0.5)
    np.testing.assert_allclose(
        [orientation.x, orientation.y, orientation.z, orientation.w], [0, 0, half, half]
    )


def test_contacts_round_trip_is_exact(rng):
    data = contact_data(rng)
    received = m.contacts_from_msg(
        through_cdr(m.contacts_to_msg(MSGS, data, CONTACT_NAMES)), CONTACT_NAMES
    )
    assert received.t == data.t
    for name in (
        'xi_cf',
        'xi_co',
        'psi',
        'xi_cf_dot',
        'xi_co_dot',
        'psi_dot',
        'force',
        'required_friction',
        'penetration',
    ):
        assert_bitwise_equal(getattr(received, name), getattr(data, name))


def test_contacts_layout_is_the_documented_one(rng):
    data = contact_data(rng)
    msg = m.contacts_to_msg(MSGS, data, CONTACT_NAMES)
    assert len(msg.name) == len(CONTACT_NAMES) * len(CONTACT_QUANTITIES)
    assert list(msg.name[:10]) == [
        'finger1/a',
        'finger1/b',
        'finger1/u',
        'finger1/v',
        'finger1/psi',
        'finger1/force_x',
        'finger1/force_y',
        'finger1/force_normal',
        'finger1/required_friction',
        'finger1/penetration',
    ]
    entry = {name: i for i, name in enumerate(msg.name)}
    assert msg.position[entry['finger2/force_normal']] == data.force[1, 2]
    assert msg.position[entry['finger3/v']] == data.xi_co[2, 1]
    assert msg.velocity[entry['finger3/v']] == data.xi_co_dot[2, 1]
    assert msg.velocity[entry['finger1/psi']] == data.psi_dot[0]
    assert msg.position[entry['finger2/required_friction']] == math.inf
    for contact in CONTACT_NAMES:
        for quantity in CONTACT_QUANTITIES[5:]:
            assert msg.velocity[entry[f'{contact}/{quantity}']] == 0.0
    assert len(msg.effort) == 0


def test_contacts_are_matched_by_name_in_any_order(rng):
    data = contact_data(rng)
    msg = m.contacts_to_msg(MSGS, data, CONTACT_NAMES)
    order = rng.permutation(len(msg.name))
    msg.name = [msg.name[i] for i in order]
    msg.position = msg.position[order]
    msg.velocity = msg.velocity[order]
    received = m.contacts_from_msg(msg, CONTACT_NAMES)
    assert_bitwise_equal(received.force, data.force)
    assert_bitwise_equal(received.xi_cf_dot, data.xi_cf_dot)


def test_contacts_from_a_grasp_state_carry_its_coordinates_and_friction():
    model = paper_model()
    state = random_configuration(model, np.random.default_rng(3)).state(model, 0.75)
    force = np.tile([0.3, -0.4, 1.0], state.n_contacts)
    data = ContactData.from_grasp_state(state, force)
    received = m.contacts_from_msg(
        through_cdr(m.contacts_to_msg(MSGS, data, CONTACT_NAMES)), CONTACT_NAMES
    )
    assert received.t == 0.75
    assert_bitwise_equal(received.xi_cf, state.xi_cf)
    assert_bitwise_equal(received.psi_dot, state.psi_dot)
    assert_bitwise_equal(received.penetration, state.penetration)
    np.testing.assert_allclose(received.required_friction, 0.5)  # |(0.3, -0.4)| / 1


def test_reference_round_trip(rng):
    points = reference_points(rng, 3)
    times = [0.0, 0.25, 1.5]
    msg = through_cdr(m.reference_to_msg(MSGS, 10.0, times, points))
    assert list(msg.joint_names) == ['object']
    trajectory = m.reference_from_msg(msg)
    assert trajectory.t == 10.0
    assert trajectory.time_from_start.tolist() == times
    for received, sent in zip(trajectory.points, points, strict=True):
        assert_bitwise_equal(received.p_object_in_palm, sent.p_object_in_palm)
        assert_bitwise_equal(received.twist_object, sent.twist_object)
        assert_bitwise_equal(received.acceleration_object, sent.acceleration_object)
        np.testing.assert_allclose(
            received.R_object_to_palm, sent.R_object_to_palm, rtol=0, atol=1e-15
        )


@pytest.mark.parametrize(
    ('t', 'index'),
    [(9.0, 0), (10.0, 0), (10.2, 0), (10.25, 1), (11.0, 1), (11.5, 2), (100.0, 2)],
)
def test_reference_sample_holds_the_last_point_reached(rng, t, index):
    points = reference_points(rng, 3)
    trajectory = m.reference_from_msg(m.reference_to_msg(MSGS, 10.0, [0.0, 0.25, 1.5], points))
    sample = trajectory.sample(t)
    assert_bitwise_equal(sample.twist_object, points[index].twist_object)


def test_reference_without_velocities_and_accelerations_means_zero(rng):
    msg = m.reference_to_msg(MSGS, 0.0, [0.0], reference_points(rng, 1))
    msg.points[0].velocities = []
    msg.points[0].accelerations = []
    point = m.reference_from_msg(through_cdr(msg)).points[0]
    assert not point.twist_object.any()
    assert not point.acceleration_object.any()


def test_margins_round_trip_with_undefined_rates_sent_as_zero(rng):
    names = ['joint_limit/finger1_joint1/lower', 'no_slip/finger2/face0', 'actuator/u_max/3']
    h = rng.normal(size=3)
    h_dot = np.array([0.5, math.nan, -2.0])
    msg = through_cdr(m.margins_to_msg(MSGS, 4.0, names, h, h_dot))
    data = m.margins_from_msg(msg)
    assert data.names == tuple(names)
    assert_bitwise_equal(data.h, h)
    assert data.h_dot.tolist() == [0.5, 0.0, -2.0]
    reordered = m.margins_from_msg(msg, names=names[::-1])
    assert_bitwise_equal(reordered.h, h[::-1])


def test_diagnostics_round_trip_restores_values_exactly():
    values = {'qp.status': 'solved', 'qp.solve_time': 1.0 / 3.0, 'qp.iterations': 25, 'ok': True}
    reports = [
        DiagnosticReport.create('safety_filter', DiagnosticLevel.WARN, 'holding', values),
        DiagnosticReport.create('hand_sim', 0, 'lockstep ok'),
    ]
    data = m.diagnostics_from_msg(through_cdr(m.diagnostics_to_msg(MSGS, 5.0, reports)))
    assert data.t == 5.0
    assert data.reports == tuple(reports)
    report = data.report('safety_filter')
    assert report.level is DiagnosticLevel.WARN
    assert float(report.values['qp.solve_time']) == 1.0 / 3.0
    assert report.values['ok'] == 'true'
    with pytest.raises(KeyError, match='safety_filter'):
        data.report('missing')


def test_clock_round_trip_is_exact():
    assert m.clock_from_msg(through_cdr(m.clock_to_msg(MSGS, 12.345678901))) == 12.345678901


def test_rclpy_representation_uses_lists_of_floats_and_bytes(rng):
    q, dq, effort = rng.normal(size=(3, len(JOINTS)))
    msg = m.joint_state_to_msg(LIST_MSGS, 0.5, JOINTS, q, dq, effort)
    for values in (msg.position, msg.velocity, msg.effort):
        assert type(values) is list
        assert all(type(v) is float for v in values)
    assert_bitwise_equal(m.joint_state_from_msg(msg, JOINTS).velocity, dq)
    odometry = m.odometry_to_msg(LIST_MSGS, 0.0, np.zeros(3), np.eye(3), np.zeros(6))
    assert type(odometry.pose.covariance) is list
    assert len(odometry.pose.covariance) == 36
    contacts = m.contacts_to_msg(LIST_MSGS, contact_data(rng), CONTACT_NAMES)
    assert type(contacts.position) is list
    diagnostics = m.diagnostics_to_msg(
        LIST_MSGS, 0.0, DiagnosticReport.create('safety_filter', DiagnosticLevel.ERROR, 'x')
    )
    assert diagnostics.status[0].level == b'\x02'
    assert m.diagnostics_from_msg(diagnostics).reports[0].level is DiagnosticLevel.ERROR


# ----------------------------------------------------------------------------------------
# Bad input


def joint_state_msg(rng: np.random.Generator):
    q, dq, effort = rng.normal(size=(3, len(JOINTS)))
    return m.joint_state_to_msg(MSGS, 0.5, JOINTS, q, dq, effort)


def set_value(field: str, index: int, value: float):
    def mutate(msg):
        values = np.array(getattr(msg, field))
        values[index] = value
        setattr(msg, field, values)

    return mutate


def truncate(field: str):
    def mutate(msg):
        setattr(msg, field, np.array(getattr(msg, field))[:-1])

    return mutate


def rename(index: int, name: str):
    def mutate(msg):
        msg.name = [name if i == index else n for i, n in enumerate(msg.name)]

    return mutate


def drop_entry(index: int):
    def mutate(msg):
        keep = [i for i in range(len(msg.name)) if i != index]
        msg.name = [msg.name[i] for i in keep]
        for field in ('position', 'velocity', 'effort'):
            values = np.array(getattr(msg, field))
            if values.size:
                setattr(msg, field, values[keep])

    return mutate


def add_entry(name: str):
    def mutate(msg):
        msg.name = [*msg.name, name]
        for field in ('position', 'velocity', 'effort'):
            values = np.array(getattr(msg, field))
            if values.size:
                setattr(msg, field, np.append(values, 0.0))

    return mutate


JOINT_STATE_DEFECTS = [
    ('nan position', set_value('position', 5, math.nan), ['position', 'finger2_joint3', 'nan']),
    ('inf velocity', set_value('velocity', 0, math.inf), ['velocity', 'finger1_joint1', 'inf']),
    ('-inf effort', set_value('effort', 8, -math.inf), ['effort', 'finger3_joint3', '-inf']),
    ('short position', truncate('position'), ['position', '8 entries', '9']),
    ('short velocity', truncate('velocity'), ['velocity', '8 entries', '9']),
    ('short effort', truncate('effort'), ['effort', '8 entries', '9']),
    ('unknown name', rename(4, 'finger9_joint1'), ['unknown', 'finger9_joint1']),
    ('missing name', drop_entry(2), ['missing', 'finger1_joint3']),
    ('duplicate name', rename(1, 'finger1_joint1'), ['duplicate', 'finger1_joint1']),
    ('extra name', add_entry('wrist_joint'), ['unknown', 'wrist_joint']),
]


@pytest.mark.parametrize(
    ('mutate', 'expected'),
    [d[1:] for d in JOINT_STATE_DEFECTS],
    ids=[d[0] for d in JOINT_STATE_DEFECTS],
)
def test_bad_joint_state_is_rejected_with_a_message_naming_the_problem(rng, mutate, expected):
    msg = joint_state_msg(rng)
    mutate(msg)
    with pytest.raises(MessageError) as error:
        m.joint_state_from_msg(msg, JOINTS, source='/hand/joint_states')
    assert '/hand/joint_states' in str(error.value)
    for fragment in expected:
        assert fragment in str(error.value)


EFFORT_DEFECTS = [
    ('nan effort', set_value('effort', 3, math.nan), ['effort', 'finger2_joint1', 'nan']),
    ('short effort', truncate('effort'), ['effort', '8 entries']),
    ('missing name', drop_entry(8), ['missing', 'finger3_joint3']),
    ('unknown name', rename(0, 'thumb'), ['unknown', 'thumb']),
    ('duplicate name', rename(8, 'finger3_joint2'), ['duplicate', 'finger3_joint2']),
]


@pytest.mark.parametrize(
    ('mutate', 'expected'), [d[1:] for d in EFFORT_DEFECTS], ids=[d[0] for d in EFFORT_DEFECTS]
)
def test_bad_effort_is_rejected(rng, mutate, expected):
    msg = m.effort_to_msg(MSGS, 0.0, JOINTS, rng.normal(size=len(JOINTS)))
    mutate(msg)
    with pytest.raises(MessageError) as error:
        m.effort_from_msg(msg, JOINTS, source='/hand/effort_nominal')
    for fragment in ['/hand/effort_nominal', *expected]:
        assert fragment in str(error.value)


def test_effort_with_a_position_of_the_wrong_length_is_rejected(rng):
    msg = m.effort_to_msg(MSGS, 0.0, JOINTS, rng.normal(size=len(JOINTS)))
    msg.position = np.zeros(3)
    with pytest.raises(MessageError, match="'position' has 3 entries"):
        m.effort_from_msg(msg, JOINTS)


def odometry_msg():
    return m.odometry_to_msg(
        MSGS, 0.0, np.array([0.0, 0.0, 0.3]), rotation('z', 0.3), np.arange(6.0)
    )


def scale_quaternion(factor: float):
    def mutate(msg):
        o = msg.pose.pose.orientation
        o.x, o.y, o.z, o.w = (factor * v for v in (o.x, o.y, o.z, o.w))

    return mutate


ODOMETRY_DEFECTS = [
    (
        'nan position',
        lambda msg: setattr(msg.pose.pose.position, 'y', math.nan),
        ['pose.position', 'nan'],
    ),
    (
        'inf angular velocity',
        lambda msg: setattr(msg.twist.twist.angular, 'z', math.inf),
        ['twist', 'inf'],
    ),
    (
        'nan quaternion',
        lambda msg: setattr(msg.pose.pose.orientation, 'w', math.nan),
        ['pose.orientation', 'finite'],
    ),
    ('non-unit quaternion', scale_quaternion(1.0 + 1e-5), ['unit quaternion', 'norm']),
    ('zero quaternion', scale_quaternion(0.0), ['unit quaternion']),
    (
        'wrong frame',
        lambda msg: setattr(msg.header, 'frame_id', 'world'),
        ['header.frame_id', "'palm'", "'world'"],
    ),
    (
        'wrong child frame',
        lambda msg: setattr(msg, 'child_frame_id', ''),
        ['child_frame_id', "'object'"],
    ),
]


@pytest.mark.parametrize(
    ('mutate', 'expected'),
    [d[1:] for d in ODOMETRY_DEFECTS],
    ids=[d[0] for d in ODOMETRY_DEFECTS],
)
def test_bad_odometry_is_rejected(mutate, expected):
    msg = odometry_msg()
    mutate(msg)
    with pytest.raises(MessageError) as error:
        m.odometry_from_msg(msg, source='/object/odom')
    for fragment in ['/object/odom', *expected]:
        assert fragment in str(error.value)


def test_odometry_quaternion_within_tolerance_is_accepted_and_normalised():
    msg = odometry_msg()
    scale_quaternion(1.0 + 5e-7)(msg)
    R = m.odometry_from_msg(msg).R_object_to_palm
    np.testing.assert_allclose(R.T @ R, np.eye(3), atol=1e-15)


CONTACT_DEFECTS = [
    ('nan value', set_value('position', 0, math.nan), ['finger1/a', 'nan']),
    ('inf rate', set_value('velocity', 14, math.inf), ['velocity', 'finger2/psi', 'inf']),
    ('inf force', set_value('position', 7, math.inf), ['finger1/force_normal', 'inf']),
    ('-inf friction', set_value('position', 8, -math.inf), ['finger1/required_friction']),
    ('nan friction', set_value('position', 18, math.nan), ['finger2/required_friction', 'nan']),
    ('short position', truncate('position'), ['position', '29 entries', '30']),
    ('short velocity', truncate('velocity'), ['velocity', '29 entries']),
    ('missing entry', drop_entry(29), ['missing', 'finger3/penetration']),
    ('unknown entry', rename(3, 'finger1/w'), ['unknown', 'finger1/w']),
    ('unknown contact', add_entry('finger4/a'), ['unknown', 'finger4/a']),
    ('duplicate entry', rename(1, 'finger1/a'), ['duplicate', 'finger1/a']),
]


@pytest.mark.parametrize(
    ('mutate', 'expected'),
    [d[1:] for d in CONTACT_DEFECTS],
    ids=[d[0] for d in CONTACT_DEFECTS],
)
def test_bad_contacts_are_rejected(rng, mutate, expected):
    msg = m.contacts_to_msg(MSGS, contact_data(rng), CONTACT_NAMES)
    mutate(msg)
    with pytest.raises(MessageError) as error:
        m.contacts_from_msg(msg, CONTACT_NAMES, source='/hand/contacts')
    for fragment in ['/hand/contacts', *expected]:
        assert fragment in str(error.value)


def reference_msg(rng: np.random.Generator):
    return m.reference_to_msg(MSGS, 1.0, [0.0, 0.5, 1.0], reference_points(rng, 3))


def set_attr(path: str, value):
    def mutate(msg):
        *parents, last = path.split('.')
        target = msg
        for parent in parents:
            target = target[int(parent)] if parent.isdigit() else getattr(target, parent)
        setattr(target, last, value)

    return mutate


REFERENCE_DEFECTS = [
    ('wrong frame', set_attr('header.frame_id', 'base'), ['header.frame_id', "'palm'"]),
    ('unknown joint', set_attr('joint_names', ['box']), ['unknown', 'box']),
    ('duplicate joint', set_attr('joint_names', ['object', 'object']), ['duplicate', 'object']),
    ('no points', set_attr('points', []), ['at least one point']),
    (
        'nan translation',
        set_attr('points.1.transforms.0.translation.x', math.nan),
        ['point 1', 'translation', 'nan'],
    ),
    (
        'non-unit rotation',
        set_attr('points.2.transforms.0.rotation.w', 3.0),
        ['point 2', 'rotation', 'unit quaternion'],
    ),
    (
        'rotation of 1e308',
        set_attr('points.2.transforms.0.rotation.w', 1e308),
        ['point 2', 'rotation', 'unit quaternion', 'norm 1e+308'],
    ),
    (
        'inf velocity',
        set_attr('points.0.velocities.0.linear.z', math.inf),
        ['point 0', 'velocity', 'inf'],
    ),
    (
        'nan acceleration',
        set_attr('points.0.accelerations.0.angular.x', math.nan),
        ['point 0', 'acceleration', 'nan'],
    ),
    ('two transforms', set_attr('points.1.transforms', []), ['point 1', "'transforms'"]),
    (
        'non-increasing time',
        set_attr('points.2.time_from_start', MSGS.Duration(sec=0, nanosec=500_000_000)),
        ['point 2', 'strictly increasing', '0.5'],
    ),
    (
        'negative time',
        set_attr('points.0.time_from_start', MSGS.Duration(sec=-1, nanosec=0)),
        ['point 0', '>= 0'],
    ),
]


@pytest.mark.parametrize(
    ('mutate', 'expected'),
    [d[1:] for d in REFERENCE_DEFECTS],
    ids=[d[0] for d in REFERENCE_DEFECTS],
)
def test_bad_reference_is_rejected(rng, mutate, expected):
    msg = reference_msg(rng)
    mutate(msg)
    with warnings.catch_warnings():
        warnings.simplefilter('error')  # refused with a message, not a numpy warning
        with pytest.raises(MessageError) as error:
            m.reference_from_msg(msg, source='/object/reference')
    for fragment in ['/object/reference', *expected]:
        assert fragment in str(error.value)


def test_reference_velocity_list_of_the_wrong_length_is_rejected(rng):
    msg = reference_msg(rng)
    msg.points[1].velocities = msg.points[1].velocities * 2
    with pytest.raises(MessageError, match="point 1: 'velocities' has 2 entries"):
        m.reference_from_msg(msg)


def test_bad_margins_are_rejected():
    msg = m.margins_to_msg(MSGS, 0.0, ['a', 'b'], np.array([1.0, math.nan]))
    with pytest.raises(MessageError, match="'position' of 'b' is nan"):
        m.margins_from_msg(msg)
    msg = m.margins_to_msg(MSGS, 0.0, ['a', 'b'], np.array([1.0, 2.0]))
    with pytest.raises(MessageError, match='missing'):
        m.margins_from_msg(msg, names=['a', 'b', 'c'])


def test_diagnostic_level_out_of_range_is_rejected():
    msg = m.diagnostics_to_msg(MSGS, 0.0, DiagnosticReport.create('safety_filter', 0, ''))
    msg.status[0].level = 7
    with pytest.raises(MessageError, match=r"'safety_filter' level must be 0\.\.3, got 7"):
        m.diagnostics_from_msg(msg)


@pytest.mark.parametrize(
    ('build', 'match'),
    [
        (lambda: m.joint_state_to_msg(MSGS, 0.0, JOINTS, np.zeros(8), None, None), 'position'),
        (lambda: m.effort_to_msg(MSGS, 0.0, ['a', 'a'], np.zeros(2)), 'duplicate'),
        (
            lambda: m.odometry_to_msg(MSGS, 0.0, np.zeros(2), np.eye(3), np.zeros(6)),
            'p_object_in_palm',
        ),
        (lambda: m.reference_to_msg(MSGS, 0.0, [0.0, 1.0], []), 'one time_from_start per point'),
    ],
)
def test_building_from_arrays_of_the_wrong_shape_is_refused(build, match):
    with pytest.raises(MessageError, match=match):
        build()


# ----------------------------------------------------------------------------------------
# Stamps


def test_stamp_guard_rejects_stale_stamps_naming_topic_and_stamps():
    guard = StampGuard(max_age=0.05)
    guard.accept('/hand/joint_states', 0.95, now=1.0)
    with pytest.raises(StaleInputError) as error:
        guard.accept('/object/odom', 0.9, now=1.0)
    text = str(error.value)
    assert '/object/odom' in text
    assert '0.900000000' in text
    assert '1.000000000' in text
    assert 'max_age 0.05' in text
    assert guard.last_stamp('/object/odom') is None


def test_stamp_guard_rejects_out_of_order_stamps_per_topic():
    guard = StampGuard(max_age=1.0)
    guard.accept('/hand/joint_states', 2.0, now=2.0)
    guard.accept('/hand/joint_states', 2.0, now=2.0)  # a repeated stamp is not a reordering
    guard.accept('/object/odom', 1.5, now=2.0)  # other topics keep their own order
    with pytest.raises(OutOfOrderError) as error:
        guard.accept('/hand/joint_states', 1.999, now=2.0)
    assert '/hand/joint_states' in str(error.value)
    assert '1.999000000' in str(error.value)
    assert '2.000000000' in str(error.value)
    assert guard.last_stamp('/hand/joint_states') == 2.0
    guard.reset()
    guard.accept('/hand/joint_states', 1.999, now=2.0)


@pytest.mark.parametrize('max_age', [0.0, -1.0, math.nan, math.inf])
def test_stamp_guard_needs_a_positive_max_age(max_age):
    with pytest.raises(ValueError, match='max_age'):
        StampGuard(max_age)


def test_stamp_guard_rejects_non_finite_stamps():
    with pytest.raises(MessageError, match='finite'):
        StampGuard(0.1).accept('/clock', math.nan, now=0.0)


# ----------------------------------------------------------------------------------------
# No command from bad input


def filter_tick(policy, guard, msg, now, gravity_torque):
    """Run the input path of a filter tick: parse, check stamps, then compute or hold."""
    try:
        state = m.joint_state_from_msg(msg, JOINTS, source='/hand/joint_states')
        guard.accept('/hand/joint_states', state.t, now)
    except MessageError as error:
        return policy.reject(now, str(error), gravity_torque)
    # Stand-in for the QP: a command that depends on every input value.
    return policy.accept(now, -2.0 * state.position - state.velocity)


@pytest.mark.parametrize(
    'mutate',
    [
        set_value('position', 5, math.nan),
        truncate('velocity'),
        rename(4, 'finger9_joint1'),
        drop_entry(2),
        rename(1, 'finger1_joint1'),
        set_attr('header.stamp', MSGS.Time(sec=0, nanosec=100_000_000)),
    ],
    ids=['nan', 'length', 'unknown', 'missing', 'duplicate', 'stale'],
)
def test_no_command_is_computed_from_bad_input(rng, mutate):
    policy = HoldPolicy(len(JOINTS), hold_timeout=0.1, fallback=Fallback.ZERO)
    guard = StampGuard(max_age=0.05)
    gravity = rng.normal(size=len(JOINTS))
    good = m.joint_state_to_msg(MSGS, 0.5, JOINTS, *rng.normal(size=(3, len(JOINTS))))
    safe = filter_tick(policy, guard, good, 0.5, gravity)
    bad = m.joint_state_to_msg(MSGS, 0.51, JOINTS, *rng.normal(size=(3, len(JOINTS))))
    mutate(bad)
    command = filter_tick(policy, guard, bad, 0.51, gravity)
    assert_bitwise_equal(command, safe)
    assert policy.mode.value == 'holding'
    assert '/hand/joint_states' in policy.last_reason


def test_joint_state_without_effort_is_accepted_as_hand_drivers_publish_it():
    rng = np.random.default_rng(4)
    q, dq = rng.normal(size=9), rng.normal(size=9)
    msg = m.joint_state_to_msg(MSGS, 0.5, JOINTS[::-1], q[::-1], dq[::-1], np.zeros(9))
    msg.effort = np.array([], dtype=np.float64)
    parsed = m.joint_state_from_msg(msg, JOINTS)
    np.testing.assert_array_equal(parsed.position, q)
    np.testing.assert_array_equal(parsed.velocity, dq)
    assert parsed.effort is None
    msg.effort = np.zeros(4)  # present but of the wrong length is still an error
    with pytest.raises(m.MessageError, match="'effort' has 4 entries"):
        m.joint_state_from_msg(msg, JOINTS)


@pytest.mark.parametrize(
    ('stamp', 'now', 'error'),
    [
        (1.05, 1.0, None),  # at the bound
        (1.0500001, 1.0, m.FutureStampError),
        (2.0, 1.0, m.FutureStampError),
        (2.0**31 - 1, 1.0, m.FutureStampError),
        (0.95, 1.0, None),
        (0.9499999, 1.0, m.StaleInputError),
    ],
)
def test_stamp_guard_rejects_stamps_ahead_of_the_clock(stamp, now, error):
    guard = StampGuard(max_age=0.05)
    if error is None:
        guard.accept('/x', stamp, now=now)
        assert guard.last_stamp('/x') == stamp
    else:
        with pytest.raises(error):
            guard.accept('/x', stamp, now=now)
        assert guard.last_stamp('/x') is None


def test_stamp_guard_forgets_a_reference_that_is_in_the_future_of_the_clock():
    guard = StampGuard(max_age=0.05)
    guard.accept('/x', 100.0, now=100.0)  # ``now`` was the stamp itself, no clock
    guard.accept('/x', 0.001, now=0.0)
    assert guard.last_stamp('/x') == 0.001
    with pytest.raises(m.OutOfOrderError):
        guard.accept('/x', 0.0, now=0.0)
