"""The grasp in space: scenes against the URDF and the contact geometry, and their pictures.

A scene's contact points must lie on the fingertip spheres and on the object's surface, its
normals point into the object, its forces be the contact-frame forces rotated; its links are
the URDF's ``<visual>`` solids (read here with ElementTree, not Pinocchio). The pictures of a
recorded run are drawn by ``grasp-analyze`` for the paper's hand and for the example hands.
"""

from __future__ import annotations

import contextlib
import io
from pathlib import Path
import xml.etree.ElementTree as ElementTree

import numpy as np
from PIL import Image
import pytest

from grasp_safety_filter.analysis.grasp_figures import FPS, scene_at, violations_at
from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.cli import analyze_main
from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.runner import record_run, RunOptions
from grasp_safety_filter.view.pictures import close_up_bounds, setup_figure
from grasp_safety_filter.view.scene import SceneBuilder
from hand_sim_node.config import SimConfig
from hand_sim_node.plant import PlantConfig

CONFIG = Path(__file__).resolve().parent.parent / 'config'
SCENARIOS = [
    'paper_scenario.yaml',
    'four_finger_box.yaml',
    'four_finger_sphere.yaml',
    'four_finger_three_contacts.yaml',
]
#: How far a contact point may lie off a surface at the simulator's initial grasp, m.
ON_SURFACE = 1e-7


def initial_scene(name: str):
    """Return a scenario file's initial grasp as a scene, forces (1, 2, 3) N per contact."""
    params = load_node_parameters(CONFIG / name, HAND_SIM_NODE)
    model = GraspModel.from_parameters(params)
    state = PlantConfig().build(model, SimConfig.from_parameters(params)).observe()
    force = np.tile([1.0, 2.0, 3.0], (model.n_contacts, 1))
    scene = SceneBuilder(model).scene(
        0.0, state.q, state.p_object_in_palm, state.R_object_to_palm, force
    )
    return model, state, scene


@pytest.mark.parametrize('name', SCENARIOS)
def test_contacts_lie_on_the_fingertips_and_on_the_object(name):
    model, _, scene = initial_scene(name)
    p_c = scene.p_contact_in_palm
    assert p_c.shape == (model.n_contacts, 3)
    for tip, p in zip(scene.fingertips, p_c, strict=True):
        assert abs(np.linalg.norm(p - tip.p_shape_in_palm) - tip.size[0]) < ON_SURFACE
    shape = scene.object
    p_in_object = (p_c - shape.p_shape_in_palm) @ shape.R_shape_to_palm
    if shape.kind == 'sphere':
        assert np.allclose(np.linalg.norm(p_in_object, axis=1), shape.size[0], atol=ON_SURFACE)
    else:  # on one face: one coordinate at its half extent, the others within theirs
        outside = np.abs(p_in_object) - shape.size
        assert np.allclose(outside.max(axis=1), 0.0, atol=ON_SURFACE)
        assert np.all(np.sort(outside, axis=1)[:, :2] < 0.0)
    # Normals: unit, into the object (towards its centre on these convex objects).
    n = scene.normal_in_palm
    assert np.allclose(np.linalg.norm(n, axis=1), 1.0)
    assert np.all(np.einsum('ij,ij->i', shape.p_shape_in_palm - p_c, n) > 0.0)
    # Forces: the contact-frame forces rotated (norm kept, f_n along the normal).
    assert np.allclose(np.linalg.norm(scene.force_in_palm, axis=1), np.sqrt(14.0))
    assert np.allclose(np.einsum('ij,ij->i', scene.force_in_palm, n), 3.0)


@pytest.mark.parametrize('name', SCENARIOS)
def test_links_are_the_urdf_visual_solids(name):
    model, _, scene = initial_scene(name)
    urdf = ElementTree.parse(model.hand.urdf_path).getroot()
    expected = sorted(
        (link.get('name'), geometry.tag)
        for link in urdf.iter('link')
        for visual in link.iter('visual')
        for geometry in visual.find('geometry')
        if geometry.tag in ('box', 'sphere', 'cylinder', 'capsule')
    )
    drawn = sorted((s.name.rsplit('_', 1)[0], s.kind) for s in scene.links)
    assert drawn == expected
    for solid in scene.links:
        assert np.allclose(solid.R_shape_to_palm.T @ solid.R_shape_to_palm, np.eye(3))
    # The chain joins each model joint to its parent: every joint origin is an end of it.
    ends = scene.chain[:, 1]
    for p in scene.p_joint_in_palm.values():
        assert np.min(np.linalg.norm(ends - p, axis=1)) < 1e-12
    assert len(scene.p_joint_in_palm) == model.n_joints


