"""A contact rolling off its box face: the simulator's event, its scenario record, a bag's verdict.

The face margin is checked against the contact point's position on the cube in object
axes (independent of the face charts); the scenario document must carry the faces so that
a bag is judged as the live run was.
"""

from __future__ import annotations

import json

from grasp_states import CONFIG_DIR, P_OBJECT_PAPER, paper_model, Q_PAPER
import numpy as np
import pytest
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.analysis.run_data import RunData
from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.nodes.scenario import OBJECT_FACES_KEY
from hand_sim_node.config import SimConfig
from hand_sim_node.constraint_margins import OBJECT_FACE
from hand_sim_node.endpoint import HandSimEndpoint
from hand_sim_node.events import EventMonitor

HALF_EDGE = 0.2604 / 2
MSGS = MessageNamespace.from_typestore(get_typestore(Stores.ROS2_JAZZY))

#: Object shift along the palm's x axis (m) and whether finger3 (on the cube's +y face)
#: is then off its face.
SHIFTS = [(0.0, False), (HALF_EDGE - 0.001, False), (HALF_EDGE + 0.001, True), (-0.15, True)]


@pytest.mark.parametrize('shift,off', SHIFTS)
def test_a_contact_off_its_cube_face_is_an_object_face_event(shift, off):
    model = paper_model()
    monitor = EventMonitor.from_model(model)
    p_object = P_OBJECT_PAPER + np.array([shift, 0.0, 0.0])
    state = model.state(0.0, Q_PAPER, np.zeros(Q_PAPER.size), p_object, np.eye(3), np.zeros(6))
    margins = monitor.margins(state, np.tile([0.0, 0.0, 1.0], model.n_contacts))
    i = model.contact_names.index('finger3')
    p_contact_in_object = state.p_contact_in_palm[i] - p_object
    assert p_contact_in_object[1] == pytest.approx(HALF_EDGE, abs=1e-3)  # the +y face
    expected = HALF_EDGE - np.abs(p_contact_in_object[[0, 2]]).max()
    assert margins.object_face[i] == pytest.approx(expected, abs=1e-9)
    events = [e for e in monitor.events(margins) if e.family == OBJECT_FACE]
    assert [e.name for e in events if e.index == i] == (['finger3'] if off else [])


def test_a_sphere_object_has_no_face_edge():
    model = paper_model(**{'model.object.shape': 'sphere', 'model.object.size': 0.3})
    model.bind_contacts(Q_PAPER, P_OBJECT_PAPER, np.eye(3))
    monitor = EventMonitor.from_model(model)
    state = model.state(
        0.0, Q_PAPER, np.zeros(Q_PAPER.size), P_OBJECT_PAPER + 0.1, np.eye(3), np.zeros(6)
    )
    margins = monitor.margins(state, np.tile([0.0, 0.0, 1.0], model.n_contacts))
    assert np.all(np.isposinf(margins.object_face))


@pytest.mark.parametrize(
    'config,faces',
    [
        ('paper_scenario.yaml', [[HALF_EDGE, HALF_EDGE]] * 3),
        ('four_finger_box.yaml', [[0.04, 0.025], [0.025, 0.04], [0.025, 0.04], [0.04, 0.025]]),
        ('four_finger_sphere.yaml', [[None, None]] * 4),
    ],
)
def test_the_scenario_document_carries_the_faces_and_a_bag_reads_them(config, faces):
    params = load_node_parameters(CONFIG_DIR / config, HAND_SIM_NODE)
    model = GraspModel.from_parameters(params, CONFIG_DIR)
    sim = HandSimEndpoint(model, SimConfig.from_parameters(params), MSGS)
    document = json.loads(sim.scenario_text)
    # Half extents of each contact's face, null where the contact has no edge (a sphere).
    assert document[OBJECT_FACES_KEY] == faces
    empty = np.zeros((0,))
    run = RunData(document, 'filtered', empty, empty, empty, empty, empty, empty, empty, empty)
    half = run.object_face_half_widths
    expected = np.array([[np.inf if h is None else h for h in row] for row in faces])
    np.testing.assert_array_equal(half, expected)
    # A document without the key (an older bag): the faces are unknown.
    del document[OBJECT_FACES_KEY]
    assert RunData(document, 'nominal', *[empty] * 8).object_face_half_widths is None
