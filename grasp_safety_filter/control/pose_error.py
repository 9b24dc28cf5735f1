"""Object pose in ZYX Euler coordinates: conversions, rate maps and the tracking error.

The computed-torque controller of Cole, Hauser & Sastry (1989) tracks the object pose in
*Euler coordinates* ``r = (x, y, z, roll, pitch, yaw)``: the centre-of-mass position in the
palm frame and the ZYX Euler angles of ``R_object_to_palm = R_z(yaw) R_y(pitch) R_x(roll)``
(extrinsic rotations about the palm axes X, then Y, then Z: yaw turns the object about the
palm Z axis). Pinocchio's :mod:`pinocchio.rpy` provides this convention; its Jacobian in the
``WORLD`` reference frame maps Euler-angle rates to the angular velocity in palm coordinates,
which is how :class:`~grasp_safety_filter.model.grasp_state.GraspState` expresses twists:

    w_palm = E(phi) phi_dot,      E = computeRpyJacobian(phi, WORLD)
    x_o_dot = P(phi) r_dot,       P = blkdiag(I3, E(phi))   (the paper's P)

E is singular at pitch = ±pi/2 (gimbal lock); the controller is not defined there.

The functions check their arguments' shapes and call Pinocchio's.
"""

from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
from pinocchio import rpy


