"""A grasp scene as RViz/Foxglove markers: what to draw, in plain values (no message classes).

:func:`scene_markers` turns a :class:`~grasp_safety_filter.view.scene.GraspScene` into
:class:`MarkerSpec` values, one per ``visualization_msgs/Marker`` (namespace and id fixed per
part, so that each update replaces the last), all in the scene's palm frame:

- ``links``: the URDF's solids (cube, sphere, cylinder; a capsule as its cylinder);
  ``chain``: the kinematic chain, a line list; ``fingertips``, ``object``: the contact model's;
- ``contacts``: the contact points (red: a contact one of the filter's active rows names);
  ``normals``: a line per contact, into the object; ``forces``: an arrow per contact, the
  contact force on the object, ``force_scale`` m per N (when known);
- ``cones``: each friction cone ``|f_t| <= mu f_n`` as a triangle list in its contact's
  frame (the same points while mu holds), coloured by the share of it used, beta / mu
  (green 0, red 1 and beyond; grey when unknown);
- ``active``: the joints an active row names (red spheres), and the active rows as text above
  the object.

Lengths follow the object's size: normals and cones are :data:`ARROW_SHARE` of it long.
:mod:`~grasp_safety_filter.io.messages.markers` builds the messages.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from functools import lru_cache

from matplotlib import colormaps
import numpy as np

from grasp_safety_filter.io.messages import quaternion_xyzw_from_matrix
from grasp_safety_filter.view.scene import friction_cone, GraspScene, Shape

#: Normals and friction cones are this share of the object's largest half extent long.
ARROW_SHARE = 0.8
#: Sides of a drawn friction cone.
CONE_SEGMENTS = 12
#: Colour of a friction cone by beta / mu in [0, 1] (as the pictures').
FRICTION_USE = colormaps['RdYlGn_r']
LINK_RGBA = (0.5, 0.55, 0.6, 0.8)
TIP_RGBA = (0.88, 0.63, 0.25, 0.9)
OBJECT_RGBA = (0.29, 0.56, 0.85, 0.5)
FORCE_RGBA = (0.17, 0.63, 0.17, 1.0)
RED = (0.84, 0.15, 0.16, 1.0)
BLACK = (0.0, 0.0, 0.0, 1.0)


@dataclass(frozen=True)
class MarkerSpec:
    """One marker, in plain values (palm frame, m).

    Attributes:
        ns: Namespace; with ``id``, what an update replaces.
        id: Index in the namespace.
        kind: ``cube``, ``sphere``, ``cylinder``, ``arrow``, ``line_list``, ``sphere_list``,
            ``triangle_list`` or ``text``.
        position: Pose position (3,), m.
        quaternion: Pose orientation ``(x, y, z, w)``.
        scale: The marker's scale (3,): sizes, m (widths for lines and arrows).
        rgba: Colour, each in [0, 1].
        points: Points of lines, lists and arrows, (N, 3), m (empty: none).
        colors: A colour per point, (N, 4) (empty: ``rgba`` for all).
        text: A text marker's text.
    """

    ns: str
    id: int
    kind: str
    position: np.ndarray = field(default_factory=lambda: np.zeros(3))
    quaternion: np.ndarray = field(default_factory=lambda: np.array([0.0, 0.0, 0.0, 1.0]))
    scale: np.ndarray = field(default_factory=lambda: np.ones(3))
    rgba: tuple[float, float, float, float] = BLACK
    points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    colors: np.ndarray = field(default_factory=lambda: np.zeros((0, 4)))
    text: str = ''


def _solid(
    ns: str, index: int, shape: Shape, quaternion: np.ndarray, rgba: tuple[float, ...]
) -> MarkerSpec:
    """Return a solid's cube, sphere or cylinder marker (a capsule: a cylinder, caps included)."""
    if shape.kind == 'box':
        kind, scale = 'cube', 2.0 * shape.size
    elif shape.kind == 'sphere':
        kind, scale = 'sphere', np.full(3, 2.0 * shape.size[0])
    else:
        radius, half = shape.size
        length = 2.0 * (half + radius) if shape.kind == 'capsule' else 2.0 * half
        kind, scale = 'cylinder', np.array([2.0 * radius, 2.0 * radius, length])
    return MarkerSpec(ns, index, kind, shape.p_shape_in_palm, quaternion, scale, rgba)


