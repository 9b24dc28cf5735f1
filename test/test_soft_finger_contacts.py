"""Soft fingers' torsions: published on ``/hand/contacts``, judged as slip live and from a bag."""

from __future__ import annotations

import math

from grasp_states import CONFIG_DIR, P_OBJECT_PAPER, paper_model, Q_PAPER
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores
from test_fast_analysis import assert_same_run, edited_copy, parsed_load
from test_messages import contact_data as random_contact_data

from grasp_safety_filter.analysis.figures import plot_friction, torsion_in_friction_units
from grasp_safety_filter.analysis.run_data import load_run, RunDataError
from grasp_safety_filter.io import messages as m
from grasp_safety_filter.io.messages import (
    CONTACT_QUANTITIES,
    contact_quantities,
    ContactData,
    MessageError,
    MessageNamespace,
)
from grasp_safety_filter.runner import analyze_bag, run, RunOptions
from hand_sim_node.constraint_margins import SLIP
from hand_sim_node.events import EventMonitor

CONTACT_NAMES = ['finger1', 'finger2', 'finger3']
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
MSGS = MessageNamespace.from_typestore(TYPESTORE)
MU, MU_T = 0.9, 0.005
#: Rigid no-spin rows: at the paper's grasp the fingers can hardly twist, so the nominal
#: law's torsions break their bound from the first steps while its forces stay in the cone.
SOFT = {'model.torsional_friction': MU_T, 'model.torsional_compliance': 0.0}


def through_cdr(msg):
    """Serialise to CDR and back, as a bag or the ROS middleware does."""
    data = TYPESTORE.serialize_cdr(msg, msg.__msgtype__)
    return TYPESTORE.deserialize_cdr(data, msg.__msgtype__)


def contact_data(torsion: bool, seed: int = 11) -> ContactData:
    return random_contact_data(np.random.default_rng(seed), 2.5, torsion)


# ----------------------------------------------------------------------------------------
# /hand/contacts in both layouts


@pytest.mark.parametrize('torsion', [False, True], ids=['point', 'soft'])
def test_contacts_round_trip_through_cdr_in_both_layouts(torsion):
    data = contact_data(torsion)
    msg = m.contacts_to_msg(MSGS, data, CONTACT_NAMES)
    quantities = contact_quantities(torsion)
    assert list(msg.name) == [f'{c}/{q}' for c in CONTACT_NAMES for q in quantities]
    assert quantities[:10] == CONTACT_QUANTITIES
    received = m.contacts_from_msg(through_cdr(msg), CONTACT_NAMES)
    for name in ContactData.__dataclass_fields__:
        sent, got = getattr(data, name), getattr(received, name)
        if sent is None or np.isscalar(sent):
            assert got == sent, name
        else:
            assert np.asarray(got).tobytes() == np.asarray(sent).tobytes(), name
    if torsion:
        entry = {name: i for i, name in enumerate(msg.name)}
        assert msg.position[entry['finger3/torsion']] == data.torsion[2]
        assert all(msg.velocity[entry[f'{c}/torsion']] == 0.0 for c in CONTACT_NAMES)


def test_a_grasp_states_soft_finger_wrench_publishes_its_torsions():
    model = paper_model(**SOFT)
    state = model.state(
        0.0, Q_PAPER, np.zeros(Q_PAPER.size), P_OBJECT_PAPER, np.eye(3), np.zeros(6)
    )
    forces = np.tile([0.3, -0.4, 1.0], 3)
    torsions = np.array([1e-3, -2e-3, 0.0])
    point = ContactData.from_grasp_state(state, forces)
    soft = ContactData.from_grasp_state(state, np.concatenate((forces, torsions)))
    assert point.torsion is None
    np.testing.assert_array_equal(soft.torsion, torsions)
    np.testing.assert_array_equal(soft.force, point.force)
    received = m.contacts_from_msg(m.contacts_to_msg(MSGS, soft, CONTACT_NAMES), CONTACT_NAMES)
    np.testing.assert_array_equal(received.torsion, torsions)


def drop(*names: str):
    def mutate(msg):
        keep = [i for i, name in enumerate(msg.name) if name not in names]
        msg.name = [msg.name[i] for i in keep]
        msg.position, msg.velocity = msg.position[keep], msg.velocity[keep]

    return mutate


def add(name: str, value: float = 0.0):
    def mutate(msg):
        msg.name = [*msg.name, name]
        msg.position = np.append(msg.position, value)
        msg.velocity = np.append(msg.velocity, 0.0)

    return mutate


def rename(old: str, new: str):
    def mutate(msg):
        msg.name = [new if name == old else name for name in msg.name]

    return mutate


