"""The grasped object: a rigid body with Newton–Euler dynamics in the palm frame.

    M_o x_o_ddot + C_o x_o_dot = G f_c + w_e,
    M_o = blkdiag(m I3, R I_body R^T),   C_o x_o_dot = (0, w × (R I_body R^T) w),
    w_e = (m g, 0)   (gravity at the centre of mass)

with ``x_o_dot = (v_o, w_o)``: centre-of-mass velocity and angular velocity, palm frame.
"""

from __future__ import annotations

import numpy as np

from grasp_safety_filter.model.arrays import read_only
from grasp_safety_filter.model.object_kernel import object_dynamics


class RigidObject:
    """Mass, inertia and contact surfaces of the grasped object.

    Args:
        mass: kg, > 0.
        inertia_in_body: Rotational inertia about the centre of mass, body frame, (3, 3),
            kg·m², symmetric positive definite.
        gravity: Gravity in the palm frame, (3,), m/s².
    """

    def __init__(self, mass: float, inertia_in_body: np.ndarray, gravity: np.ndarray) -> None:
        if not np.isfinite(mass) or mass <= 0.0:
            raise ValueError(f'model.object.mass: expected a positive mass in kg, got {mass!r}')
        inertia_in_body = np.ascontiguousarray(inertia_in_body, dtype=float)
        if inertia_in_body.shape != (3, 3) or not np.allclose(inertia_in_body, inertia_in_body.T):
            raise ValueError(
                f'object inertia: expected a symmetric (3, 3) matrix, got {inertia_in_body!r}'
            )
        if np.any(np.linalg.eigvalsh(inertia_in_body) <= 0.0):
            raise ValueError('object inertia: expected positive definite')
        self.mass = float(mass)
        self.inertia_in_body = inertia_in_body
        self.inverse_inertia_in_body = np.ascontiguousarray(np.linalg.inv(inertia_in_body))
        self.gravity = np.asarray(gravity, dtype=float)
        # An isotropic inertia c I (the cube's, the sphere's) is the same in every frame,
        # R (c I) R^T = c I, and has no gyroscopic torque, w × c w = 0: M_o, M_o^-1 and
        # C_o x_o_dot are then constants, computed once.
        self.isotropic = bool(np.all(inertia_in_body == inertia_in_body[0, 0] * np.eye(3)))
        #: ``blkdiag(mass I3, I_body)`` and ``blkdiag(I3 / mass, I_body^-1)``, (2, 6, 6),
        #: read-only: M_o and M_o^-1 in the body frame (the compiled grasp terms rotate them).
        self.mass_matrices_in_body = read_only(
            np.stack([
                self._block_diagonal(self.mass, inertia_in_body),
                self._block_diagonal(1.0 / self.mass, self.inverse_inertia_in_body),
            ])
        )
        self._M_o, self._M_o_inv = self.mass_matrices_in_body
        self._zero_wrench = read_only(np.zeros(6))
        self._external_wrench = read_only(np.concatenate([self.mass * self.gravity, np.zeros(3)]))

    @classmethod
    def cube(cls, mass: float, edge_length: float, gravity: np.ndarray) -> RigidObject:
        """Solid homogeneous cube: I = m a² / 6 I3."""
        if not np.isfinite(edge_length) or edge_length <= 0.0:
            raise ValueError(
                f'model.object.size: expected a positive edge length in m, got {edge_length!r}'
            )
        return cls(mass, mass * edge_length**2 / 6.0 * np.eye(3), gravity)

    @classmethod
    def sphere(cls, mass: float, diameter: float, gravity: np.ndarray) -> RigidObject:
        """Solid homogeneous sphere: I = 2/5 m r² I3."""
        if not np.isfinite(diameter) or diameter <= 0.0:
            raise ValueError(
                f'model.object.size: expected a positive diameter in m, got {diameter!r}'
            )
        radius = 0.5 * diameter
        return cls(mass, 0.4 * mass * radius**2 * np.eye(3), gravity)

    @staticmethod
    def _block_diagonal(linear: float, rotational: np.ndarray) -> np.ndarray:
        """``blkdiag(linear I3, rotational)``, (6, 6)."""
        matrix = np.zeros((6, 6))
        matrix[:3, :3] = linear * np.eye(3)
        matrix[3:, 3:] = rotational
        return matrix

    def dynamics(
        self, R_object_to_palm: np.ndarray, twist: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """``(M_o, M_o^-1, C_o x_o_dot)`` in palm coordinates, (6, 6), (6, 6), (6,), read-only.

        :func:`~grasp_safety_filter.model.object_kernel.object_dynamics` at the orientation
        ``R_object_to_palm`` and twist ``(v_o, w_o)`` (m/s, rad/s); shared constants if the
        inertia is isotropic.
        """
        if self.isotropic:
            return self._M_o, self._M_o_inv, self._zero_wrench
        terms = object_dynamics(
            self.mass_matrices_in_body,
            False,
            np.ascontiguousarray(R_object_to_palm, dtype=float),
            np.ascontiguousarray(twist, dtype=float),
        )
        return read_only(terms[0]), read_only(terms[1]), read_only(terms[2])

    def external_wrench(self) -> np.ndarray:
        """``w_e``: gravity at the centre of mass, (6,) (a shared read-only array)."""
        return self._external_wrench

    def energy(
        self, p_object_in_palm: np.ndarray, R_object_to_palm: np.ndarray, twist: np.ndarray
    ) -> float:
        """Kinetic plus gravitational potential energy, J."""
        v, w = twist[:3], twist[3:]
        inertia = R_object_to_palm @ self.inertia_in_body @ R_object_to_palm.T
        kinetic = 0.5 * self.mass * v @ v + 0.5 * w @ inertia @ w
        return float(kinetic - self.mass * self.gravity @ p_object_in_palm)
