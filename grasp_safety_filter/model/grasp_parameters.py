"""A :class:`~grasp_safety_filter.model.grasp_model.GraspModel` from its ``model.*`` parameters.

What each parameter becomes (io/schemas/model.py documents them):

- ``model.urdf_file``, ``model.joint_names``, ``model.gravity``: the hand (Pinocchio);
- ``model.fingertip_frames``: per contact, the fingertip sphere from the URDF's collision
  model (radius R_i, centre; :mod:`grasp_safety_filter.model.fingertips`); a positive
  ``model.fingertip_radius`` must equal every R_i;
- ``model.object.shape`` with ``model.object.size`` (cube edge, sphere diameter) or
  ``model.object.edge_lengths`` (box): the object's inertia and surfaces;
- ``model.contact_faces``: per contact a declared box face, or ``nearest`` (one entry for
  all contacts allowed); the nearest faces, and a sphere's charts, are chosen at the first
  configuration: the initial grasp when the parameters hold it (``hand_sim_node``'s
  ``initial.*``), else the first state the model is given;
- ``model.friction_coefficient``, ``model.torsional_friction`` (0: point contacts, > 0: soft
  fingers) and ``model.fingertip_workspace.*``: one value for every contact or one per
  contact (:mod:`grasp_safety_filter.model.per_contact`);
- ``model.palm_frame`` (empty: the URDF's root link), ``model.object_frame``.

Free fingers: ``model.joint_names`` lists every actuated joint of the URDF; a joint on no
listed fingertip's chain (a finger whose tip is not in ``model.fingertip_frames``) is free.
It moves no contact (its columns of J_h are zero), so only its joint limits, its actuator
limits and the nominal controller's null-space posture act on it.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any, TYPE_CHECKING

import numpy as np
import pinocchio as pin

from grasp_safety_filter.model.fingertip_workspace import (
    BOUNDS,
    FingertipWorkspace,
    GraspConfigError,
    PARAMETER_PREFIX,
)
from grasp_safety_filter.model.hand import HandModel
from grasp_safety_filter.model.object_shapes import ObjectShape
from grasp_safety_filter.model.quaternion import rotation_matrix
from grasp_safety_filter.model.rolling import ContactPair
from grasp_safety_filter.model.surfaces import SphereSurface

if TYPE_CHECKING:
    from grasp_safety_filter.model.grasp_model import GraspModel

#: Relative tolerance of ``model.fingertip_radius`` against a collision sphere's radius.
RADIUS_RTOL = 1e-9

#: The ``model.contact_faces`` entry asking for the nearest face (io/schemas.NEAREST_FACE).
NEAREST_FACE = 'nearest'


def _root_link(hand: HandModel) -> str:
    """Name of the URDF's root link (Pinocchio's first body frame on the universe joint)."""
    for frame in hand.model.frames:
        if frame.type == pin.FrameType.BODY and frame.parentJoint == 0:
            return frame.name
    return hand.model.frames[0].name


def palm_frame_name(hand: HandModel, configured: str) -> str:
    """Return the palm frame's name: ``configured``, or the URDF's root link if it is empty.

    Raises:
        GraspConfigError: ``configured`` names a URDF frame that is not fixed to the root at
            the identity (the model's poses are in the root link's frame).
    """
    root = _root_link(hand)
    if not configured:
        return root
    model = hand.model
    if model.existFrame(configured):
        frame = model.frames[model.getFrameId(configured)]
        root_frame = model.frames[model.getFrameId(root)]
        if frame.parentJoint != 0 or not frame.placement.isApprox(root_frame.placement, 1e-12):
            raise GraspConfigError(
                f'model.palm_frame: frame {configured!r} of the URDF is not the root link '
                f"{root!r} (every pose of the model is in the root link's frame): expected "
                f'{root!r}, a frame fixed to it at the identity, or a name outside the URDF'
            )
    return configured


def free_joint_names(hand: HandModel) -> list[str]:
    """Joints of ``hand`` on no fingertip's chain (free fingers), in joint order.

    A joint is on a fingertip's chain when it moves the fingertip frame (Pinocchio's
    ``supports`` of the frame's parent joint). A free joint's columns of J_h are zero.
    """
    model = hand.model
    on_chain = {
        model.names[joint]
        for frame_id in hand.frame_ids
        for joint in model.supports[model.frames[frame_id].parentJoint]
    }
    return [name for name in hand.joint_names if name not in on_chain]


def _object_shape(params: Mapping[str, Any]) -> ObjectShape:
    kind = params['model.object.shape']
    try:
        if kind == 'box':
            lengths = tuple(float(x) for x in params['model.object.edge_lengths'])
            return ObjectShape('box', edge_lengths=lengths)
        if kind == 'cube':
            return ObjectShape('cube', edge_lengths=(float(params['model.object.size']),) * 3)
        if kind == 'sphere':
            return ObjectShape('sphere', radius=0.5 * float(params['model.object.size']))
        return ObjectShape(kind)
    except ValueError as error:
        raise GraspConfigError(f'model.object: {error}') from None


def _declared_faces(params: Mapping[str, Any], names: list[str], shape: ObjectShape) -> list:
    """Per contact the declared face label, or None for the nearest (always for a sphere)."""
    if not shape.has_faces:
        return [None] * len(names)
    faces = list(params.get('model.contact_faces', [NEAREST_FACE]))
    if len(faces) == 1:
        faces = faces * len(names)
    if len(faces) != len(names):
        raise GraspConfigError(
            f'model.contact_faces: expected one face per contact ({len(names)}) or one for all, '
            f'got {len(faces)}'
        )
    return [None if face == NEAREST_FACE else face for face in faces]


def grasp_model_from_parameters(
    cls: type[GraspModel], params: Mapping[str, Any], base_dir: Path | str = '.'
) -> GraspModel:
    """Build ``cls`` from validated ``model.*`` parameters.

    Relative ``model.urdf_file`` paths resolve against ``base_dir`` (the directory of the
    parameter file).

    Raises:
        GraspConfigError: A parameter is missing or does not fit the URDF (naming it, the
            contact or the link).
        HandModelError: The URDF cannot be used.
    """
    def get(name: str) -> Any:
        if name not in params:
            raise GraspConfigError(f"parameter '{name}' is missing")
        return params[name]

    urdf = Path(get('model.urdf_file'))
    if not urdf.is_absolute():
        urdf = Path(base_dir) / urdf
    gravity = np.asarray(get('model.gravity'), dtype=float)
    if gravity.shape != (3,):
        raise GraspConfigError(f'model.gravity: expected 3 elements, got {len(gravity)}')
    frames = list(get('model.fingertip_frames'))
    names = list(get('model.contact_names'))
    if len(names) != len(frames):
        raise GraspConfigError(
            f'model.contact_names: expected one name per fingertip frame ({len(frames)}), '
            f'got {len(names)}'
        )
    shape = _object_shape({'model.object.shape': get('model.object.shape'), **params})
    faces = _declared_faces(params, names, shape)
    hand = HandModel(urdf, list(get('model.joint_names')), frames, gravity)
    radius = float(params.get('model.fingertip_radius', 0.0))
    if radius > 0.0:
        for name, tip in zip(names, hand.fingertips, strict=True):
            if abs(tip.radius - radius) > RADIUS_RTOL * radius:
                raise GraspConfigError(
                    f'model.fingertip_radius: contact {name!r}: expected the radius of the '
                    f'collision sphere of link {tip.link!r} ({tip.radius:g} m), got {radius:g} m '
                    '(leave model.fingertip_radius out: the URDF gives it)'
                )
    try:
        rigid_object = shape.rigid_object(float(get('model.object.mass')), gravity)
    except ValueError as error:
        raise GraspConfigError(str(error)) from None
    contacts = None
    if all(face is not None for face in faces):
        contacts = []
        for name, face, tip in zip(names, faces, hand.fingertips, strict=True):
            try:
                contacts.append(ContactPair(SphereSurface(tip.radius), shape.face(face)))
            except ValueError as error:
                raise GraspConfigError(f'model.contact_faces: contact {name!r}: {error}') from None
    workspace = FingertipWorkspace.for_contacts(
        names, **{bound: get(PARAMETER_PREFIX + bound) for bound in BOUNDS}
    )
    model = cls(
        hand,
        rigid_object,
        contacts,
        names,
        get('model.friction_coefficient'),
        workspace,
        object_shape=shape,
        declared_faces=faces,
        palm_frame=palm_frame_name(hand, str(params.get('model.palm_frame', ''))),
        object_frame=str(params.get('model.object_frame', 'object')) or 'object',
        torsional_friction=params.get('model.torsional_friction', 0.0),
        torsional_compliance=params.get('model.torsional_compliance', 0.1),
    )
    q0, p0 = params.get('initial.joint_positions'), params.get('initial.object_position')
    if not model.contacts_bound and q0 is not None and p0 is not None:
        if len(q0) == model.n_joints:
            R0 = rotation_matrix(params.get('initial.object_orientation', (0.0, 0.0, 0.0, 1.0)))
            model.bind_contacts(np.asarray(q0, dtype=float), np.asarray(p0, dtype=float), R0)
    return model
