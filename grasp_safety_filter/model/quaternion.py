"""Unit-quaternion orientation kinematics, quaternions stored ``(x, y, z, w)`` (ROS order).

The object's orientation ``R_object_to_palm`` is integrated as a unit quaternion
``q = (v, w)`` (vector part v, scalar part w) with the angular velocity ``omega`` in palm
coordinates (a spatial angular velocity, ``R_dot = [omega]x R``):

    q_dot = 1/2 (0, omega) ⊗ q,   i.e.   v_dot = 1/2 (w omega + omega × v),
                                          w_dot = -1/2 omega · v

A Runge–Kutta step does not keep ``|q| = 1`` exactly (the drift is of the order of the
local truncation error), so the simulator renormalises after every step; this projection
does not lower the method's order. Rotation matrices are computed from the normalised
quaternion, so intermediate stages need not be unit.
"""

from __future__ import annotations

import numpy as np


def quaternion_derivative(quaternion_xyzw: np.ndarray, omega_in_palm: np.ndarray) -> np.ndarray:
    """Time derivative ``1/2 (0, omega) ⊗ q`` of an orientation quaternion.

    Args:
        quaternion_xyzw: Orientation ``(x, y, z, w)``, shape (4,).
        omega_in_palm: Angular velocity in palm coordinates, shape (3,), rad/s.

    Returns:
        ``q_dot`` in the same ``(x, y, z, w)`` order, shape (4,), 1/s.

    """
    x, y, z, w = quaternion_xyzw
    wx, wy, wz = omega_in_palm
    # Written out: np.cross costs more than the rest of a simulator stage's bookkeeping.
    return 0.5 * np.array(
        [
            w * wx + wy * z - wz * y,
            w * wy + wz * x - wx * z,
            w * wz + wx * y - wy * x,
            -(wx * x + wy * y + wz * z),
        ]
    )


def normalized(quaternion_xyzw: np.ndarray) -> np.ndarray:
    """Return the unit quaternion ``q / |q|``; raise ValueError for a (near) zero one."""
    norm = float(np.linalg.norm(quaternion_xyzw))
    if not np.isfinite(norm) or norm < 1e-12:
        raise ValueError(
            f'quaternion: expected a non-zero finite quaternion, got {quaternion_xyzw}'
        )
    return np.asarray(quaternion_xyzw, dtype=float) / norm


def rotation_matrix(quaternion_xyzw: np.ndarray) -> np.ndarray:
    """Return the rotation matrix of a quaternion ``(x, y, z, w)`` (normalised first), (3, 3)."""
    x, y, z, w = normalized(quaternion_xyzw)
    return np.array(
        [
            [1.0 - 2.0 * (y * y + z * z), 2.0 * (x * y - z * w), 2.0 * (x * z + y * w)],
            [2.0 * (x * y + z * w), 1.0 - 2.0 * (x * x + z * z), 2.0 * (y * z - x * w)],
            [2.0 * (x * z - y * w), 2.0 * (y * z + x * w), 1.0 - 2.0 * (x * x + y * y)],
        ]
    )


def from_rotation_matrix(R: np.ndarray) -> np.ndarray:
    """Return the unit quaternion ``(x, y, z, w)``, ``w >= 0``, of a rotation (Shepperd)."""
    R = np.asarray(R, dtype=float)
    trace = R[0, 0] + R[1, 1] + R[2, 2]
    # Pick the largest of 4w², 4x², 4y², 4z² as the pivot for numerical robustness.
    pivots = np.array([trace, R[0, 0], R[1, 1], R[2, 2]])
    k = int(np.argmax(pivots))
    if k == 0:
        s = 2.0 * np.sqrt(1.0 + trace)
        quaternion = [
            (R[2, 1] - R[1, 2]) / s,
            (R[0, 2] - R[2, 0]) / s,
            (R[1, 0] - R[0, 1]) / s,
            0.25 * s,
        ]
    elif k == 1:
        s = 2.0 * np.sqrt(1.0 + R[0, 0] - R[1, 1] - R[2, 2])
        quaternion = [
            0.25 * s,
            (R[0, 1] + R[1, 0]) / s,
            (R[0, 2] + R[2, 0]) / s,
            (R[2, 1] - R[1, 2]) / s,
        ]
    elif k == 2:
        s = 2.0 * np.sqrt(1.0 - R[0, 0] + R[1, 1] - R[2, 2])
        quaternion = [
            (R[0, 1] + R[1, 0]) / s,
            0.25 * s,
            (R[1, 2] + R[2, 1]) / s,
            (R[0, 2] - R[2, 0]) / s,
        ]
    else:
        s = 2.0 * np.sqrt(1.0 - R[0, 0] - R[1, 1] + R[2, 2])
        quaternion = [
            (R[0, 2] + R[2, 0]) / s,
            (R[1, 2] + R[2, 1]) / s,
            0.25 * s,
            (R[1, 0] - R[0, 1]) / s,
        ]
    result = normalized(np.array(quaternion))
    return result if result[3] >= 0.0 else -result