@lru_cache(maxsize=64)
def _cone_triangles(mu: float, length: float) -> np.ndarray:
    """Return a friction cone's triangles in its contact frame (apex at 0, along z), m.

    Cached: a marker whose points are the same array is not rebuilt
    (:class:`~grasp_safety_filter.io.messages.markers.MarkerArrayBuilder`).
    """
    rim = friction_cone(np.zeros(3), np.array([0.0, 0.0, 1.0]), mu, length, CONE_SEGMENTS)
    rim = rim[:, 1, :].T
    apex = np.zeros_like(rim[:-1])
    triangles = np.stack([apex, rim[:-1], rim[1:]], axis=1).reshape(-1, 3)
    triangles.flags.writeable = False
    return triangles


def _named(rows: Sequence[str]) -> set[str]:
    """Return the contacts and joints the rows name (``family/<name>/<side>``)."""
    return {parts[1] for row in rows if len(parts := row.split('/')) > 2}


def scene_markers(
    scene: GraspScene,
    mu: np.ndarray,
    beta: np.ndarray | None = None,
    active_rows: Sequence[str] = (),
    force_scale: float = 0.005,
) -> list[MarkerSpec]:
    """Return the markers of ``scene`` (module docstring).

    Args:
        scene: The grasp.
        mu: Friction coefficient per contact, (n,).
        beta: Friction used per contact, ``|f_t| / f_n`` (n,), inf where ``f_n <= 0``;
            None: unknown (the cones grey).
        active_rows: The filter's active rows (its status's ``active``).
        force_scale: Force arrows' length per newton, m/N.
    """
    size = float(np.max(scene.object.size)) if scene.object is not None else 0.05
    length = ARROW_SHARE * size
    width = 0.04 * length
    solids = [*scene.links, *scene.fingertips, *([scene.object] if scene.object else [])]
    frames = [s.R_shape_to_palm for s in solids] + list(scene.R_contact_to_palm)
    quaternions = [quaternion_xyzw_from_matrix(R) for R in frames]
    n_links, n_tips = len(scene.links), len(scene.fingertips)
    markers = [
        _solid('links', i, link, quaternions[i], LINK_RGBA) for i, link in enumerate(scene.links)
    ]
    markers += [
        _solid('fingertips', i, tip, quaternions[n_links + i], TIP_RGBA)
        for i, tip in enumerate(scene.fingertips)
    ]
    if scene.object is not None:
        markers.append(
            _solid('object', 0, scene.object, quaternions[n_links + n_tips], OBJECT_RGBA)
        )
    line, chain = np.array([width, 0.0, 0.0]), scene.chain.reshape(-1, 3)
    markers.append(MarkerSpec('chain', 0, 'line_list', scale=line, points=chain))
    named = _named(active_rows)
    p_c = scene.p_contact_in_palm
    colors = np.array([RED if name in named else BLACK for name in scene.contact_names])
    dot = np.full(3, 3.0 * width)
    markers.append(MarkerSpec('contacts', 0, 'sphere_list', scale=dot, points=p_c, colors=colors))
    normals = np.stack([p_c, p_c + length * scene.normal_in_palm], axis=1).reshape(-1, 3)
    markers.append(MarkerSpec('normals', 0, 'line_list', scale=line, points=normals))
    arrow = np.array([width, 2.0 * width, 3.0 * width])  # shaft, head diameters, head length
    if scene.force_in_palm is not None:
        for i, (p, f) in enumerate(zip(p_c, scene.force_in_palm, strict=True)):
            ends = np.array([p, p + force_scale * f])
            markers.append(
                MarkerSpec('forces', i, 'arrow', scale=arrow, rgba=FORCE_RGBA, points=ends)
            )
    contact_quaternions = quaternions[len(solids) :]
    for i, (p, q, mu_i) in enumerate(zip(p_c, contact_quaternions, mu, strict=True)):
        if beta is None:
            rgba = (0.6, 0.6, 0.6, 0.5)
        else:
            used = min(beta[i] / mu_i, 1.0) if np.isfinite(beta[i]) else 1.0
            rgba = (*FRICTION_USE(used)[:3], 0.5)
        triangles = _cone_triangles(float(mu_i), length)
        markers.append(MarkerSpec('cones', i, 'triangle_list', p, q, rgba=rgba, points=triangles))
    joints = [scene.p_joint_in_palm[name] for name in scene.p_joint_in_palm if name in named]
    markers.append(
        MarkerSpec(
            'active',
            0,
            'sphere_list',
            scale=np.full(3, 4.0 * width),
            rgba=RED,
            points=np.array(joints).reshape(-1, 3),
        )
    )
    if scene.object is not None:
        above = scene.object.p_shape_in_palm + np.array([0.0, 0.0, 2.0 * size])
        text = 'active: ' + ', '.join(active_rows) if active_rows else 'no active row'
        height = np.array([0.0, 0.0, 0.3 * size])
        markers.append(MarkerSpec('active', 1, 'text', above, scale=height, text=text))
    return markers