def set_torsion(value: float):
    def mutate(msg):
        msg.position[list(msg.name).index('finger2/torsion')] = value

    return mutate


#: (id, soft-finger message, mutation, required layout, fragments of the error).
CONTACT_DEFECTS = [
    ('torsion of some contacts only', False, add('finger2/torsion'), None,
     ['missing', 'finger1/torsion', 'finger3/torsion']),
    ('one torsion missing', True, drop('finger3/torsion'), None, ['missing', 'finger3/torsion']),
    ('torsion of an unknown contact', True, add('finger4/torsion'), None,
     ['unknown', 'finger4/torsion']),
    ('duplicate torsion', True, rename('finger1/torsion', 'finger2/torsion'), None,
     ['duplicate', 'finger2/torsion']),
    ('misspelt torsion', True, rename('finger1/torsion', 'finger1/torque'), None,
     ['unknown', 'finger1/torque']),
    ('nan torsion', True, set_torsion(math.nan), None, ['finger2/torsion', 'nan']),
    ('inf torsion', True, set_torsion(math.inf), None, ['finger2/torsion', 'inf']),
    ('torsions where none are expected', True, None, False, ['unknown', 'finger1/torsion']),
    ('no torsions where they are expected', False, None, True, ['missing', 'finger1/torsion']),
]


@pytest.mark.parametrize(
    ('soft', 'mutate', 'torsion', 'expected'),
    [d[1:] for d in CONTACT_DEFECTS],
    ids=[d[0] for d in CONTACT_DEFECTS],
)
def test_bad_contact_layouts_are_refused_naming_the_problem(soft, mutate, torsion, expected):
    msg = m.contacts_to_msg(MSGS, contact_data(soft), CONTACT_NAMES)
    msg.position, msg.velocity = np.array(msg.position), np.array(msg.velocity)
    if mutate is not None:
        mutate(msg)
    with pytest.raises(MessageError) as error:
        m.contacts_from_msg(msg, CONTACT_NAMES, source='/hand/contacts', torsion=torsion)
    for fragment in ['/hand/contacts', *expected]:
        assert fragment in str(error.value)


# ----------------------------------------------------------------------------------------
# Torsional slip


def slip_margin_of(force: tuple[float, float, float], torsion: float | None) -> float:
    """Return the first contact's slip margin (the others hold firmly) with soft fingers."""
    monitor = EventMonitor(
        [-1.0], [1.0], (-1.0, 1.0, -1.0, 1.0), MU, ['j'], CONTACT_NAMES, torsional_friction=MU_T
    )
    forces = np.array([force, (0.0, 0.0, 1.0), (0.0, 0.0, 1.0)]).ravel()
    wrench = forces if torsion is None else np.concatenate((forces, [torsion, 0.0, 0.0]))
    margins = monitor.margins_at(0.0, [0.0], np.zeros((3, 2)), wrench)
    slipping = [e.index for e in monitor.events(margins) if e.family == SLIP]
    assert slipping == ([0] if margins.friction[0] < 0.0 else [])
    assert list(margins.friction[1:]) == [MU, MU]
    return float(margins.friction[0])


#: (id, force (f_x, f_y, f_n) N, torsion N·m (None: the forces alone), expected margin).
SLIP_CASES = [
    ('no load', (0.0, 0.0, 2.0), 0.0, MU),
    ('force cone alone', (0.6, 0.8, 2.0), 0.0, MU - 0.5),
    ('torsion inside both bounds', (0.0, 0.0, 2.0), 0.5 * MU_T * 2.0, MU - 0.5 * MU),
    ('torsion below force ratio', (0.6, 0.8, 2.0), -0.4 * MU_T * 2.0, MU - 0.5),
    ('torsion above force ratio', (0.6, 0.8, 2.0), -0.8 * MU_T * 2.0, MU - 0.8 * MU),
    ('torsion alone over its bound', (0.0, 0.0, 2.0), 1.25 * MU_T * 2.0, MU - 1.25 * MU),
    ('negative torsion over its bound', (0.1, 0.0, 2.0), -1.1 * MU_T * 2.0, MU - 1.1 * MU),
    ('force over, torsion inside', (1.2, 1.6, 2.0), 0.5 * MU_T * 2.0, MU - 1.0),
    ('torsion at its bound', (0.0, 0.0, 2.0), MU_T * 2.0, 0.0),
    ('torsions not given', (0.0, 0.0, 2.0), None, MU),
    ('separated', (0.0, 0.0, 0.0), 1e-3, -math.inf),
]


