"""The hand–object–contact model: hand, object and rolling contacts assembled.

The equations (DESIGN.md §3; Shaw-Cortez et al., eqs. 1, 2, 4, 17):

    M_h ddq + C_h dq = -J_h^T f_c + tau_e + u          (hand, tau_e = -g(q))
    M_o x_o_ddot + C_o x_o_dot = G f_c + w_e            (object)
    J_h dq = G^T x_o_dot                                (rolling without slipping)

    J_h,i = R_cp,i [I, -(p_fc,i)×] J_s,i,   G_i = [R_pc,i; (p_c,i - p_o)× R_pc,i]

Differentiating the rolling constraint once and substituting both dynamics makes the
contact force affine in the torque:

    B_ho f_c = J_h M_h^-1 (u - C_h dq - g) + J_h_dot dq - G_dot^T x_o_dot
               + G^T M_o^-1 (C_o x_o_dot - w_e),    B_ho = J_h M_h^-1 J_h^T + G^T M_o^-1 G

and with it ``ddq``, ``x_o_ddot`` and the fingertip contact coordinates' second
derivatives. ``J_h_dot`` and ``G_dot`` are total time derivatives along the rolling
motion: they include the motion of the contact point over the fingertip and the rotation of
the contact frame.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from grasp_safety_filter.model.affine import AffineMap
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.hand import HandModel
from grasp_safety_filter.model.rigid_object import RigidObject, object_surface
from grasp_safety_filter.model.rolling import ContactGeometry, ContactPair
from grasp_safety_filter.model.surfaces import SphereSurface


class GraspConfigError(ValueError):
    """The configuration does not describe a valid grasp (names the parameter and the values)."""


@dataclass(frozen=True)
class FingertipWorkspace:
    """The box of admissible fingertip coordinates ``a_min ≤ a ≤ a_max, b_min ≤ b ≤ b_max``, rad."""

    a_min: float
    a_max: float
    b_min: float
    b_max: float

    def __post_init__(self) -> None:
        if not -np.pi / 2 <= self.a_min < self.a_max <= np.pi / 2:
            raise GraspConfigError(
                "model.fingertip_workspace: expected -pi/2 <= a_min < a_max <= pi/2, got "
                f"a_min={self.a_min}, a_max={self.a_max}"
            )
        if not self.b_min < self.b_max:
            raise GraspConfigError(
                "model.fingertip_workspace: expected b_min < b_max, got "
                f"b_min={self.b_min}, b_max={self.b_max}"
            )

    def __iter__(self):  # noqa: ANN204 - tuple-like unpacking: a_min, a_max, b_min, b_max
        return iter((self.a_min, self.a_max, self.b_min, self.b_max))

    def margins(self, xi_cf: np.ndarray) -> np.ndarray:
        """Barrier values ``(a - a_min, a_max - a, b - b_min, b_max - b)`` per contact, (n, 4)."""
        xi = np.atleast_2d(xi_cf)
        a, b = xi[:, 0], xi[:, 1]
        return np.column_stack([a - self.a_min, self.a_max - a, b - self.b_min, self.b_max - b])


def _skew(v: np.ndarray) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    # np.cross costs ~15 µs of axis bookkeeping per call; this is the hot path.
    return np.array([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def _frozen(array: np.ndarray) -> np.ndarray:
    array.flags.writeable = False
    return array


class GraspModel:
    """A hand grasping a rigid object at n rolling point contacts with friction.

    Args:
        hand: Kinematics and dynamics of the hand.
        rigid_object: The grasped object.
        contacts: One fingertip–object surface pair per fingertip, in the hand's fingertip
            frame order.
        contact_names: A name per contact (e.g. the finger's).
        friction_coefficient: Coulomb friction coefficient mu (> 0).
        fingertip_workspace: Admissible fingertip coordinates.
    """

    def __init__(
        self,
        hand: HandModel,
        rigid_object: RigidObject,
        contacts: Sequence[ContactPair],
        contact_names: Sequence[str],
        friction_coefficient: float,
        fingertip_workspace: FingertipWorkspace,
    ) -> None:
        n = len(contacts)
        if len(hand.frame_ids) != n or len(contact_names) != n:
            raise GraspConfigError(
                f"model: expected one fingertip frame and one name per contact ({n} contacts), got "
                f"{len(hand.frame_ids)} frames and {len(contact_names)} names"
            )
        if hand.n_joints < 3 * n:
            raise GraspConfigError(
                f"model.joint_names: a hand with n = {n} contacts needs at least 3n = {3 * n} "
                f"joints (the paper's Assumption 1), got {hand.n_joints}"
            )
        if not np.isfinite(friction_coefficient) or friction_coefficient <= 0.0:
            raise GraspConfigError(
                f"model.friction_coefficient: expected mu > 0, got {friction_coefficient!r}"
            )
        self.hand = hand
        self.object = rigid_object
        self.contacts = list(contacts)
        self.contact_names = list(contact_names)
        self.friction_coefficient = float(friction_coefficient)
        self.fingertip_workspace = fingertip_workspace

    # ----------------------------------------------------------------------------- loading
    @classmethod
    def from_parameters(cls, params: Mapping[str, Any], base_dir: Path | str = ".") -> GraspModel:
        """Build from validated ``model.*`` parameters (dotted names, see io/schemas.py).

        Relative ``model.urdf_file`` paths resolve against ``base_dir`` (the directory of
        the parameter file).
        """
        def get(name: str) -> Any:
            if name not in params:
                raise GraspConfigError(f"parameter '{name}' is missing")
            return params[name]

        urdf = Path(get("model.urdf_file"))
        if not urdf.is_absolute():
            urdf = Path(base_dir) / urdf
        gravity = np.asarray(get("model.gravity"), dtype=float)
        if gravity.shape != (3,):
            raise GraspConfigError(f"model.gravity: expected 3 elements, got {len(gravity)}")
        frames = list(get("model.fingertip_frames"))
        names = list(get("model.contact_names"))
        faces = list(get("model.contact_faces"))
        shape = get("model.object.shape")
        if len(names) != len(frames):
            raise GraspConfigError(
                f"model.contact_names: expected one name per fingertip frame ({len(frames)}), "
                f"got {len(names)}"
            )
        if shape == "cube" and len(faces) != len(frames):
            raise GraspConfigError(
                f"model.contact_faces: expected one cube face per fingertip ({len(frames)}), got "
                f"{len(faces)}"
            )
        if shape == "sphere":
            faces = [""] * len(frames)
        hand = HandModel(urdf, list(get("model.joint_names")), frames, gravity)
        size, mass = float(get("model.object.size")), float(get("model.object.mass"))
        if shape == "cube":
            rigid_object = RigidObject.cube(mass, size, gravity)
        elif shape == "sphere":
            rigid_object = RigidObject.sphere(mass, size, gravity)
        else:
            raise GraspConfigError(f"model.object.shape: expected 'cube' or 'sphere', got {shape!r}")
        fingertip = SphereSurface(float(get("model.fingertip_radius")))
        contacts = []
        for name, face in zip(names, faces, strict=True):
            try:
                contacts.append(ContactPair(fingertip, object_surface(shape, size, face)))
            except ValueError as error:
                raise GraspConfigError(f"model.contact_faces: contact {name!r}: {error}") from None
        workspace = FingertipWorkspace(
            float(get("model.fingertip_workspace.a_min")),
            float(get("model.fingertip_workspace.a_max")),
            float(get("model.fingertip_workspace.b_min")),
            float(get("model.fingertip_workspace.b_max")),
        )
        return cls(hand, rigid_object, contacts, names, float(get("model.friction_coefficient")), workspace)

    @classmethod
    def from_parameter_file(
        cls, path: Path | str, node_name: str = "hand_sim_node"
    ) -> tuple[GraspModel, dict[str, Any]]:
        """Load a ROS 2 parameter file, validate it against ``node_name``'s schema, build the model.

        Returns:
            The model and the node's validated parameters (defaults filled in).
        """
        from grasp_safety_filter.io.schemas import load_node_parameters

        path = Path(path)
        params = load_node_parameters(path, node_name)
        return cls.from_parameters(params, path.parent), params

    # -------------------------------------------------------------------------- properties
    @property
    def joint_names(self) -> list[str]:
        """Joint names in command order."""
        return self.hand.joint_names

    @property
    def n_joints(self) -> int:
        """Number of joints m."""
        return self.hand.n_joints

    @property
    def n_contacts(self) -> int:
        """Number of contacts n."""
        return len(self.contacts)

    @property
    def joint_lower_limits(self) -> np.ndarray:
        """q_min from the URDF, (m,), rad."""
        return self.hand.joint_lower_limits

    @property
    def joint_upper_limits(self) -> np.ndarray:
        """q_max from the URDF, (m,), rad."""
        return self.hand.joint_upper_limits

    @property
    def effort_limits(self) -> np.ndarray:
        """Actuator torque limits from the URDF (|u_j| ≤ limit), (m,), N·m."""
        return self.hand.effort_limits

    # ------------------------------------------------------------------------ configuration
    def contact_geometry(
        self, q: np.ndarray, p_object_in_palm: np.ndarray, R_object_to_palm: np.ndarray
    ) -> list[ContactGeometry]:
        """Contact coordinates and frames of every contact at a configuration."""
        p_f, R_f, _ = self.hand.fingertip_placements(np.asarray(q, dtype=float))
        return [
            contact.geometry(p_f[i], R_f[i], p_object_in_palm, R_object_to_palm)
            for i, contact in enumerate(self.contacts)
        ]

    def project_to_contact(
        self,
        q: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        tolerance: float = 1e-13,
        max_iterations: int = 50,
    ) -> np.ndarray:
        """Smallest joint correction that makes every fingertip touch its surface exactly.

        Gauss–Newton on the penetrations δ_i(q), with ``dδ_i/dq = -n_i^T J_v,i`` (n_i the
        object's outward normal at the contact, J_v,i the fingertip centre's Jacobian).
        """
        q = np.array(q, dtype=float)
        for _ in range(max_iterations):
            p_f, R_f, J_f = self.hand.fingertip_placements(q)
            delta = np.empty(self.n_contacts)
            jacobian = np.empty((self.n_contacts, self.n_joints))
            for i, contact in enumerate(self.contacts):
                geometry = contact.geometry(p_f[i], R_f[i], p_object_in_palm, R_object_to_palm)
                delta[i] = geometry.penetration
                n_object = -geometry.R_contact_to_palm[:, 2]
                jacobian[i] = -n_object @ J_f[i, :3]
            if np.max(np.abs(delta)) <= tolerance:
                return q
            q -= np.linalg.lstsq(jacobian, delta, rcond=None)[0]
        raise GraspConfigError(
            f"cannot bring every fingertip onto the object: penetrations {delta} m after "
            f"{max_iterations} iterations"
        )

    def check_grasp(
        self,
        q: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        tolerance: float = 1e-4,
        parameter: str = "initial.joint_positions",
    ) -> None:
        """Raise GraspConfigError unless every fingertip touches its surface within ``tolerance`` m,
        inside the fingertip workspace, and every joint is inside its limits.
        """
        q = np.asarray(q, dtype=float)
        if q.shape != (self.n_joints,):
            raise GraspConfigError(
                f"{parameter}: expected {self.n_joints} joint angles ({self.joint_names}), got {q.size}"
            )
        for name, value, lo, hi in zip(
            self.joint_names, q, self.joint_lower_limits, self.joint_upper_limits, strict=True
        ):
            if not lo < value < hi:
                raise GraspConfigError(
                    f"{parameter}: joint {name!r} = {value:.6g} rad is outside its limits [{lo:.6g}, {hi:.6g}]"
                )
        for name, geometry in zip(self.contact_names, self.contact_geometry(q, p_object_in_palm, R_object_to_palm), strict=True):
            if abs(geometry.penetration) > tolerance:
                state = "is separated from" if geometry.penetration < 0 else "penetrates"
                raise GraspConfigError(
                    f"{parameter}: fingertip of contact {name!r} {state} the object by "
                    f"{abs(geometry.penetration):.3g} m (expected touching within {tolerance:g} m)"
                )
            margins = self.fingertip_workspace.margins(geometry.xi_cf)[0]
            if np.any(margins <= 0.0):
                raise GraspConfigError(
                    f"{parameter}: contact {name!r} at fingertip coordinates (a, b) = "
                    f"({geometry.xi_cf[0]:.4g}, {geometry.xi_cf[1]:.4g}) rad is outside the "
                    "fingertip workspace"
                )

    def rolling_joint_velocity(
        self,
        q: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        twist_object: np.ndarray,
    ) -> np.ndarray:
        """Joint velocity that rolls the fingertips with the object: ``J_h dq = G^T x_o_dot``
        (least-norm when m > 3n)."""
        state = self.state(0.0, q, np.zeros(self.n_joints), p_object_in_palm, R_object_to_palm, np.zeros(6))
        return np.linalg.lstsq(state.J_h, state.G.T @ np.asarray(twist_object, dtype=float), rcond=None)[0]

    def total_energy(self, state: GraspState) -> float:
        """Kinetic plus gravitational potential energy of hand and object, J."""
        return self.hand.energy(state.q, state.dq) + self.object.energy(
            state.p_object_in_palm, state.R_object_to_palm, state.twist_object
        )

    # ------------------------------------------------------------------------------- state
    def state(
        self,
        t: float,
        q: np.ndarray,
        dq: np.ndarray,
        p_object_in_palm: np.ndarray,
        R_object_to_palm: np.ndarray,
        twist_object: np.ndarray,
    ) -> GraspState:
        """Every model term at one instant (see :class:`GraspState`)."""
        n, m = self.n_contacts, self.n_joints
        q = np.array(q, dtype=float)
        dq = np.array(dq, dtype=float)
        p_o = np.array(p_object_in_palm, dtype=float)
        R_o = np.array(R_object_to_palm, dtype=float)
        twist_o = np.array(twist_object, dtype=float)
        v_o, w_o = twist_o[:3], twist_o[3:]
        hand = self.hand.terms(q, dq)

        J_h = np.empty((3 * n, m))
        G = np.empty((6, 3 * n))
        Jh_dot_dq = np.empty(3 * n)
        G_dot_T_twist = np.empty(3 * n)
        xi_cf, xi_co = np.empty((n, 2)), np.empty((n, 2))
        xi_cf_dot, xi_co_dot = np.empty((n, 2)), np.empty((n, 2))
        psi, psi_dot, penetration = np.empty(n), np.empty(n), np.empty(n)
        p_c = np.empty((n, 3))
        R_pc_all = np.empty((n, 3, 3))
        # Pieces of the contact-coordinate acceleration, finished once ddq(u) is known.
        roll_terms = []
        for i, contact in enumerate(self.contacts):
            rows = slice(3 * i, 3 * i + 3)
            p_f, R_pf = hand.p_fingertip_in_palm[i], hand.R_fingertip_to_palm[i]
            J_s = hand.J_fingertip[i]
            v_f, w_f = hand.twist_fingertip[i, :3], hand.twist_fingertip[i, 3:]
            a_f0, alpha_f0 = hand.J_fingertip_dot_dq[i, :3], hand.J_fingertip_dot_dq[i, 3:]

            geometry = contact.geometry(p_f, R_pf, p_o, R_o)
            R_pc = geometry.R_contact_to_palm
            R_cp = R_pc.T
            w_relative = w_f - w_o
            rates = contact.rolling_rates(geometry, R_cp @ w_relative)

            p_fc = geometry.p_contact_in_palm - p_f
            p_oc = geometry.p_contact_in_palm - p_o
            J_h[rows] = R_cp @ (J_s[:3] - _skew(p_fc) @ J_s[3:])
            G[:3, rows] = R_pc
            G[3:, rows] = _skew(p_oc) @ R_pc

            # Total time derivatives: the contact point slides over the fingertip at
            # R_pf c_xi xi_cf_dot and the contact frame turns with the fingertip and along it.
            v_rolling = R_pf @ contact.fingertip.tangents(geometry.xi_cf) @ rates.xi_cf_dot
            v_material_f = v_f + _cross(w_f, p_fc)
            p_c_dot = v_material_f + v_rolling
            R_pc_dot = _skew(w_f) @ R_pc + R_pf @ contact.fingertip.frame_rate(geometry.xi_cf, rates.xi_cf_dot)
            R_cp_dot = R_pc_dot.T
            Jh_dot_dq[rows] = R_cp_dot @ v_material_f + R_cp @ (
                a_f0 + _cross(alpha_f0, p_fc) + _cross(w_f, p_c_dot - v_f)
            )
            G_dot_T_twist[rows] = R_cp_dot @ (v_o + _cross(w_o, p_oc)) + R_cp @ _cross(w_o, p_c_dot - v_o)

            H_cf_dot = contact.H_cf_rate(geometry, rates)
            # xi_cf_ddot = H_dot w + H (R_cp_dot (w_f - w_o) + R_cp (alpha_f - alpha_o)).
            roll_terms.append((rates.H_cf @ R_cp, H_cf_dot @ (R_cp @ w_relative) + rates.H_cf @ (R_cp_dot @ w_relative), J_s[3:], alpha_f0))

            xi_cf[i], xi_co[i], psi[i], penetration[i] = geometry.xi_cf, geometry.xi_co, geometry.psi, geometry.penetration
            xi_cf_dot[i], xi_co_dot[i], psi_dot[i] = rates.xi_cf_dot, rates.xi_co_dot, rates.psi_dot
            p_c[i] = geometry.p_contact_in_palm
            R_pc_all[i] = R_pc

        M_o = self.object.inertia_matrix(R_o)
        M_o_inv = np.zeros((6, 6))
        M_o_inv[:3, :3] = np.eye(3) / self.object.mass
        M_o_inv[3:, 3:] = R_o @ np.linalg.inv(self.object.inertia_in_body) @ R_o.T
        C_o_twist = self.object.bias_wrench(R_o, twist_o)
        w_e = self.object.external_wrench()

        M_h = hand.M_h
        chol = np.linalg.cholesky(M_h)
        M_h_inv = np.linalg.inv(chol).T @ np.linalg.inv(chol)
        M_h_inv_J_hT = M_h_inv @ J_h.T
        B_ho = J_h @ M_h_inv_J_hT + G.T @ M_o_inv @ G
        # f_c(u) = F u + f0.
        F = np.linalg.solve(B_ho, M_h_inv_J_hT.T)
        f0 = np.linalg.solve(
            B_ho,
            -M_h_inv_J_hT.T @ hand.h_bias + Jh_dot_dq - G_dot_T_twist + G.T @ M_o_inv @ (C_o_twist - w_e),
        )
        ddq_matrix = M_h_inv - M_h_inv_J_hT @ F
        ddq_offset = -M_h_inv @ hand.h_bias - M_h_inv_J_hT @ f0
        x_ddot_matrix = M_o_inv @ G @ F
        x_ddot_offset = M_o_inv @ (G @ f0 + w_e - C_o_twist)

        xi_ddot_matrix = np.empty((2 * n, m))
        xi_ddot_offset = np.empty(2 * n)
        for i, (H_R, drift, J_w, alpha_f0) in enumerate(roll_terms):
            rows = slice(2 * i, 2 * i + 2)
            xi_ddot_matrix[rows] = H_R @ (J_w @ ddq_matrix - x_ddot_matrix[3:])
            xi_ddot_offset[rows] = drift + H_R @ (J_w @ ddq_offset + alpha_f0 - x_ddot_offset[3:])

        arrays = dict(
            q=q, dq=dq, p_object_in_palm=p_o, R_object_to_palm=R_o, twist_object=twist_o,
            p_fingertip_in_palm=hand.p_fingertip_in_palm, R_fingertip_to_palm=hand.R_fingertip_to_palm,
            twist_fingertip=hand.twist_fingertip, xi_cf=xi_cf, xi_co=xi_co, psi=psi,
            xi_cf_dot=xi_cf_dot, xi_co_dot=xi_co_dot, psi_dot=psi_dot, penetration=penetration,
            p_contact_in_palm=p_c, R_contact_to_palm=R_pc_all, M_h=M_h, h_bias=hand.h_bias,
            gravity_torque=hand.gravity_torque, J_fingertip=hand.J_fingertip, J_h=J_h, G=G,
            Jh_dot_dq=Jh_dot_dq, G_dot_T_twist=G_dot_T_twist, M_o=M_o, C_o_twist=C_o_twist,
            w_e=w_e, B_ho=B_ho,
        )
        maps = dict(
            contact_force=(F, f0),
            joint_acceleration=(ddq_matrix, ddq_offset),
            object_acceleration=(x_ddot_matrix, x_ddot_offset),
            xi_cf_ddot=(xi_ddot_matrix, xi_ddot_offset),
        )
        return GraspState(
            t=float(t),
            **{name: _frozen(value) for name, value in arrays.items()},
            **{name: AffineMap(_frozen(a), _frozen(b)) for name, (a, b) in maps.items()},
        )
