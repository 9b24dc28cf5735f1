"""The MarkerArray message of marker specs (:mod:`~grasp_safety_filter.view.markers`)."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from grasp_safety_filter.io.messages.namespace import MessageNamespace
from grasp_safety_filter.io.messages.stamps import duration_to_msg, header_msg, Stamp

#: ``visualization_msgs/Marker`` types by the specs' kinds.
MARKER_TYPES = {
    'arrow': 0,
    'cube': 1,
    'sphere': 2,
    'cylinder': 3,
    'line_list': 5,
    'sphere_list': 7,
    'text': 9,
    'triangle_list': 11,
}
ADD = 0


def _points(msgs: MessageNamespace, points: np.ndarray) -> list[Any]:
    return [msgs.Point(x=float(x), y=float(y), z=float(z)) for x, y, z in points]


def _color(msgs: MessageNamespace, rgba: Sequence[float]) -> Any:
    r, g, b, a = (float(c) for c in rgba)
    return msgs.ColorRGBA(r=r, g=g, b=b, a=a)


class MarkerArrayBuilder:
    """Builds ``MarkerArray`` messages, each spec a marker in ``frame_id``, added.

    A marker message is made once per namespace and id and then updated in place: building
    one costs a Python message class most of its time in the sub-messages it makes anew,
    and a viewer's update changes only poses, points and colours. A spec whose points are
    the array of the marker's last update (a cone in its contact frame) keeps its points
    messages. The markers never expire
    (``lifetime`` 0): each update replaces them by namespace and id.

    Args:
        msgs: Message classes to build.
        frame_id: The markers' frame.
    """

    def __init__(self, msgs: MessageNamespace, frame_id: str) -> None:
        self.msgs = msgs
        self.frame_id = frame_id
        self._markers: dict[tuple[str, int], Any] = {}
        self._points: dict[tuple[str, int], np.ndarray] = {}  # the arrays they were built of

    def _new(self, ns: str, index: int) -> Any:
        msgs = self.msgs
        empty = [] if msgs.sequences_as_lists else np.zeros(0, dtype=np.uint8)  # uint8[]
        no_time = header_msg(msgs, 0, '')
        return msgs.Marker(
            header=header_msg(msgs, 0, self.frame_id),
            ns=ns,
            id=index,
            type=0,
            action=ADD,
            pose=msgs.Pose(position=msgs.Point(x=0.0, y=0.0, z=0.0),
                           orientation=msgs.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0)),
            scale=msgs.Vector3(x=1.0, y=1.0, z=1.0),
            color=_color(msgs, (0.0, 0.0, 0.0, 1.0)),
            lifetime=duration_to_msg(msgs, 0.0),
            frame_locked=False,
            points=[],
            colors=[],
            texture_resource='',
            texture=msgs.CompressedImage(header=no_time, format='', data=empty),
            uv_coordinates=[],
            text='',
            mesh_resource='',
            mesh_file=msgs.MeshFile(filename='', data=empty),
            mesh_use_embedded_materials=False,
        )  # fmt: skip

    def build(self, t: Stamp, specs: Sequence[Any]) -> Any:
        """Return the ``MarkerArray`` of ``specs``, stamped ``t``."""
        msgs = self.msgs
        stamp = header_msg(msgs, t, self.frame_id).stamp
        markers = []
        for spec in specs:
            key = (spec.ns, int(spec.id))
            marker = self._markers.get(key)
            if marker is None:
                marker = self._markers[key] = self._new(*key)
            marker.header.stamp = stamp
            marker.type = MARKER_TYPES[spec.kind]
            position, orientation = marker.pose.position, marker.pose.orientation
            position.x, position.y, position.z = (float(c) for c in spec.position)
            q = orientation
            q.x, q.y, q.z, q.w = (float(c) for c in spec.quaternion)
            marker.scale.x, marker.scale.y, marker.scale.z = (float(c) for c in spec.scale)
            colour = marker.color
            colour.r, colour.g, colour.b, colour.a = (float(c) for c in spec.rgba)
            if self._points.get(key) is not spec.points:
                marker.points = _points(msgs, spec.points)
                self._points[key] = spec.points
            marker.colors = [_color(msgs, c) for c in spec.colors]
            marker.text = spec.text
            markers.append(marker)
        return msgs.MarkerArray(markers=markers)
