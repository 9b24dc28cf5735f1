"""Pictures of a grasp scene: the paper's Fig. 2 (the initial grasp) and Fig. 3a (a failed one).

:func:`setup_figure` draws a :class:`~grasp_safety_filter.view.scene.GraspScene` from two
sides, isometric and from the top (palm z towards the viewer), and isometrically around the
object (a close-up, the rest clipped): the URDF's links, the kinematic chain, the fingertip
spheres, the object, each contact's point and normal, the contact forces and the palm frame.
:func:`configuration_figure` draws one scene isometrically with what is violated marked on
it: a contact in red with its families' names, a joint at its limit in red.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence

from matplotlib import colormaps
from matplotlib.axes import Axes
from matplotlib.figure import Figure
from mpl_toolkits.mplot3d.art3d import Poly3DCollection
import numpy as np

from grasp_safety_filter.view.scene import friction_cone, GraspScene, Shape

#: The views of the setup figure: name, elevation and azimuth, degrees.
VIEWS = (('isometric', 30.0, -135.0), ('top', 90.0, -90.0), ('close-up', 30.0, -135.0))
#: The close-up shows the object and the fingertips, widened by this share of their size.
CLOSE_UP_MARGIN = 0.25
LINK_COLOUR, TIP_COLOUR, OBJECT_COLOUR = '#7f8c9a', '#e0a040', '#4a90d9'
VIOLATED = '#d62728'
#: Colour of a friction cone by the share of it used, beta / mu in [0, 1].
FRICTION_USE = colormaps['RdYlGn_r']
#: Box faces as corner indices (corners numbered by the bits of their sign pattern).
_BOX_FACES = ((0, 1, 3, 2), (4, 5, 7, 6), (0, 1, 5, 4), (2, 3, 7, 6), (0, 2, 6, 4), (1, 3, 7, 5))
_SIGNS = np.array([[(i >> 2) & 1, (i >> 1) & 1, i & 1] for i in range(8)]) * 2.0 - 1.0


def _solid(axes: Axes, shape: Shape, colour: str, alpha: float, clip: bool = False) -> None:
    """Draw a box as its faces; a sphere, cylinder or capsule as a coarse surface."""
    R, p = shape.R_shape_to_palm, shape.p_shape_in_palm
    if shape.kind == 'box':
        corners = p + (_SIGNS * shape.size) @ R.T
        faces = [[corners[i] for i in face] for face in _BOX_FACES]
        axes.add_collection3d(
            Poly3DCollection(
                faces, facecolor=colour, edgecolor='k', linewidths=0.3, alpha=alpha,
                axlim_clip=clip,
            ),
            axlim_clip=clip,
        )  # fmt: skip
        return
    u, v = np.meshgrid(np.linspace(0.0, 2.0 * np.pi, 17), np.linspace(0.0, np.pi, 9))
    radius = shape.size[0]
    if shape.kind == 'sphere':
        local = radius * np.stack([np.cos(u) * np.sin(v), np.sin(u) * np.sin(v), np.cos(v)])
    else:  # cylinder or capsule, along the shape's z
        half = shape.size[1]
        z = np.where(v < np.pi / 2, half, -half) + (
            radius * np.cos(v) if shape.kind == 'capsule' else 0.0
        )
        ring = radius * (np.sin(v) if shape.kind == 'capsule' else np.ones_like(v))
        local = np.stack([ring * np.cos(u), ring * np.sin(u), z])
    world = np.einsum('ij,jab->iab', R, local) + p[:, None, None]
    axes.plot_surface(
        *world, color=colour, alpha=alpha, linewidth=0.0, shade=True, axlim_clip=clip
    )


def _equal_axes(axes: Axes, points: np.ndarray) -> float:
    """Set equal scales around ``points`` (N, 3); return the half width of the box, m."""
    low, high = points.min(axis=0), points.max(axis=0)
    centre, half = 0.5 * (low + high), 0.5 * float(np.max(high - low))
    for set_limits, c in zip((axes.set_xlim, axes.set_ylim, axes.set_zlim), centre, strict=True):
        set_limits(c - half, c + half)
    axes.set_box_aspect((1.0, 1.0, 1.0), zoom=0.95)
    axes.set_xlabel('x (m)')
    axes.set_ylabel('y (m)')
    axes.set_zlabel('z (m)')
    return half


def draw_scene(
    axes: Axes,
    scene: GraspScene,
    violated_contacts: Mapping[str, Sequence[str]] | None = None,
    violated_joints: Sequence[str] = (),
    bounds: np.ndarray | None = None,
    friction: tuple[np.ndarray, np.ndarray] | None = None,
    reference: Shape | None = None,
    clip: bool = False,
) -> None:
    """Draw ``scene`` on 3-D ``axes``; mark the violated contacts (name -> families) and joints.

    Args:
        axes: 3-D axes.
        scene: The grasp.
        violated_contacts: Contact name -> its violated families, drawn red.
        violated_joints: Joints at a limit, drawn red.
        bounds: Points the axes must show, (N, 3), m (default: the scene's own); an animation
            keeps one box for all its frames.
        friction: ``(mu, beta)`` per contact: each friction cone coloured by the share of it
            used, beta / mu (green 0, red 1 and beyond).
        reference: The object's reference pose, drawn as its box's edges (dashed).
        clip: Leave out what lies outside the axes' box (a close-up).
    """
    violated_contacts = violated_contacts or {}
    half = _equal_axes(axes, scene.points() if bounds is None else bounds)
    c = {'axlim_clip': clip}
    for link in scene.links:
        _solid(axes, link, LINK_COLOUR, 0.35, clip)
    for tip in scene.fingertips:
        _solid(axes, tip, TIP_COLOUR, 0.5, clip)
    if scene.object is not None:
        _solid(axes, scene.object, OBJECT_COLOUR, 0.25, clip)
    for start, end in scene.chain:
        axes.plot(*np.stack([start, end]).T, color='k', linewidth=1.0, **c)
    arrow = 0.3 * half
    for axis, colour in zip(np.eye(3), ('r', 'g', 'b'), strict=True):  # the palm frame
        axes.quiver(0.0, 0.0, 0.0, *(arrow * axis), color=colour, linewidth=1.5, **c)
    p_c = scene.p_contact_in_palm
    axes.quiver(*p_c.T, *(arrow * scene.normal_in_palm).T, color='k', linewidth=0.8, **c)
    if friction is not None:
        for p, n, mu, beta in zip(p_c, scene.normal_in_palm, *friction, strict=True):
            used = min(beta / mu, 1.0) if np.isfinite(beta) else 1.0
            cone = friction_cone(p, n, mu, 0.6 * arrow)
            axes.plot_surface(*cone, color=FRICTION_USE(used), alpha=0.45, linewidth=0.0, **c)
    if reference is not None:  # its edges (a sphere's: those of the cube around it)
        R, p = reference.R_shape_to_palm, reference.p_shape_in_palm
        corners = p + (_SIGNS * reference.size) @ R.T
        for face in _BOX_FACES:
            ring = corners[[*face, face[0]]]
            axes.plot(*ring.T, color=OBJECT_COLOUR, linestyle='--', linewidth=0.8, **c)
    if scene.force_in_palm is not None:
        largest = float(np.max(np.linalg.norm(scene.force_in_palm, axis=1)))
        if largest > 0.0:
            f = scene.force_in_palm * (1.5 * arrow / largest)
            axes.quiver(*p_c.T, *f.T, color='#2ca02c', linewidth=1.5, **c)
    for name, p in zip(scene.contact_names, p_c, strict=True):
        violated = name in violated_contacts
        colour = VIOLATED if violated else 'k'
        # Drawn last and unshaded: a contact stays visible through the solids around it.
        axes.scatter(*p, color=colour, s=45 if violated else 15, depthshade=False, zorder=10, **c)
        axes.text(*p, f' {name}', color=colour, fontsize=7, zorder=11, **c)
    for name in violated_joints:
        p = scene.p_joint_in_palm[name]
        axes.scatter(*p, color=VIOLATED, marker='X', s=60, depthshade=False, zorder=10, **c)
        axes.text(*p, f' {name}', color=VIOLATED, fontsize=7, zorder=11, **c)


def close_up_bounds(scene: GraspScene) -> np.ndarray:
    """Return the corners of the box around the object and the fingertips, widened, (2, 3), m."""
    points = scene.grasp_points()
    low, high = points.min(axis=0), points.max(axis=0)
    widen = CLOSE_UP_MARGIN * float(np.max(high - low))
    return np.array([low - widen, high + widen])


def setup_figure(scene: GraspScene, title: str) -> Figure:
    """Draw the grasp from two sides and around the object (module docstring): Fig. 2."""
    figure = Figure(figsize=(16.0, 5.5))
    for column, (name, elevation, azimuth) in enumerate(VIEWS, start=1):
        axes = figure.add_subplot(1, len(VIEWS), column, projection='3d')
        close_up = name == 'close-up'
        bounds = close_up_bounds(scene) if close_up else None
        draw_scene(axes, scene, bounds=bounds, clip=close_up)
        axes.view_init(elev=elevation, azim=azimuth)
        if name == 'top':  # z points at the viewer: its axis would only clutter
            axes.set_zticks([])
            axes.set_zlabel('')
        axes.set_title(f'{name} view')
    figure.suptitle(f'{title} (t = {scene.t:.3f} s; normals black, forces green)')
    figure.tight_layout()
    return figure


def configuration_figure(
    scene: GraspScene,
    title: str,
    violated_contacts: Mapping[str, Sequence[str]],
    violated_joints: Sequence[str],
) -> Figure:
    """Draw the grasp with its violated constraints marked: the paper's Fig. 3a."""
    figure = Figure(figsize=(10.0, 6.5))
    axes = figure.add_axes((0.02, 0.02, 0.62, 0.9), projection='3d')
    draw_scene(axes, scene, violated_contacts, violated_joints)
    axes.view_init(elev=VIEWS[0][1], azim=VIEWS[0][2])
    lines = [f'{name}: {", ".join(families)}' for name, families in violated_contacts.items()]
    if violated_joints:
        lines.append('at a joint limit: ' + ', '.join(violated_joints))
    text = 'violated (red):\n' + '\n'.join(lines) if lines else 'no constraint violated'
    figure.text(0.66, 0.5, text, fontsize=9, va='center', wrap=True)
    figure.suptitle(f'{title}, t = {scene.t:.3f} s', fontsize=11)
    return figure
