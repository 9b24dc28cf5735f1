"""ZYX Euler coordinates of the object pose, compiled: the operations of one control tick.

The compiled counterparts of :mod:`grasp_safety_filter.control.pose_error` (which states the
convention: ``R = R_z(yaw) R_y(pitch) R_x(roll)``, ``w_palm = E(phi) phi_dot``), written with
the same floating-point operations in the same order as the libraries they replace, so their
results are equal to the last bit:

- :func:`euler_angles` is Pinocchio's ``rpy.matrixToRpy``: Eigen's ``eulerAngles(2, 1, 0)``
  (Graphics Gems IV), reversed, with pitch brought into [-pi/2, pi/2];
- E, E^-1 and dE/dt are Pinocchio's ``computeRpyJacobian``, ``...Inverse`` and
  ``...TimeDerivative`` in the ``WORLD`` frame; their products with vectors are ``np.dot``
  of C-ordered 3 × 3 matrices, BLAS's gemv as numpy's ``@`` calls it (a plain loop would
  not round as BLAS does; test/test_nominal_kernel.py checks the equality);
- :func:`wrap_angle` is the same ``remainder`` (numba's is numpy's).

Angles in rad, rates in rad/s, accelerations in rad/s².
"""

from __future__ import annotations

import math

import numpy as np

from grasp_safety_filter.model.compiled import kernel

_PI = math.pi


@kernel
def wrap_angle(angle: float) -> float:
    """Wrap an angle to ``(-pi, pi]``, rad."""
    remainder = np.remainder(angle + _PI, 2.0 * _PI)
    wrapped = remainder - _PI
    # remainder maps +pi to -pi; keep the interval closed on the right.
    return _PI if wrapped == -_PI else wrapped


@kernel
def euler_angles(R: np.ndarray, out: np.ndarray) -> None:
    """``out = (roll, pitch, yaw)`` of the rotation matrix R (3, 3), rad.

    Roll and yaw in [-pi, pi], pitch in [-pi/2, pi/2].
    """
    # Eigen's eulerAngles(2, 1, 0), Tait-Bryan branch with i = 2, j = 1, k = 0, odd = 1.
    a0 = math.atan2(R[1, 0], R[0, 0])
    c2 = math.sqrt(R[2, 2] * R[2, 2] + R[2, 1] * R[2, 1])
    if a0 < 0.0:
        a0 += _PI
        a1 = math.atan2(-R[2, 0], -c2)
    else:
        a1 = math.atan2(-R[2, 0], c2)
    s1 = math.sin(a0)
    c1 = math.cos(a0)
    a2 = math.atan2(s1 * R[0, 2] - c1 * R[1, 2], c1 * R[1, 1] - s1 * R[0, 1])
    roll, pitch, yaw = a2, a1, a0
    if pitch < -_PI / 2:
        pitch += 2 * _PI
    if pitch > _PI / 2:
        pitch = _PI - pitch
        if roll < 0.0:
            roll += _PI
        else:
            roll -= _PI
        yaw -= _PI
    out[0] = roll
    out[1] = pitch
    out[2] = yaw


@kernel
def rate_jacobian(phi: np.ndarray) -> np.ndarray:
    """E(phi), (3, 3): Euler-angle rates ↦ angular velocity in palm coordinates."""
    sp, cp = math.sin(phi[1]), math.cos(phi[1])
    sy, cy = math.sin(phi[2]), math.cos(phi[2])
    E = np.zeros((3, 3))
    E[0, 0] = cp * cy
    E[0, 1] = -sy
    E[1, 0] = cp * sy
    E[1, 1] = cy
    E[2, 0] = -sp
    E[2, 2] = 1.0
    return E


@kernel
def rate_jacobian_inverse(phi: np.ndarray) -> np.ndarray:
    """E(phi)^-1, (3, 3), in closed form (singular at pitch = ±pi/2)."""
    sp, cp = math.sin(phi[1]), math.cos(phi[1])
    tp = sp / cp
    sy, cy = math.sin(phi[2]), math.cos(phi[2])
    E_inv = np.zeros((3, 3))
    E_inv[0, 0] = cy / cp
    E_inv[0, 1] = sy / cp
    E_inv[1, 0] = -sy
    E_inv[1, 1] = cy
    E_inv[2, 0] = cy * tp
    E_inv[2, 1] = sy * tp
    E_inv[2, 2] = 1.0
    return E_inv


@kernel
def rate_jacobian_dot(phi: np.ndarray, phi_dot: np.ndarray) -> np.ndarray:
    """dE/dt along ``phi_dot``, (3, 3), 1/s."""
    sp, cp = math.sin(phi[1]), math.cos(phi[1])
    sy, cy = math.sin(phi[2]), math.cos(phi[2])
    dp, dy = phi_dot[1], phi_dot[2]
    E_dot = np.zeros((3, 3))
    E_dot[0, 0] = -sp * cy * dp - cp * sy * dy
    E_dot[0, 1] = -cy * dy
    E_dot[1, 0] = cp * cy * dy - sp * sy * dp
    E_dot[1, 1] = -sy * dy
    E_dot[2, 0] = -cp * dp
    return E_dot


@kernel
def euler_rates(phi: np.ndarray, twist: np.ndarray, out: np.ndarray) -> None:
    """``out = P(phi)^-1 x_dot = (v, E^-1 w)``, (6,), from the twist ``(v, w)``."""
    out[:3] = twist[:3]
    out[3:] = np.dot(rate_jacobian_inverse(phi), np.ascontiguousarray(twist[3:]))


@kernel
def twist(phi: np.ndarray, r_dot: np.ndarray, out: np.ndarray) -> None:
    """``out = P(phi) r_dot = (v, E phi_dot)``, (6,)."""
    out[:3] = r_dot[:3]
    out[3:] = np.dot(rate_jacobian(phi), np.ascontiguousarray(r_dot[3:]))


@kernel
def acceleration(
    phi: np.ndarray, r_dot: np.ndarray, r_ddot: np.ndarray, out: np.ndarray
) -> None:
    """``out = P r_ddot + P_dot r_dot = (a, E phi_ddot + E_dot phi_dot)``, (6,)."""
    phi_dot = np.ascontiguousarray(r_dot[3:])
    alpha = np.dot(rate_jacobian(phi), np.ascontiguousarray(r_ddot[3:]))
    alpha += np.dot(rate_jacobian_dot(phi, phi_dot), phi_dot)
    out[:3] = r_ddot[:3]
    out[3:] = alpha


@kernel
def euler_accelerations(
    phi: np.ndarray, r_dot: np.ndarray, acceleration_: np.ndarray, out: np.ndarray
) -> None:
    """``out = P^-1 (x_ddot - P_dot r_dot)``, (6,): the inverse of :func:`acceleration`."""
    phi_dot = np.ascontiguousarray(r_dot[3:])
    alpha_from_rates = np.dot(rate_jacobian_dot(phi, phi_dot), phi_dot)
    alpha = np.ascontiguousarray(acceleration_[3:]) - alpha_from_rates
    out[:3] = acceleration_[:3]
    out[3:] = np.dot(rate_jacobian_inverse(phi), alpha)


@kernel
def pose_error(r_reference: np.ndarray, r_object: np.ndarray, out: np.ndarray) -> None:
    """``out = r_reference - r_object``, (6,), the angle differences wrapped to (-pi, pi]."""
    for i in range(3):
        out[i] = r_reference[i] - r_object[i]
    for i in range(3, 6):
        out[i] = wrap_angle(r_reference[i] - r_object[i])
