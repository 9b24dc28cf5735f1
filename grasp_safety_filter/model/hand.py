"""The hand: rigid-body kinematics and dynamics from its URDF, with Pinocchio.

Joint vectors are in the caller's joint order (``joint_names``), matched to the URDF by
name; Pinocchio's own order is internal to this module.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin


class HandModelError(ValueError):
    """The URDF does not describe the hand the configuration expects."""


@dataclass(frozen=True)
class HandTerms:
    """Hand quantities at one ``(q, dq)``; arrays in the caller's joint order.

    Attributes:
        M_h: Joint-space inertia, (m, m), kg·m².
        h_bias: ``C_h dq + g(q)``, (m,), N·m.
        gravity_torque: ``g(q)``, (m,), N·m.
        p_fingertip_in_palm: Fingertip frame origins, (n, 3), m.
        R_fingertip_to_palm: Fingertip frame orientations, (n, 3, 3).
        J_fingertip: Frame Jacobians in LOCAL_WORLD_ALIGNED, (n, 6, m): ``dq ↦ (v_f, w_f)``.
        twist_fingertip: ``(v_f, w_f)``, (n, 6).
        J_fingertip_dot_dq: ``J_s_dot dq``: the frames' classical acceleration at ddq = 0, (n, 6).
    """

    M_h: np.ndarray
    h_bias: np.ndarray
    gravity_torque: np.ndarray
    p_fingertip_in_palm: np.ndarray
    R_fingertip_to_palm: np.ndarray
    J_fingertip: np.ndarray
    twist_fingertip: np.ndarray
    J_fingertip_dot_dq: np.ndarray


class HandModel:
    """Kinematics and dynamics of a fixed-base hand of revolute joints.

    Args:
        urdf_path: The hand's URDF.
        joint_names: Actuated joints, in command order; exactly the URDF's movable joints.
        fingertip_frames: URDF frames at the fingertip sphere centres (z out of the tip).
        gravity: Gravity in the palm frame, (3,), m/s².

    Raises:
        HandModelError: unreadable URDF, unknown or non-revolute joint, a movable URDF joint
            missing from ``joint_names``, unknown frame, or invalid joint limits.
    """

    def __init__(
        self,
        urdf_path: Path,
        joint_names: list[str],
        fingertip_frames: list[str],
        gravity: np.ndarray,
    ) -> None:
        urdf_path = Path(urdf_path)
        if not urdf_path.is_file():
            raise HandModelError(f"model.urdf_file: no such file {str(urdf_path)!r}")
        try:
            self.model = pin.buildModelFromUrdf(str(urdf_path))
        except (RuntimeError, ValueError) as error:
            raise HandModelError(f"model.urdf_file: cannot parse {str(urdf_path)!r}: {error}") from None
        urdf_joints = [self.model.names[j] for j in range(1, self.model.njoints)]
        if len(set(joint_names)) != len(joint_names):
            raise HandModelError(f"model.joint_names: duplicate names in {joint_names}")
        for name in joint_names:
            if name not in urdf_joints:
                raise HandModelError(
                    f"model.joint_names: joint {name!r} is not a movable joint of "
                    f"{urdf_path.name} (it has {urdf_joints})"
                )
        missing = [name for name in urdf_joints if name not in joint_names]
        if missing:
            raise HandModelError(
                f"model.joint_names: the URDF's movable joints {missing} are not listed; every "
                "joint must be commanded"
            )
        self.joint_names = list(joint_names)
        # idx[k]: Pinocchio index of the caller's joint k.
        idx = []
        for name in joint_names:
            joint = self.model.joints[self.model.getJointId(name)]
            if joint.nq != 1 or joint.nv != 1 or not joint.shortname().startswith(("JointModelR", "JointModelRevolute")):
                raise HandModelError(
                    f"model.joint_names: joint {name!r} is {joint.shortname()}, expected revolute"
                )
            idx.append(joint.idx_q)
        self._idx = np.array(idx)
        lower = self.model.lowerPositionLimit[self._idx]
        upper = self.model.upperPositionLimit[self._idx]
        effort = self.model.effortLimit[self._idx]
        for name, lo, hi, tau in zip(joint_names, lower, upper, effort, strict=True):
            if not lo < hi:
                raise HandModelError(
                    f"{urdf_path.name}: joint {name!r} needs lower < upper limit, got "
                    f"lower={lo}, upper={hi}"
                )
            if not tau > 0.0:
                raise HandModelError(
                    f"{urdf_path.name}: joint {name!r} needs a positive effort limit, got {tau}"
                )
        self.joint_lower_limits = lower.copy()
        self.joint_upper_limits = upper.copy()
        self.effort_limits = effort.copy()
        self.frame_ids = []
        for frame in fingertip_frames:
            if not self.model.existFrame(frame):
                raise HandModelError(
                    f"model.fingertip_frames: frame {frame!r} is not in {urdf_path.name}"
                )
            self.frame_ids.append(self.model.getFrameId(frame))
        gravity = np.asarray(gravity, dtype=float)
        self.model.gravity = pin.Motion(gravity, np.zeros(3))
        self.data = self.model.createData()
        self._zero = np.zeros(self.model.nv)

    @property
    def n_joints(self) -> int:
        """Number of joints m."""
        return len(self.joint_names)

    def _to_pin(self, x: np.ndarray) -> np.ndarray:
        out = np.empty(self.model.nq)
        out[self._idx] = x
        return out

    def terms(self, q: np.ndarray, dq: np.ndarray) -> HandTerms:
        """Everything the grasp model needs from the hand at ``(q, dq)``."""
        model, data, idx = self.model, self.data, self._idx
        q_pin, dq_pin = self._to_pin(q), self._to_pin(dq)
        # Kinematics with ddq = 0: frame accelerations are then J_s_dot dq.
        pin.forwardKinematics(model, data, q_pin, dq_pin, self._zero)
        pin.computeJointJacobians(model, data, q_pin)
        pin.updateFramePlacements(model, data)
        n = len(self.frame_ids)
        p = np.empty((n, 3))
        R = np.empty((n, 3, 3))
        J = np.empty((n, 6, len(idx)))
        twist = np.empty((n, 6))
        J_dot_dq = np.empty((n, 6))
        for i, fid in enumerate(self.frame_ids):
            placement = data.oMf[fid]
            p[i] = placement.translation
            R[i] = placement.rotation
            J[i] = pin.getFrameJacobian(model, data, fid, pin.LOCAL_WORLD_ALIGNED)[:, idx]
            twist[i] = pin.getFrameVelocity(model, data, fid, pin.LOCAL_WORLD_ALIGNED).vector
            J_dot_dq[i] = pin.getFrameClassicalAcceleration(
                model, data, fid, pin.LOCAL_WORLD_ALIGNED
            ).vector
        M = pin.crba(model, data, q_pin)
        M = np.triu(M) + np.triu(M, 1).T  # crba fills the upper triangle only
        h_bias = pin.nonLinearEffects(model, data, q_pin, dq_pin)[idx]
        gravity_torque = pin.computeGeneralizedGravity(model, data, q_pin)[idx]
        return HandTerms(
            M_h=M[np.ix_(idx, idx)],
            h_bias=h_bias,
            gravity_torque=gravity_torque,
            p_fingertip_in_palm=p,
            R_fingertip_to_palm=R,
            J_fingertip=J,
            twist_fingertip=twist,
            J_fingertip_dot_dq=J_dot_dq,
        )

    def fingertip_placements(self, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Fingertip positions (n, 3), orientations (n, 3, 3) and Jacobians (n, 6, m) at q."""
        q_pin = self._to_pin(q)
        pin.computeJointJacobians(self.model, self.data, q_pin)
        pin.updateFramePlacements(self.model, self.data)
        p = np.array([self.data.oMf[f].translation for f in self.frame_ids])
        R = np.array([self.data.oMf[f].rotation for f in self.frame_ids])
        J = np.array(
            [
                pin.getFrameJacobian(self.model, self.data, f, pin.LOCAL_WORLD_ALIGNED)[:, self._idx]
                for f in self.frame_ids
            ]
        )
        return p, R, J

    def energy(self, q: np.ndarray, dq: np.ndarray) -> float:
        """Kinetic plus gravitational potential energy of the hand, J."""
        q_pin, dq_pin = self._to_pin(q), self._to_pin(dq)
        kinetic = pin.computeKineticEnergy(self.model, self.data, q_pin, dq_pin)
        potential = pin.computePotentialEnergy(self.model, self.data, q_pin)
        return float(kinetic + potential)
