"""Random, physically consistent GraspState objects for testing the control layer.

A hand of n fingers with ``joints_per_finger`` joints each grasps a box-like object whose
centre of mass is near the palm origin. The contacts sit around the object, roughly in a
horizontal plane, with their contact-frame z axis pointing into the object, so a squeezing
grasp that holds the object against gravity exists. Every affine map is derived from the same
random dynamics:

    B_ho f_c = J_h M_h^-1 (u - h_bias) + Jh_dot_dq - G_dot_T_twist + G^T M_o^-1 (C_o_twist - w_e)
    ddq      = M_h^-1 (u - h_bias - J_h^T f_c)
    x_o_ddot = M_o^-1 (G f_c + w_e - C_o_twist)
    xi_cf_ddot,i = H_i (alpha_f,i - alpha_o) + c_i     (alpha: angular accelerations)
    xi_co_ddot,i = R_psi,i M_cf,i xi_cf_ddot,i           (a sphere rolling on a face, bias 0)

so ``J_h ddq + Jh_dot_dq = G^T x_o_ddot + G_dot_T_twist`` holds for every u (the rolling
constraint, differentiated). Velocity-dependent terms scale with ``speed``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.grasp_state import GraspState

GRAVITY = 9.81
FINGERTIP_RADIUS = 0.06
OBJECT_HALF_EDGE = 0.13
PAPER_WORKSPACE = (-np.pi / 2, np.pi / 2, -np.pi, 0.0)


@dataclass
class SyntheticHand:
    """The attributes SafetyFilter.from_config reads from a grasp model."""

    n_fingers: int = 3
    joints_per_finger: int = 3
    friction_coefficient: float = 0.9
    torsional_friction: None = None  # point contacts
    effort: float = 5.0
    fingertip_workspace: tuple[float, float, float, float] = PAPER_WORKSPACE
    object_mass: float = 0.11
    joint_names: tuple[str, ...] = field(init=False)
    contact_names: tuple[str, ...] = field(init=False)
    joint_lower_limits: np.ndarray = field(init=False)
    joint_upper_limits: np.ndarray = field(init=False)
    effort_limits: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        self.contact_names = tuple(f'finger{i + 1}' for i in range(self.n_fingers))
        self.joint_names = tuple(
            f'{finger}_joint{j + 1}'
            for finger in self.contact_names
            for j in range(self.joints_per_finger)
        )
        lower = np.array([0.0, -np.pi / 3, 0.0] * self.n_fingers)[: self.n_joints]
        upper = np.array([1.5 * np.pi, np.pi / 3, 1.5 * np.pi] * self.n_fingers)[: self.n_joints]
        self.joint_lower_limits = lower
        self.joint_upper_limits = upper
        self.effort_limits = np.full(self.n_joints, self.effort)

    @property
    def n_joints(self) -> int:
        return self.n_fingers * self.joints_per_finger


def random_rotation(rng: np.random.Generator) -> np.ndarray:
    Q, R = np.linalg.qr(rng.normal(size=(3, 3)))
    Q = Q * np.sign(np.diag(R))
    if np.linalg.det(Q) < 0:
        Q[:, 0] = -Q[:, 0]
    return Q


def skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _frame_with_z(z: np.ndarray, angle: float) -> np.ndarray:
    """Return a rotation whose third column is z, rotated by ``angle`` about it."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    c, s = np.cos(angle), np.sin(angle)
    return np.column_stack((c * x + s * y, -s * x + c * y, z))


def _spd(rng: np.random.Generator, size: int, scale: float) -> np.ndarray:
    B = rng.normal(size=(size, size))
    return scale * (B @ B.T / size + 0.2 * np.eye(size))


def constrained_dynamics(
    M_h: np.ndarray,
    h_bias: np.ndarray,
    J_h: np.ndarray,
    Jh_dot_dq: np.ndarray,
    G: np.ndarray,
    G_dot_T_twist: np.ndarray,
    M_o: np.ndarray,
    C_o_twist: np.ndarray,
    w_e: np.ndarray,
) -> tuple[np.ndarray, AffineMap, AffineMap, AffineMap]:
    """Solve the hand–object dynamics (module docstring) for the maps affine in u.

    Returns:
        ``B_ho`` and the maps ``u ↦ f_c``, ``u ↦ ddq`` and ``u ↦ x_o_ddot``.
    """
    M_h_inv = np.linalg.inv(M_h)
    M_o_inv = np.linalg.inv(M_o)
    B_ho = J_h @ M_h_inv @ J_h.T + G.T @ M_o_inv @ G
    F = np.linalg.solve(B_ho, J_h @ M_h_inv)
    f0 = np.linalg.solve(
        B_ho,
        -J_h @ M_h_inv @ h_bias + Jh_dot_dq - G_dot_T_twist + G.T @ M_o_inv @ (C_o_twist - w_e),
    )
    contact_force = AffineMap(F, f0)
    joint_acceleration = AffineMap(
        M_h_inv @ (np.eye(M_h.shape[0]) - J_h.T @ F), -M_h_inv @ (h_bias + J_h.T @ f0)
    )
    object_acceleration = AffineMap(M_o_inv @ G @ F, M_o_inv @ (G @ f0 + w_e - C_o_twist))
    return B_ho, contact_force, joint_acceleration, object_acceleration


