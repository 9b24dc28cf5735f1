"""Fingertip spheres from the URDF's collision model (Pinocchio's own URDF collision parser).

Each contact names a fingertip frame (``model.fingertip_frames``: a link, or a frame fixed to
one). Its fingertip is the ``<collision>`` whose geometry is a ``<sphere>`` on the rigid body
that frame belongs to (the links joined to it by fixed joints):

- R_i is the sphere's radius, m;
- the fingertip frame F_i used by the model has its origin at the sphere's centre and the
  named frame's axes (z out of the tip, as the fingertip chart
  ``c(a, b) = R (-cos a cos b, sin a, -cos a sin b)`` expects: ``b`` turns about y, ``a``
  towards y).

A body with several sphere collisions takes the one declared on the named link itself (or on
the link the named frame hangs from); otherwise the name is ambiguous and refused. A body with
no sphere collision is refused, naming the frame and its link.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin

from grasp_safety_filter.model.urdf import HandModelError


@dataclass(frozen=True)
class FingertipSphere:
    """The fingertip of one contact.

    Attributes:
        frame: The named frame (``model.fingertip_frames`` entry).
        link: The URDF link whose ``<collision><sphere>`` it is.
        radius: R_i, m.
        frame_id: Pinocchio frame at the sphere's centre with the named frame's axes.
    """

    frame: str
    link: str
    radius: float
    frame_id: int


def _link_of(model: pin.Model, frame_id: int) -> str:
    """Return the link a frame is, or the nearest link it hangs from (fixed joints, op frames)."""
    frame = model.frames[frame_id]
    while frame.type not in (pin.FrameType.BODY,) and frame.parentFrame != frame_id:
        frame_id = frame.parentFrame
        frame = model.frames[frame_id]
    return frame.name


def fingertip_spheres(
    model: pin.Model, urdf_path: Path, frame_names: list[str]
) -> list[FingertipSphere]:
    """Find each named frame's fingertip sphere; add a frame at its centre where needed.

    ``model`` gains an operational frame ``<name>/sphere_centre`` for a named frame whose
    origin is not the sphere's centre (placed on the same joint: the sphere's centre, the
    named frame's rotation); a frame already at the centre is used as it is.

    Raises:
        HandModelError: unknown frame, no or ambiguous sphere collision on its body, or a
            collision model Pinocchio cannot read.
    """
    try:
        geometry = pin.buildGeomFromUrdf(model, str(urdf_path), pin.GeometryType.COLLISION)
    except (RuntimeError, ValueError) as error:
        raise HandModelError(
            f'model.urdf_file: cannot read the collision model of {str(urdf_path)!r}: {error}'
        ) from None
    spheres = [
        item for item in geometry.geometryObjects if type(item.geometry).__name__ == 'Sphere'
    ]
    found = []
    for name in frame_names:
        if not model.existFrame(name):
            raise HandModelError(
                f'model.fingertip_frames: frame {name!r} is not in {urdf_path.name}'
            )
        frame_id = model.getFrameId(name)
        frame = model.frames[frame_id]
        link = _link_of(model, frame_id)
        on_body = [item for item in spheres if item.parentJoint == frame.parentJoint]
        if len(on_body) > 1:
            own = {frame_id, model.getFrameId(link)}
            on_body = [item for item in on_body if item.parentFrame in own] or on_body
        if not on_body:
            raise HandModelError(
                f'model.fingertip_frames: frame {name!r} (link {link!r}) has no '
                f'<collision><sphere> on its link or the links fixed to it in '
                f'{urdf_path.name}: expected the fingertip as a collision sphere (its radius and '
                "centre are the fingertip's)"
            )
        if len(on_body) > 1:
            links = sorted(model.frames[item.parentFrame].name for item in on_body)
            raise HandModelError(
                f'model.fingertip_frames: frame {name!r} (link {link!r}) has {len(on_body)} '
                f'collision spheres on its body (links {links}): expected one, or name the link '
                'that holds the fingertip sphere'
            )
        sphere = on_body[0]
        centre = np.array(sphere.placement.translation)
        if np.array_equal(centre, frame.placement.translation):
            tip_id = frame_id
        else:
            placement = pin.SE3(frame.placement.rotation, centre)
            tip_id = model.addFrame(
                pin.Frame(
                    f'{name}/sphere_centre',
                    frame.parentJoint,
                    frame_id,
                    placement,
                    pin.FrameType.OP_FRAME,
                )
            )
        found.append(
            FingertipSphere(
                frame=name,
                link=model.frames[sphere.parentFrame].name,
                radius=float(sphere.geometry.radius),
                frame_id=int(tip_id),
            )
        )
    return found
