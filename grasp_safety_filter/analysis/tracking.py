"""Object tracking: the object's pose against the reference the nominal controller tracked.

The object pose is read from ``/object/odom``, the reference from
``/object/reference_sample`` (the sample the nominal controller used on each tick, stamped
as the tick; recorded since that topic exists). The two are paired by stamp. Per pair:

- position error ``e_p = |p_object_in_palm - p_reference_in_palm|``, m;
- orientation error ``e_R = angle(R_reference^T R_object)``, the rotation angle between
  the two orientations, rad in [0, pi] (``arccos((tr - 1) / 2)``).

A bag without the reference topic (recorded before it existed, or a graph without the
nominal controller) still gives the object pose; its errors are None and the summary and
figure say :data:`NO_REFERENCE`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from grasp_safety_filter.analysis.columns import Column
from grasp_safety_filter.control.pose_error import euler_from_matrix
from grasp_safety_filter.io import topics
from grasp_safety_filter.io.messages import header_stamp_ns, odometry_from_msg

#: What the summary and the figure say when a bag has no reference samples.
NO_REFERENCE = 'no reference recorded'

#: The topics :class:`TrackingReader` reads.
TRACKING_TOPICS = (topics.OBJECT_ODOM, topics.OBJECT_REFERENCE_SAMPLE)


def rotation_angle(R_a_to_palm: np.ndarray, R_b_to_palm: np.ndarray) -> np.ndarray:
    """Angle of the rotation between orientations, rad in [0, pi].

    Args:
        R_a_to_palm: Rotations, shape (K, 3, 3).
        R_b_to_palm: Rotations, shape (K, 3, 3).

    Returns:
        ``angle(R_b^T R_a)`` per row, shape (K,).

    """
    # trace(R_b^T R_a) = sum of the elementwise product.
    trace = np.einsum('kij,kij->k', R_b_to_palm, R_a_to_palm)
    return np.arccos(np.clip(0.5 * (trace - 1.0), -1.0, 1.0))


def unwrapped_euler(R_to_palm: np.ndarray) -> np.ndarray:
    """ZYX Euler angles ``(roll, pitch, yaw)`` per row, each unwrapped over time, rad (K, 3).

    Unwrapped so that a yaw that runs past pi (the paper's reference reaches -4 rad) is drawn
    as one continuous line.
    """
    if not len(R_to_palm):
        return np.zeros((0, 3))
    angles = np.array([euler_from_matrix(R) for R in R_to_palm])
    return np.unwrap(angles, axis=0)


@dataclass(frozen=True)
class ObjectTracking:
    """The object's pose and its reference over a run, palm frame.

    Attributes:
        t: Object pose stamps, shape (K,), s.
        p_object_in_palm: Object position, shape (K, 3), m.
        R_object_to_palm: Object orientation, shape (K, 3, 3).
        t_reference: Stamps with both a pose and a reference sample, shape (L,), s.
        p_reference_in_palm: Reference position at ``t_reference``, (L, 3), m.
        R_reference_to_palm: Reference orientation at ``t_reference``, (L, 3, 3).
        position_error: ``|p_object - p_reference|`` at ``t_reference``, (L,), m.
        orientation_error: Rotation angle between them at ``t_reference``, (L,), rad.

    """

    t: np.ndarray
    p_object_in_palm: np.ndarray
    R_object_to_palm: np.ndarray
    t_reference: np.ndarray
    p_reference_in_palm: np.ndarray
    R_reference_to_palm: np.ndarray
    position_error: np.ndarray
    orientation_error: np.ndarray

    @property
    def has_reference(self) -> bool:
        """True when at least one reference sample pairs with an object pose."""
        return bool(len(self.t_reference))

    def summary(self) -> dict[str, Any]:
        """Return ``{"reference", "samples", "position_error_m", "orientation_error_rad"}``.

        Each error is ``{"rms", "max", "final"}`` over the paired samples; without a
        reference ``reference`` is :data:`NO_REFERENCE` and the errors are None.
        """
        if not self.has_reference:
            return {
                'reference': NO_REFERENCE,
                'samples': 0,
                'position_error_m': None,
                'orientation_error_rad': None,
            }

        def stats(error: np.ndarray) -> dict[str, float]:
            return {
                'rms': float(np.sqrt(np.mean(error**2))),
                'max': float(error.max()),
                'final': float(error[-1]),
            }

        return {
            'reference': topics.OBJECT_REFERENCE_SAMPLE,
            'samples': len(self.t_reference),
            'position_error_m': stats(self.position_error),
            'orientation_error_rad': stats(self.orientation_error),
        }


class TrackingReader:
    """Collects object poses and reference samples as the bag streams (module docstring)."""

    def __init__(self) -> None:
        self.frames: tuple[str, str] | None = None
        self.stamps = {name: Column((), np.int64) for name in TRACKING_TOPICS}
        self.p = {name: Column((3,)) for name in TRACKING_TOPICS}
        self.R = {name: Column((3, 3)) for name in TRACKING_TOPICS}

    def add(self, topic: str, msg: Any) -> None:
        """Read one ``/object/odom`` or ``/object/reference_sample`` message.

        The frames are those of the first message read (every hand names its own palm and
        object frames); a later message in other frames is rejected.
        """
        if self.frames is None:
            self.frames = (str(msg.header.frame_id), str(msg.child_frame_id))
        data = odometry_from_msg(msg, *self.frames, source=topic)
        self.stamps[topic].append(header_stamp_ns(msg))
        self.p[topic].append(data.p_object_in_palm)
        self.R[topic].append(data.R_object_to_palm)

    def _by_stamp(self, topic: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Distinct stamps in order (the last message of a stamp), positions, rotations."""
        stamps = self.stamps[topic].array()
        p = self.p[topic].array().reshape(-1, 3)
        R = self.R[topic].array().reshape(-1, 3, 3)
        _, last_reversed = np.unique(stamps[::-1], return_index=True)
        rows = len(stamps) - 1 - last_reversed
        return stamps[rows], p[rows], R[rows]

    def finish(self) -> ObjectTracking | None:
        """Pair poses and references by stamp; None without any object pose."""
        stamps, p, R = self._by_stamp(topics.OBJECT_ODOM)
        if not len(stamps):
            return None
        ref_stamps, ref_p, ref_R = self._by_stamp(topics.OBJECT_REFERENCE_SAMPLE)
        common, in_pose, in_ref = np.intersect1d(
            stamps, ref_stamps, assume_unique=True, return_indices=True
        )
        return ObjectTracking(
            t=stamps.astype(float) * 1e-9,
            p_object_in_palm=p,
            R_object_to_palm=R,
            t_reference=common.astype(float) * 1e-9,
            p_reference_in_palm=ref_p[in_ref],
            R_reference_to_palm=ref_R[in_ref],
            position_error=np.linalg.norm(p[in_pose] - ref_p[in_ref], axis=1),
            orientation_error=rotation_angle(R[in_pose], ref_R[in_ref]),
        )


def tracking_text(entry: dict[str, Any]) -> str:
    """Return the report line of a summary's ``object_tracking`` entry."""
    position, orientation = entry['position_error_m'], entry['orientation_error_rad']
    if position is None or orientation is None:
        return f'object tracking: {NO_REFERENCE}'
    return (
        'object tracking error (RMS / max / final): position '
        f'{position["rms"]:.4g} / {position["max"]:.4g} / {position["final"]:.4g} m, '
        f'orientation {orientation["rms"]:.4g} / {orientation["max"]:.4g} / '
        f'{orientation["final"]:.4g} rad'
    )
