"""The hand: rigid-body kinematics and dynamics from its URDF, with Pinocchio.

Joint vectors are in the caller's joint order (``joint_names``), matched to the URDF by
name; Pinocchio's own order is internal to this module.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import NamedTuple

import numpy as np
import pinocchio as pin

from grasp_safety_filter.model.fingertips import fingertip_spheres
from grasp_safety_filter.model.hand_kernel import hand_in_model_order
from grasp_safety_filter.model.urdf import check_urdf_file, HandModelError

__all__ = ['HandModel', 'HandModelError', 'HandTerms', 'RawHandTerms']


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
        M_h_inverse: ``M_h^-1``, (m, m), from the sparse (tree) Cholesky factor of M_h.
    """

    M_h: np.ndarray
    h_bias: np.ndarray
    gravity_torque: np.ndarray
    p_fingertip_in_palm: np.ndarray
    R_fingertip_to_palm: np.ndarray
    J_fingertip: np.ndarray
    twist_fingertip: np.ndarray
    J_fingertip_dot_dq: np.ndarray
    M_h_inverse: np.ndarray


class RawHandTerms(NamedTuple):
    """Pinocchio's terms at one ``(q, dq)``, in its joint order (see :meth:`HandModel.raw_terms`).

    Attributes:
        placements: Fingertip frame placements, homogeneous, (n, 4, 4).
        J_frames: Fingertip frame Jacobians (LOCAL_WORLD_ALIGNED), (n, 6, nv).
        J_frames_dot_dq: Their classical accelerations at ddq = 0, ``J_s_dot dq``, (n, 6).
        M_upper: Joint-space inertia, upper triangle only (a view of Pinocchio's buffer).
        nle: ``C_h dq + g(q)``, (nv,) (a view of Pinocchio's buffer).
        g: ``g(q)``, (nv,) (a view of Pinocchio's buffer).
        M_inverse: ``M_h^-1``, (nv, nv), full.
    """

    placements: np.ndarray
    J_frames: np.ndarray
    J_frames_dot_dq: np.ndarray
    M_upper: np.ndarray
    nle: np.ndarray
    g: np.ndarray
    M_inverse: np.ndarray


