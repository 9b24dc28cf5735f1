"""Object tracking error and object.png: against an independent recomputation from the bag."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from grasp_safety_filter.analysis.figures import plot_run
from grasp_safety_filter.analysis.object_figure import object_figure, OBJECT_PANELS
from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.analysis.summary import summarize
from grasp_safety_filter.analysis.tracking import NO_REFERENCE
from grasp_safety_filter.control.reference import PaperReference, Pose
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.bag import BagRecorder, iter_bag
from grasp_safety_filter.io.messages import header_stamp_ns
from grasp_safety_filter.runner import record_run, RunOptions

CONFIG = Path(__file__).resolve().parents[1] / 'config' / 'paper_scenario.yaml'
#: The paper scenario's reference shape (config/paper_scenario.yaml, nominal_controller_node).
AMPLITUDE = (0.0, 0.0, 0.25, 0.0, 0.0, 2.0)
FREQUENCY = 1.0


def _matrix_from_quaternion(x: float, y: float, z: float, w: float) -> np.ndarray:
    """Return the textbook unit-quaternion rotation matrix (written out, not the package's)."""
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
    )


@pytest.fixture(scope='module', params=['nominal', 'filtered'])
def short_run(request, tmp_path_factory):
    bag = tmp_path_factory.mktemp(request.param) / 'bag'
    record_run(RunOptions(CONFIG, mode=request.param, duration=0.3), bag)
    return bag


def _independent_errors(bag: Path) -> tuple[np.ndarray, np.ndarray]:
    """Position error norm and rotation angle from the odometry and the paper's r(t).

    The reference is recomputed from :class:`PaperReference` started at the first object
    pose and its stamp (the nominal controller's first tick in the paper scenario: its
    start-up grasp check passes at once); the rotation angle from the quaternions,
    ``2 arccos |<q_object, q_reference>|``.
    """
    poses = []
    for _, _, msg in iter_bag(bag, topics=[topics.OBJECT_ODOM]):
        o = msg.pose.pose.orientation
        p = msg.pose.pose.position
        poses.append(
            (header_stamp_ns(msg) * 1e-9, np.array([p.x, p.y, p.z]), (o.x, o.y, o.z, o.w))
        )
    t0, p0, q0 = poses[0]
    reference = PaperReference(Pose(p0, _matrix_from_quaternion(*q0)), AMPLITUDE, FREQUENCY, t0=t0)
    position, angle = [], []
    for t, p, q in poses:
        desired = reference.sample(t)
        position.append(np.linalg.norm(p - desired.r[:3]))
        roll, pitch, yaw = desired.r[3:]
        # ZYX: q = q_z(yaw) q_y(pitch) q_x(roll), written out.
        cr, sr = np.cos(roll / 2), np.sin(roll / 2)
        cp, sp = np.cos(pitch / 2), np.sin(pitch / 2)
        cy, sy = np.cos(yaw / 2), np.sin(yaw / 2)
        q_desired = np.array(
            [
                sr * cp * cy - cr * sp * sy,
                cr * sp * cy + sr * cp * sy,
                cr * cp * sy - sr * sp * cy,
                cr * cp * cy + sr * sp * sy,
            ]
        )
        dot = min(abs(float(np.dot(q_desired, np.asarray(q)))), 1.0)
        angle.append(2.0 * np.arccos(dot))
    return np.array(position), np.array(angle)


def test_tracking_error_matches_an_independent_computation(short_run):
    position, angle = _independent_errors(short_run)
    tracking = summarize(load_run(short_run))['object_tracking']
    assert tracking['reference'] == topics.OBJECT_REFERENCE_SAMPLE
    assert tracking['samples'] == len(position)
    for key, expected in (('position_error_m', position), ('orientation_error_rad', angle)):
        numbers = tracking[key]
        assert numbers['rms'] == pytest.approx(np.sqrt(np.mean(expected**2)), rel=1e-6, abs=1e-9)
        assert numbers['max'] == pytest.approx(expected.max(), rel=1e-6, abs=1e-9)
        assert numbers['final'] == pytest.approx(expected[-1], rel=1e-6, abs=1e-9)
    # Something is tracked: the object moves away from its start and errors are not all zero.
    assert position.max() > 0.0 and angle.max() > 0.0


def test_object_figure_has_a_panel_per_coordinate_with_object_and_reference(short_run, tmp_path):
    run = load_run(short_run)
    paths = plot_run(run, tmp_path)
    assert tmp_path / 'object.png' in paths
    assert (tmp_path / 'object.png').stat().st_size > 0
    figure = object_figure(run)
    labels = [axes.get_ylabel() for axes in figure.axes]
    assert labels == [f'{label} [{unit}]' for label, unit in OBJECT_PANELS]
    for axes in figure.axes:
        assert [line.get_label() for line in axes.get_lines()] == ['object', 'reference']
    z_reference = figure.axes[2].get_lines()[1].get_ydata()
    z_object = np.array(
        [
            msg.pose.pose.position.z
            for _, _, msg in iter_bag(short_run, topics=[topics.OBJECT_ODOM])
        ]
    )
    # The reference starts at the object's initial z and moves down (A_z > 0, cos - 1 <= 0).
    assert z_reference[0] == pytest.approx(z_object[0], abs=1e-12)
    assert z_reference[-1] < z_reference[0]


def test_a_bag_without_the_reference_still_analyses(short_run, tmp_path):
    old = tmp_path / 'old'
    with BagRecorder(old) as bag:
        for topic, stamp, msg in iter_bag(short_run):
            if topic != topics.OBJECT_REFERENCE_SAMPLE:
                bag.write(topic, stamp, msg)
    run = load_run(old)
    tracking = summarize(run)['object_tracking']
    assert tracking == {
        'reference': NO_REFERENCE,
        'samples': 0,
        'position_error_m': None,
        'orientation_error_rad': None,
    }
    paths = plot_run(run, tmp_path / 'figures')
    assert tmp_path / 'figures' / 'object.png' in paths
    figure = object_figure(run)
    assert NO_REFERENCE in figure.get_suptitle()
    assert all(len(axes.get_lines()) == 1 for axes in figure.axes)