@pytest.mark.parametrize('name', SCENARIOS)
def test_the_close_up_holds_the_object_and_the_fingertips_and_is_a_zoom(name):
    _, _, scene = initial_scene(name)
    figure = setup_figure(scene, name)
    whole, _, close = figure.axes
    assert close.get_title() == 'close-up view'
    limits = np.array([close.get_xlim3d(), close.get_ylim3d(), close.get_zlim3d()]).T
    for solid in [*scene.fingertips, scene.object]:
        reach = float(np.max(solid.size))
        assert np.all(limits[0] <= solid.p_shape_in_palm - reach)
        assert np.all(solid.p_shape_in_palm + reach <= limits[1])
    assert np.all(close_up_bounds(scene)[0] >= limits[0] - 1e-12)
    whole_width = np.diff(whole.get_xlim3d())[0]
    assert np.diff(close.get_xlim3d())[0] < 0.8 * whole_width


@pytest.fixture(scope='module')
def nominal_bag(tmp_path_factory) -> Path:
    """Record the paper's nominal run to its failure (1.3 s)."""
    path = tmp_path_factory.mktemp('nominal') / 'bag'
    record_run(RunOptions(CONFIG / 'paper_scenario.yaml', 'nominal', duration=1.3), path)
    return path


def test_the_paper_nominal_run_ends_in_the_failed_grasp_of_fig_3a(nominal_bag, tmp_path):
    run = load_run(nominal_bag)
    contacts, joints = violations_at(run, len(run.t) - 1)
    # The paper's nominal run: contacts leave the fingertip workspace, joints pass limits.
    assert run.stop_reason == 'fingertip_workspace'
    assert any('fingertip_workspace' in families for families in contacts.values())
    assert joints
    model, _ = GraspModel.from_parameter_file(CONFIG / 'paper_scenario.yaml')
    first = scene_at(SceneBuilder(model), run, 0)
    assert np.allclose(first.chain, initial_scene('paper_scenario.yaml')[2].chain, atol=1e-9)
    with contextlib.redirect_stdout(io.StringIO()) as printed:
        code = analyze_main([str(nominal_bag), '--out', str(tmp_path), '--animate'])
    assert code == 0, printed.getvalue()
    for name in ('setup.png', 'configuration.png', 'animation.gif'):
        assert f'figure: {tmp_path / name}' in printed.getvalue()
    for name in ('setup.png', 'configuration.png'):
        png = (tmp_path / name).read_bytes()
        assert png.startswith(b'\x89PNG') and len(png) > 20_000, name
    # The animation plays the run in real time: a frame per 1 / FPS s of it.
    with Image.open(tmp_path / 'animation.gif') as gif:
        assert gif.format == 'GIF'
        assert gif.n_frames == int((run.t[-1] - run.t[0]) * FPS + 1e-6) + 1
        assert gif.info['duration'] == round(1000 / FPS)
        gif.seek(gif.n_frames - 1)
        colours = np.unique(np.asarray(gif.convert('RGB')).reshape(-1, 3), axis=0)
        assert len(colours) > 8  # drawn, not blank


def test_a_bag_of_another_hand_gets_no_grasp_pictures(nominal_bag, tmp_path):
    """The default scenario file is the paper's: a bag of it analysed as another hand's."""
    with contextlib.redirect_stdout(io.StringIO()):
        code = analyze_main(
            [str(nominal_bag), '--out', str(tmp_path), '--config',
             str(CONFIG / 'four_finger_box.yaml')]
        )  # fmt: skip
    assert code == 2  # the file names another hand: refused, nothing drawn
    assert not (tmp_path / 'setup.png').exists()