class HandModel:
    """Kinematics and dynamics of a fixed-base hand of revolute joints.

    Args:
        urdf_path: The hand's URDF.
        joint_names: Actuated joints, in command order; exactly the URDF's movable joints.
        fingertip_frames: URDF frames of the fingertips, one per contact (z out of the tip);
            each one's fingertip is the ``<collision><sphere>`` of its body, whose centre
            becomes the fingertip frame's origin (:mod:`grasp_safety_filter.model.fingertips`).
        gravity: Gravity in the palm frame, (3,), m/s².

    Raises:
        HandModelError: unreadable URDF, unknown or non-revolute joint, a movable URDF joint
            missing from ``joint_names``, unknown frame, a fingertip frame without a collision
            sphere, or invalid joint limits.
    """

    def __init__(
        self,
        urdf_path: Path,
        joint_names: list[str],
        fingertip_frames: list[str],
        gravity: np.ndarray,
    ) -> None:
        urdf_path = Path(urdf_path)
        check_urdf_file(urdf_path)
        try:
            self.model = pin.buildModelFromUrdf(str(urdf_path))
        except (RuntimeError, ValueError) as error:
            raise HandModelError(
                f'model.urdf_file: cannot parse {str(urdf_path)!r}: {error}'
            ) from None
        urdf_joints = [self.model.names[j] for j in range(1, self.model.njoints)]
        if len(set(joint_names)) != len(joint_names):
            raise HandModelError(f'model.joint_names: duplicate names in {joint_names}')
        for name in joint_names:
            if name not in urdf_joints:
                raise HandModelError(
                    f'model.joint_names: joint {name!r} is not a movable joint of '
                    f'{urdf_path.name} (it has {urdf_joints})'
                )
        missing = [name for name in urdf_joints if name not in joint_names]
        if missing:
            raise HandModelError(
                f"model.joint_names: the URDF's movable joints {missing} are not listed; every "
                'joint must be commanded'
            )
        self.joint_names = list(joint_names)
        # idx[k]: Pinocchio index of the caller's joint k.
        idx = []
        for name in joint_names:
            joint = self.model.joints[self.model.getJointId(name)]
            revolute = joint.shortname().startswith(('JointModelR', 'JointModelRevolute'))
            if joint.nq != 1 or joint.nv != 1 or not revolute:
                raise HandModelError(
                    f'model.joint_names: joint {name!r} is {joint.shortname()}, expected revolute'
                )
            idx.append(joint.idx_q)
        self._idx = np.array(idx)
        #: Pinocchio's index of each of the caller's joints, (m,) (read-only).
        self.pinocchio_index = self._idx.astype(np.intp)
        self.pinocchio_index.setflags(write=False)
        lower = self.model.lowerPositionLimit[self._idx]
        upper = self.model.upperPositionLimit[self._idx]
        effort = self.model.effortLimit[self._idx]
        for name, lo, hi, tau in zip(joint_names, lower, upper, effort, strict=True):
            if not lo < hi:
                raise HandModelError(
                    f'{urdf_path.name}: joint {name!r} needs lower < upper limit, got '
                    f'lower={lo}, upper={hi}'
                )
            if not tau > 0.0:
                raise HandModelError(
                    f'{urdf_path.name}: joint {name!r} needs a positive effort limit, got {tau}'
                )
        self.joint_lower_limits = lower.copy()
        self.joint_upper_limits = upper.copy()
        self.effort_limits = effort.copy()
        #: Per contact: its fingertip's collision sphere (radius, link, centre frame).
        self.fingertips = fingertip_spheres(self.model, urdf_path, list(fingertip_frames))
        self.frame_ids = [tip.frame_id for tip in self.fingertips]
        gravity = np.asarray(gravity, dtype=float)
        self.model.gravity = pin.Motion(gravity, np.zeros(3))
        self.data = self.model.createData()
        # The caller's joint order is usually the URDF's: then no reordering copies are needed.
        self._in_pin_order = bool(np.array_equal(self._idx, np.arange(self.model.nv)))
        # Pinocchio's crba fills the upper triangle of M only.
        self._upper = np.triu(np.ones((self.model.nv, self.model.nv), dtype=bool))
        self._check_inertia(urdf_path.name)

    def _check_inertia(self, urdf_name: str) -> None:
        """Refuse a hand whose M_h is singular at the middle of the joint ranges.

        A joint that moves no mass (links without ``<inertial>``) leaves M_h singular: the
        filter would divide by it. The joint named is the one the null direction moves most.
        """
        q_middle = 0.5 * (self.joint_lower_limits + self.joint_upper_limits)
        M = pin.crba(self.model, self.data, self._to_pin(q_middle))
        M = np.where(self._upper, M, M.T)
        eigenvalues, vectors = np.linalg.eigh(M)
        if not eigenvalues[0] > 1e-12 * max(eigenvalues[-1], 1e-300):
            joint = self.joint_names[int(np.argmax(np.abs(self._from_pin(vectors[:, 0]))))]
            raise HandModelError(
                f'{urdf_name}: joint {joint!r} moves no inertia (M_h at the middle of the joint '
                f'ranges has eigenvalue {eigenvalues[0]:.3g}): expected an <inertial> with a '
                'mass > 0 on a link it moves'
            )

    @property
    def n_joints(self) -> int:
        """Number of joints m."""
        return len(self.joint_names)

    def _to_pin(self, x: np.ndarray) -> np.ndarray:
        if self._in_pin_order:
            return x
        out = np.empty(self.model.nq)
        out[self._idx] = x
        return out

    def _from_pin(self, x: np.ndarray) -> np.ndarray:
        """``x`` with its last (joint) axis in the caller's joint order (``x`` itself if equal)."""
        return x if self._in_pin_order else x[..., self._idx]

    def raw_terms(self, q: np.ndarray, dq: np.ndarray) -> RawHandTerms:
        """Pinocchio's hand terms at ``(q, dq)``, as Pinocchio gives them (its joint order).

        One recursive pass gives M (upper triangle), C dq + g, g, the joint Jacobians and
        the kinematics with ddq = 0, whose frame accelerations are then J_s_dot dq; M^-1
        comes from Pinocchio's Cholesky factor of M, which follows the kinematic tree. The
        few per-frame reads are the only Python loop: :meth:`terms` and the compiled grasp
        terms (:mod:`grasp_safety_filter.model.packed_terms`) do the rest.
        """
        model, data = self.model, self.data
        pin.computeAllTerms(model, data, self._to_pin(q), self._to_pin(dq))
        pin.updateFramePlacements(model, data)
        world_aligned = pin.LOCAL_WORLD_ALIGNED
        placements, jacobians, accelerations = [], [], []
        for f in self.frame_ids:
            placements.append(data.oMf[f].homogeneous)
            jacobians.append(pin.getFrameJacobian(model, data, f, world_aligned))
            accelerations.append(
                pin.getFrameClassicalAcceleration(model, data, f, world_aligned).vector
            )
        pin.cholesky.decompose(model, data)
        # data.M, data.nle and data.g are views of Pinocchio's buffers (overwritten by its
        # next call); computeMinv returns a new, full symmetric array.
        return RawHandTerms(
            placements=np.array(placements),
            J_frames=np.array(jacobians),
            J_frames_dot_dq=np.array(accelerations),
            M_upper=data.M,
            nle=data.nle,
            g=data.g,
            M_inverse=pin.cholesky.computeMinv(model, data),
        )

    def frame_twists(self, raw: RawHandTerms, dq: np.ndarray) -> np.ndarray:
        """Return the fingertip frame twists ``J_s dq``, (n, 6), as :meth:`terms` has them."""
        return self._from_pin(raw.J_frames) @ dq

    def terms(self, q: np.ndarray, dq: np.ndarray) -> HandTerms:
        """Everything the grasp model needs from the hand at ``(q, dq)``."""
        raw = self.raw_terms(q, dq)
        p_f, R_f, J, M, M_inv, h_bias, gravity = hand_in_model_order(
            raw.placements, raw.J_frames, raw.M_upper, raw.nle, raw.g, raw.M_inverse,
            self.pinocchio_index,
        )
        return HandTerms(
            M_h=M,
            h_bias=h_bias,
            gravity_torque=gravity,
            p_fingertip_in_palm=p_f,
            R_fingertip_to_palm=R_f,
            J_fingertip=J,
            # The frame twists are J_s dq (the same as Pinocchio's frame velocities).
            twist_fingertip=self.frame_twists(raw, dq),
            J_fingertip_dot_dq=raw.J_frames_dot_dq,
            M_h_inverse=M_inv,
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
                pin.getFrameJacobian(self.model, self.data, f, pin.LOCAL_WORLD_ALIGNED)
                for f in self.frame_ids
            ]
        )[:, :, self._idx]
        return p, R, J

    def energy(self, q: np.ndarray, dq: np.ndarray) -> float:
        """Kinetic plus gravitational potential energy of the hand, J."""
        q_pin, dq_pin = self._to_pin(q), self._to_pin(dq)
        kinetic = pin.computeKineticEnergy(self.model, self.data, q_pin, dq_pin)
        potential = pin.computePotentialEnergy(self.model, self.data, q_pin)
        return float(kinetic + potential)