def _array(function: str, name: str, value: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """``value`` as a float array of ``shape``; ValueError naming it otherwise."""
    array = np.asarray(value, dtype=float)
    if array.shape != shape:
        raise ValueError(f'{function}: {name}: expected shape {shape}, got {array.shape}')
    return array


def wrap_angle(angle: np.ndarray | float) -> np.ndarray:
    """Wrap angles to ``(-pi, pi]``, elementwise, rad."""
    wrapped = np.remainder(np.asarray(angle, dtype=float) + math.pi, 2.0 * math.pi) - math.pi
    # remainder maps +pi to -pi; keep the interval closed on the right.
    return np.where(wrapped == -math.pi, math.pi, wrapped)


def euler_from_matrix(R: np.ndarray) -> np.ndarray:
    """ZYX Euler angles ``(roll, pitch, yaw)`` of a rotation matrix, rad.

    ``R = R_z(yaw) R_y(pitch) R_x(roll)`` with roll, yaw in [-pi, pi], pitch in [-pi/2, pi/2]
    (Pinocchio's ``rpy.matrixToRpy``).
    """
    return np.asarray(rpy.matrixToRpy(_array('euler_from_matrix', 'R', R, (3, 3))), dtype=float)


def matrix_from_euler(phi: np.ndarray) -> np.ndarray:
    """Rotation matrix ``R_z(yaw) R_y(pitch) R_x(roll)`` of ``phi = (roll, pitch, yaw)``."""
    return np.asarray(rpy.rpyToMatrix(np.asarray(phi, dtype=float)), dtype=float)


def euler_rate_jacobian(phi: np.ndarray) -> np.ndarray:
    """E(phi), shape (3, 3): Euler-angle rates ↦ angular velocity in the palm frame.

    ``w_palm = E(phi) phi_dot`` with
    ``E = [[cp cy, -sy, 0], [cp sy, cy, 0], [-sp, 0, 1]]`` (p = pitch, y = yaw).
    """
    phi = _array('euler_rate_jacobian', 'phi', phi, (3,))
    return np.asarray(rpy.computeRpyJacobian(phi, pin.WORLD))


def euler_rate_jacobian_dot(phi: np.ndarray, phi_dot: np.ndarray) -> np.ndarray:
    """Time derivative ``dE/dt`` along ``phi_dot``, shape (3, 3), 1/s."""
    phi = _array('euler_rate_jacobian_dot', 'phi', phi, (3,))
    phi_dot = _array('euler_rate_jacobian_dot', 'phi_dot', phi_dot, (3,))
    return np.asarray(rpy.computeRpyJacobianTimeDerivative(phi, phi_dot, pin.WORLD))


def euler_rates_from_angular_velocity(phi: np.ndarray, w_palm: np.ndarray) -> np.ndarray:
    """``phi_dot = E(phi)^-1 w_palm``, rad/s (closed-form inverse; singular at gimbal lock)."""
    name = 'euler_rates_from_angular_velocity'
    phi = _array(name, 'phi', phi, (3,))
    E_inv = np.asarray(rpy.computeRpyJacobianInverse(phi, pin.WORLD))
    return E_inv @ _array(name, 'w_palm', w_palm, (3,))


def twist_from_euler(phi: np.ndarray, r_dot: np.ndarray) -> np.ndarray:
    """Twist ``x_dot = P(phi) r_dot = (v, E(phi) phi_dot)``, shape (6,)."""
    r_dot = _array('twist_from_euler', 'r_dot', r_dot, (6,))
    return np.concatenate((r_dot[:3], euler_rate_jacobian(phi) @ r_dot[3:]))


def euler_rates_from_twist(phi: np.ndarray, twist: np.ndarray) -> np.ndarray:
    """Euler-coordinate rates ``r_dot = P(phi)^-1 x_dot = (v, E^-1 w)``, shape (6,)."""
    twist = _array('euler_rates_from_twist', 'twist', twist, (6,))
    return np.concatenate((twist[:3], euler_rates_from_angular_velocity(phi, twist[3:])))


def acceleration_from_euler(phi: np.ndarray, r_dot: np.ndarray, r_ddot: np.ndarray) -> np.ndarray:
    """Acceleration ``x_ddot = P r_ddot + P_dot r_dot = (a, E phi_ddot + E_dot phi_dot)``.

    ``a`` is the centre-of-mass acceleration and ``alpha = w_dot`` the angular acceleration,
    both in palm coordinates, shape (6,).
    """
    name = 'acceleration_from_euler'
    r_dot = _array(name, 'r_dot', r_dot, (6,))
    r_ddot = _array(name, 'r_ddot', r_ddot, (6,))
    alpha = euler_rate_jacobian(phi) @ r_ddot[3:]
    alpha += euler_rate_jacobian_dot(phi, r_dot[3:]) @ r_dot[3:]
    return np.concatenate((r_ddot[:3], alpha))


def euler_accelerations_from_acceleration(
    phi: np.ndarray, r_dot: np.ndarray, acceleration: np.ndarray
) -> np.ndarray:
    """Inverse of :func:`acceleration_from_euler`: ``r_ddot = P^-1 (x_ddot - P_dot r_dot)``."""
    name = 'euler_accelerations_from_acceleration'
    r_dot = _array(name, 'r_dot', r_dot, (6,))
    acceleration = _array(name, 'acceleration', acceleration, (6,))
    alpha = acceleration[3:] - euler_rate_jacobian_dot(phi, r_dot[3:]) @ r_dot[3:]
    return np.concatenate((acceleration[:3], euler_rates_from_angular_velocity(phi, alpha)))


def euler_pose_error(r_reference: np.ndarray, r_object: np.ndarray) -> np.ndarray:
    """Tracking error ``e = r_reference - r_object`` in Euler coordinates, shape (6,).

    Position error in m; the angle differences are wrapped to ``(-pi, pi]``, rad. Euler
    vectors that differ by 2 pi in any angle describe the same rotation, and
    :func:`euler_from_matrix` returns the object's angles in their principal range, so the
    raw difference jumps by 2 pi whenever the object (or a reference such as the paper's
    yaw of 2 (cos t - 1), which reaches -4 rad) crosses ±pi. Wrapping removes exactly those
    jumps: while the true tracking error stays below pi in magnitude, the wrapped difference
    *is* the continuous difference of the two continuous Euler trajectories, whichever
    2 pi branch either is reported on. The error rate and the maps ``P``, ``P_dot`` depend
    only on pitch and yaw through sines and cosines, so they need no unwrapping.
    """
    error = _array('euler_pose_error', 'r_reference', r_reference, (6,)) - _array(
        'euler_pose_error', 'r_object', r_object, (6,)
    )
    error[3:] = wrap_angle(error[3:])
    return error