@pytest.mark.parametrize(
    ('force', 'torsion', 'expected'),
    [c[1:] for c in SLIP_CASES],
    ids=[c[0] for c in SLIP_CASES],
)
def test_a_soft_fingers_slip_margin_bounds_its_torsion(force, torsion, expected):
    assert slip_margin_of(force, torsion) == pytest.approx(expected, rel=1e-14, abs=1e-15)


def test_point_contacts_ignore_a_wrenchs_torsions_and_keep_their_margin_to_the_bit():
    point = EventMonitor([-1.0], [1.0], (-1.0, 1.0, -1.0, 1.0), MU, ['j'], CONTACT_NAMES)
    forces = np.random.default_rng(5).normal(size=(3, 3))
    forces[:, 2] = np.abs(forces[:, 2])
    wrench = np.concatenate((forces.ravel(), [1.0, -1.0, 1.0]))
    margins = point.margins_at(0.0, [0.0], np.zeros((3, 2)), wrench)
    beta = np.hypot(forces[:, 0], forces[:, 1]) / forces[:, 2]
    assert margins.friction.tobytes() == (MU - beta).tobytes()
    assert point.margins_at(0.0, [0.0], np.zeros((3, 2)), forces.ravel()).values.tobytes() == (
        margins.values.tobytes()
    )


def test_a_soft_finger_model_gives_its_monitor_the_torsional_friction():
    assert EventMonitor.from_model(paper_model()).torsional_friction is None
    monitor = EventMonitor.from_model(paper_model(**SOFT))
    np.testing.assert_array_equal(monitor.torsional_friction, [MU_T] * 3)
    with pytest.raises(ValueError, match='torsional_friction > 0'):
        EventMonitor([-1.0], [1.0], (-1.0, 1.0, -1.0, 1.0), MU, ['j'], ['c'], None, 0.0)


# ----------------------------------------------------------------------------------------
# A soft-finger run and its bag

CONFIG = CONFIG_DIR / 'paper_scenario.yaml'


@pytest.fixture(scope='module')
def soft_nominal_run(tmp_path_factory):
    """Run the start of the paper's nominal run with rigid soft fingers.

    Its torsions slip from the first steps and its forces stay inside the cone until about
    0.78 s, so a verdict blind to the torsions differs.
    """
    options = RunOptions(CONFIG, 'nominal', duration=0.15, overrides=SOFT)
    return run(options, tmp_path_factory.mktemp('soft'))


def test_the_analysis_of_a_soft_finger_bag_gives_the_live_verdict(soft_nominal_run, tmp_path):
    result = soft_nominal_run
    live = result.recording.live_log
    summary, _ = analyze_bag(result.bag, tmp_path)
    assert summary['violations'] == live.violations()
    assert summary['violations'][SLIP]['count'] > 0  # the torsions slip, the forces do not
    for family, margin in live.min_margin().items():
        assert summary['min_margin'][family] == (margin if np.isfinite(margin) else None)
    assert summary['max_required_friction'] < MU  # the force cone alone holds


def test_a_soft_finger_bag_is_read_packed_as_parsed(soft_nominal_run):
    fast = load_run(soft_nominal_run.bag)
    assert fast.torsion is not None and fast.torsion.shape == (len(fast.t), 3)
    np.testing.assert_array_equal(fast.torsional_friction_per_contact, [MU_T] * 3)
    assert_same_run(fast, parsed_load(soft_nominal_run.bag))


def test_a_soft_finger_bag_without_torsions_is_refused(soft_nominal_run, tmp_path):
    def drop_torsions(index, msg):
        keep = [i for i, name in enumerate(msg.name) if not name.endswith('/torsion')]
        msg.name = [msg.name[i] for i in keep]
        msg.position, msg.velocity = msg.position[keep], msg.velocity[keep]

    edited_copy(soft_nominal_run.bag, tmp_path / 'no_torsion', drop_torsions)
    with pytest.raises(RunDataError, match=r'/hand/contacts: missing .*finger1/torsion'):
        load_run(tmp_path / 'no_torsion')


def test_the_friction_figure_draws_the_torsions_the_verdict_counts(soft_nominal_run, tmp_path):
    run_data = load_run(soft_nominal_run.bag)
    spin = torsion_in_friction_units(run_data)
    assert spin is not None and spin.shape == run_data.required_friction.shape
    # Above mu exactly where the event monitor counted slip (the force cone holds here).
    slipping = np.maximum(spin, run_data.required_friction).max(axis=1) > MU
    assert slipping.sum() == soft_nominal_run.recording.live_log.violations()[SLIP]['count']
    assert (tmp_path / 'friction.png') == plot_friction(run_data, tmp_path / 'friction.png')
