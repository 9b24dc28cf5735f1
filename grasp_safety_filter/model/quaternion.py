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

import math

import numpy as np
import pinocchio as pin

from grasp_safety_filter.model.compiled import kernel


@kernel
def quaternion_derivative(quaternion_xyzw: np.ndarray, omega_in_palm: np.ndarray) -> np.ndarray:
    """Time derivative ``1/2 (0, omega) ⊗ q`` of an orientation quaternion.

    Compiled: the simulator evaluates it at every Runge–Kutta stage.

    Args:
        quaternion_xyzw: Orientation ``(x, y, z, w)``, shape (4,).
        omega_in_palm: Angular velocity in palm coordinates, shape (3,), rad/s.

    Returns:
        ``q_dot`` in the same ``(x, y, z, w)`` order, shape (4,), 1/s.

    """
    x, y, z, w = quaternion_xyzw[0], quaternion_xyzw[1], quaternion_xyzw[2], quaternion_xyzw[3]
    wx, wy, wz = omega_in_palm[0], omega_in_palm[1], omega_in_palm[2]
    rate = np.empty(4)
    rate[0] = 0.5 * (w * wx + wy * z - wz * y)
    rate[1] = 0.5 * (w * wy + wz * x - wx * z)
    rate[2] = 0.5 * (w * wz + wx * y - wy * x)
    rate[3] = 0.5 * -(wx * x + wy * y + wz * z)
    return rate


def normalized(quaternion_xyzw: np.ndarray) -> np.ndarray:
    """Return the unit quaternion ``q / |q|``; raise ValueError for a (near) zero one."""
    norm = float(np.linalg.norm(quaternion_xyzw))
    if not np.isfinite(norm) or norm < 1e-12:
        raise ValueError(
            f'quaternion: expected a non-zero finite quaternion, got {quaternion_xyzw}'
        )
    return np.asarray(quaternion_xyzw, dtype=float) / norm


def rotation_matrix(quaternion_xyzw: np.ndarray) -> np.ndarray:
    """Return the rotation matrix of a quaternion ``(x, y, z, w)`` (normalised first), (3, 3).

    Eigen's ``toRotationMatrix`` of the normalised quaternion, written out in floats (the
    simulator calls it at every Runge–Kutta stage, where a numpy and Pinocchio round trip
    would cost a few µs).

    Raises:
        ValueError: The quaternion is (near) zero or not finite.
    """
    quaternion = np.asarray(quaternion_xyzw, dtype=float)
    norm = math.sqrt(float(quaternion.dot(quaternion)))
    if not (math.isfinite(norm) and norm >= 1e-12):
        raise ValueError(
            f'quaternion: expected a non-zero finite quaternion, got {quaternion_xyzw}'
        )
    x, y, z, w = (quaternion / norm).tolist()
    tx, ty, tz = 2.0 * x, 2.0 * y, 2.0 * z
    twx, twy, twz = tx * w, ty * w, tz * w
    txx, txy, txz = tx * x, ty * x, tz * x
    tyy, tyz, tzz = ty * y, tz * y, tz * z
    return np.array(
        [
            [1.0 - (tyy + tzz), txy - twz, txz + twy],
            [txy + twz, 1.0 - (txx + tzz), tyz - twx],
            [txz - twy, tyz + twx, 1.0 - (txx + tyy)],
        ]
    )


def from_rotation_matrix(R: np.ndarray) -> np.ndarray:
    """Return the unit quaternion ``(x, y, z, w)``, ``w >= 0``, of a rotation matrix."""
    # Column-major: pinocchio 3 / eigenpy 3.13's Quaternion(matrix) leaks its copy of a
    # row-major matrix (80 bytes a call: once per tick in the simulator's odometry).
    quaternion = normalized(pin.Quaternion(np.asfortranarray(R, dtype=float)).coeffs())
    return quaternion if quaternion[3] >= 0.0 else -quaternion