def synthetic_state(
    rng: np.random.Generator,
    hand: SyntheticHand | None = None,
    *,
    speed: float = 0.1,
    q: np.ndarray | None = None,
    dq: np.ndarray | None = None,
    xi_cf: np.ndarray | None = None,
    xi_cf_dot: np.ndarray | None = None,
    object_mass: float | None = None,
    link_inertia: float = 0.01,
    t: float = 0.0,
) -> GraspState:
    """Build a random consistent grasp state.

    Args:
        rng: Random generator.
        hand: Joint/contact layout and limits (default: 3 fingers x 3 joints).
        speed: Scale of the object twist, rad/s and m/s; velocity-product terms scale
            with its square.
        q: Joint angles (default: uniform in the middle 60 % of the limits).
        dq: Joint rates (default: consistent with the object twist through the rolling
            constraint).
        xi_cf: Fingertip contact coordinates, shape (n, 2) (default: in the middle half of
            the workspace).
        xi_cf_dot: Their rates, shape (n, 2) (default: of order ``speed``).
        object_mass: kg (default: the hand's object_mass).
        link_inertia: Scale of each finger's joint-space inertia block, kg m^2.
        t: Time stamp, s.
    """
    hand = hand if hand is not None else SyntheticHand()
    n, m, per = hand.n_fingers, hand.n_joints, hand.joints_per_finger
    mass = hand.object_mass if object_mass is None else object_mass

    p_object = rng.normal(scale=0.01, size=3) + np.array([0.0, 0.0, 0.2])
    R_object = random_rotation(rng)
    inertia_body = np.diag(mass * (2 * OBJECT_HALF_EDGE) ** 2 / 6 * rng.uniform(0.8, 1.2, 3))
    inertia = R_object @ inertia_body @ R_object.T
    M_o = np.zeros((6, 6))
    M_o[:3, :3] = mass * np.eye(3)
    M_o[3:, 3:] = inertia
    twist_object = rng.normal(scale=speed, size=6)
    w_o = twist_object[3:]
    C_o_twist = np.concatenate((np.zeros(3), np.cross(w_o, inertia @ w_o)))
    w_e = np.array([0.0, 0.0, -mass * GRAVITY, 0.0, 0.0, 0.0])

    angles = 2 * np.pi * np.arange(n) / n + rng.uniform(-0.3, 0.3, n)
    tilts = rng.uniform(-0.3, 0.3, n)
    directions = np.column_stack(
        (np.cos(tilts) * np.cos(angles), np.cos(tilts) * np.sin(angles), np.sin(tilts))
    )
    p_contact = p_object + OBJECT_HALF_EDGE * directions
    R_contact = np.stack([_frame_with_z(-d, rng.uniform(-np.pi, np.pi)) for d in directions])
    p_fingertip = p_contact + FINGERTIP_RADIUS * directions
    R_fingertip = np.stack([random_rotation(rng) for _ in range(n)])

    J_fingertip = np.zeros((n, 6, m))
    J_h = np.zeros((3 * n, m))
    G = np.zeros((6, 3 * n))
    M_h = np.zeros((m, m))
    for i in range(n):
        cols = slice(per * i, per * (i + 1))
        J_fingertip[i, :3, cols] = rng.normal(scale=0.2, size=(3, per))
        J_fingertip[i, 3:, cols] = rng.normal(scale=1.0, size=(3, per))
        p_fc = p_contact[i] - p_fingertip[i]
        lever = np.hstack((np.eye(3), -skew(p_fc)))
        J_h[3 * i : 3 * i + 3] = R_contact[i].T @ lever @ J_fingertip[i]
        G[:3, 3 * i : 3 * i + 3] = R_contact[i]
        G[3:, 3 * i : 3 * i + 3] = skew(p_contact[i] - p_object) @ R_contact[i]
        M_h[cols, cols] = _spd(rng, per, link_inertia)

    if dq is None:
        dq = np.linalg.lstsq(J_h, G.T @ twist_object, rcond=None)[0]
    twist_fingertip = np.einsum('ijk,k->ij', J_fingertip, dq)
    gravity_torque = rng.normal(scale=0.05, size=m)
    h_bias = gravity_torque + rng.normal(scale=0.01 * speed**2 + 1e-12, size=m)
    Jh_dot_dq = rng.normal(scale=0.05 * speed**2 + 1e-12, size=3 * n)
    G_dot_T_twist = rng.normal(scale=0.05 * speed**2 + 1e-12, size=3 * n)

    B_ho, contact_force, joint_acceleration, object_acceleration = constrained_dynamics(
        M_h, h_bias, J_h, Jh_dot_dq, G, G_dot_T_twist, M_o, C_o_twist, w_e
    )
    rows_matrix = np.zeros((2 * n, m))
    rows_offset = np.zeros(2 * n)
    for i in range(n):
        H = rng.normal(scale=1.0 / FINGERTIP_RADIUS, size=(2, 3))
        angular_f = AffineMap(
            J_fingertip[i, 3:] @ joint_acceleration.matrix,
            J_fingertip[i, 3:] @ joint_acceleration.offset,
        )
        rows_matrix[2 * i : 2 * i + 2] = H @ (angular_f.matrix - object_acceleration.matrix[3:])
        rows_offset[2 * i : 2 * i + 2] = H @ (
            angular_f.offset - object_acceleration.offset[3:]
        ) + rng.normal(scale=speed**2 + 1e-12, size=2)
    xi_cf_ddot = AffineMap(rows_matrix, rows_offset)

    lo, hi = hand.joint_lower_limits, hand.joint_upper_limits
    if q is None:
        q = lo + (hi - lo) * rng.uniform(0.2, 0.8, m)
    a_min, a_max, b_min, b_max = hand.fingertip_workspace
    if xi_cf is None:
        xi_cf = np.column_stack(
            (
                a_min + (a_max - a_min) * rng.uniform(0.25, 0.75, n),
                b_min + (b_max - b_min) * rng.uniform(0.25, 0.75, n),
            )
        )
    if xi_cf_dot is None:
        xi_cf_dot = rng.normal(scale=speed, size=(n, 2))

    state = GraspState(
        t=t,
        q=np.asarray(q, dtype=float),
        dq=np.asarray(dq, dtype=float),
        p_object_in_palm=p_object,
        R_object_to_palm=R_object,
        twist_object=twist_object,
        p_fingertip_in_palm=p_fingertip,
        R_fingertip_to_palm=R_fingertip,
        twist_fingertip=twist_fingertip,
        xi_cf=np.asarray(xi_cf, dtype=float),
        xi_co=rng.uniform(-0.05, 0.05, size=(n, 2)),
        psi=rng.uniform(-np.pi, np.pi, n),
        xi_cf_dot=np.asarray(xi_cf_dot, dtype=float),
        xi_co_dot=rng.normal(scale=speed * FINGERTIP_RADIUS, size=(n, 2)),
        psi_dot=rng.normal(scale=speed, size=n),
        penetration=np.zeros(n),
        p_contact_in_palm=p_contact,
        R_contact_to_palm=R_contact,
        M_h=M_h,
        h_bias=h_bias,
        gravity_torque=gravity_torque,
        J_fingertip=J_fingertip,
        J_h=J_h,
        G=G,
        Jh_dot_dq=Jh_dot_dq,
        G_dot_T_twist=G_dot_T_twist,
        M_o=M_o,
        C_o_twist=C_o_twist,
        w_e=w_e,
        B_ho=B_ho,
        contact_force=contact_force,
        joint_acceleration=joint_acceleration,
        object_acceleration=object_acceleration,
        xi_cf_ddot=xi_cf_ddot,
        xi_co_rate_terms=lambda: (np.zeros((n, 2, 2)), np.zeros((n, 2))),
    )
    # A sphere rolling on a face: M_co = I, so M_co^-1 R_psi M_cf = R_psi diag(R, R cos a);
    # no random numbers, so that later states are unchanged.
    c, s = np.cos(state.psi), np.sin(state.psi)
    cos_a = np.cos(state.xi_cf[:, 0])
    blocks = FINGERTIP_RADIUS * np.array([[c, -s * cos_a], [-s, -c * cos_a]]).transpose(2, 0, 1)
    return with_fields(state, xi_co_rate_terms=lambda: (blocks, np.zeros((n, 2))))


def with_fields(state: GraspState, **changes: object) -> GraspState:
    """Copy ``state`` with some fields replaced (GraspState is frozen)."""
    values = {name: getattr(state, name) for name in state.__dataclass_fields__}
    values.update(changes)
    return GraspState(**values)
