"""The grasp in space from a run's series: ``setup.png`` (Fig. 2) and ``configuration.png``.

With ``animate``, also ``animation.gif``: the run at :data:`FPS` frames a second of run time,
drawn on two cores (:mod:`~grasp_safety_filter.view.animation`).

The scenes (:mod:`~grasp_safety_filter.view.scene`) need the hand's model, which a bag does
not record: the run's scenario file gives it (``grasp-demo``'s own; ``grasp-analyze
--config``, or the paper's for a bag of its hand). The joint angles and contact forces are the
run's samples; the object's pose is ``/object/odom``'s sample nearest before. ``setup.png`` is
the first sample (the initial grasp), ``configuration.png`` the last, with the constraints the
simulator's event monitor finds violated there marked (the paper's nominal run: the failed
grasp of Fig. 3a).
"""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

from matplotlib.figure import Figure
import numpy as np

from grasp_safety_filter.analysis.forked import ForkedCall, ForkedCallError
from grasp_safety_filter.analysis.run_data import RunData
from grasp_safety_filter.analysis.summary import events_at
from grasp_safety_filter.view.animation import Frame, render_frames, write_gif
from grasp_safety_filter.view.pictures import configuration_figure, setup_figure
from grasp_safety_filter.view.scene import GraspScene, SceneBuilder, Shape
from hand_sim_node.constraint_margins import JOINT_LIMITS

#: Frames of ``animation.gif`` per second of run time: a GIF counts a frame's duration in
#: hundredths of a second, so 10 plays the run exactly in real time.
FPS = 10.0


def scene_at(builder: SceneBuilder, run: RunData, k: int) -> GraspScene:
    """Return the scene of sample ``k`` of ``run`` (``run.tracking`` must hold a pose).

    Raises:
        ValueError: No object pose at or before the sample, or the model refuses the state.
    """
    tracking = run.tracking
    t = float(run.t[k])
    j = int(np.searchsorted(tracking.t, t + 1e-9, side='right')) - 1
    if j < 0:
        raise ValueError(f'no object pose at or before t = {t:.3f} s')
    return builder.scene(
        t, run.q[k], tracking.p_object_in_palm[j], tracking.R_object_to_palm[j], run.force[k]
    )


def violations_at(run: RunData, k: int) -> tuple[dict[str, list[str]], list[str]]:
    """Return the violated families per contact name, and the joints at a limit, at sample k."""
    contacts: dict[str, list[str]] = defaultdict(list)
    joints: list[str] = []
    for event in events_at(run, k):
        if event.family == JOINT_LIMITS:
            joints.append(event.name)
        elif event.family not in contacts[event.name]:
            contacts[event.name].append(event.family)
    return dict(contacts), joints


def setup_picture(run: RunData, builder: SceneBuilder) -> Figure | None:
    """Draw the initial grasp from two sides (the paper's Fig. 2); None if it cannot be."""
    try:
        scene = scene_at(builder, run, 0)
    except ValueError:
        return None
    return setup_figure(scene, f'{run.mode} run: initial grasp')


def configuration_picture(run: RunData, builder: SceneBuilder) -> Figure | None:
    """Draw the last sample's grasp, its violations marked (Fig. 3a); None if it cannot be.

    A configuration the model refuses (a fingertip centre at a sphere object's centre) is not
    drawn: the time series show what happened.
    """
    k = len(run.t) - 1
    try:
        scene = scene_at(builder, run, k)
    except ValueError:
        return None
    contacts, joints = violations_at(run, k)
    title = f'{run.mode} run: end ({run.stop_reason or "recording ended"})'
    return configuration_figure(scene, title, contacts, joints)


def _latest(stamps: np.ndarray, t: float) -> int:
    """Index of the last stamp at or before ``t`` (-1: none)."""
    return int(np.searchsorted(stamps, t + 1e-9, side='right')) - 1


def animation_frames(run: RunData, builder: SceneBuilder) -> list[Frame]:
    """Return the run's frames at :data:`FPS`, up to the first state the model refuses."""
    tracking, statuses = run.tracking, run.filter_statuses
    frames = []
    for t in np.arange(run.t[0], run.t[-1] + 1e-9, 1.0 / FPS):
        k = max(_latest(run.t, t), 0)
        try:
            scene = scene_at(builder, run, k)
        except ValueError:
            break
        text = f'{run.mode} run, t = {run.t[k]:6.3f} s'
        j = _latest(statuses.t, t)
        if j >= 0:
            text += f', filter: {statuses.status[j]}'
        reference = None
        i = _latest(tracking.t_reference, t)
        if i >= 0 and scene.object is not None:
            reference = Shape(
                scene.object.kind,
                scene.object.size,
                tracking.R_reference_to_palm[i],
                tracking.p_reference_in_palm[i],
                'reference',
            )
        frames.append(Frame(scene, text, run.mu_per_contact, run.required_friction[k], reference))
    return frames


def animation(run: RunData, builder: SceneBuilder, path: Path) -> Path | None:
    """Write ``animation.gif`` of the run, half its frames drawn in a forked child.

    None when not even the first sample can be drawn.
    """
    frames = animation_frames(run, builder)
    if not frames:
        path.unlink(missing_ok=True)
        return None
    bounds = np.vstack([frame.scene.points() for frame in frames])
    half = len(frames) // 2
    with ForkedCall(lambda: render_frames(frames[:half], bounds)) as child:
        second = render_frames(frames[half:], bounds)
        try:
            first = child.result()
        except ForkedCallError:  # no child: draw its half here
            first = render_frames(frames[:half], bounds)
    return write_gif(first + second, path, FPS)
