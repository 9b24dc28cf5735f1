"""The hand: rigid-body kinematics and dynamics from its URDF, with Pinocchio.

Joint vectors are in the caller's joint order (``joint_names``), matched to the URDF by
name; Pinocchio's own order is internal to this module.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
from numpy.lib.stride_tricks import as_strided
import pinocchio as pin

from grasp_safety_filter.model.fingertips import fingertip_spheres
from grasp_safety_filter.model.hand_kernel import hand_in_model_order
from grasp_safety_filter.model.urdf import check_urdf_file, HandModelError

__all__ = [
    'Branches', 'FingertipFrames', 'HandModel', 'HandModelError', 'HandTerms', 'RawHandTerms',
]


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

    All but ``M_inverse`` are read-only views of Pinocchio's buffers, overwritten by its next
    call on the hand's data (placements: rows of 12, the rotation column by column then the
    translation; motions: rows of 6, ``(linear, angular)``).

    Attributes:
        frame_placements: Every frame's placement in the palm (``oMf``), (nframes, 12).
        joint_placements: Every joint's placement in the palm (``oMi``), (njoints, 12).
        joint_velocities: Every joint's velocity in its own frame (``v``), (njoints, 6).
        joint_accelerations: Every joint's acceleration at ddq = 0, own frame (``a``),
            (njoints, 6).
        J_joints: The joint Jacobian in the world frame (``J``), (6, nv).
        M_upper: Joint-space inertia, upper triangle only, (nv, nv).
        nle: ``C_h dq + g(q)``, (nv,).
        g: ``g(q)``, (nv,).
        M_inverse: ``M_h^-1``, (nv, nv), full (a new array).
    """

    frame_placements: np.ndarray
    joint_placements: np.ndarray
    joint_velocities: np.ndarray
    joint_accelerations: np.ndarray
    J_joints: np.ndarray
    M_upper: np.ndarray
    nle: np.ndarray
    g: np.ndarray
    M_inverse: np.ndarray


class FingertipFrames(NamedTuple):
    """Where the fingertip frames hang in Pinocchio's model (constants of the hand).

    Attributes:
        frame_index: Each fingertip's frame, (n,).
        parent_joint: Each one's parent joint, (n,).
        offset_in_parent: Each one's origin in its parent joint's frame, (n, 3), m.
        support: Whether Pinocchio's velocity column k moves fingertip i, (n, nv).
    """

    frame_index: np.ndarray
    parent_joint: np.ndarray
    offset_in_parent: np.ndarray
    support: np.ndarray


class Branches(NamedTuple):
    """Which joints can couple to which: spans of the hand's branches, in the caller's order.

    A branch is a subtree of the kinematic tree hanging from the palm: each finger of a hand
    whose fingers all hang from the palm, the whole hand if a wrist joint carries them.
    Joints on different branches are decoupled (``M_h[a, b] = 0`` unless one of a, b
    supports the other), so ``M_h`` and ``M_h^-1`` are block-diagonal by branch, and a
    fingertip's Jacobian is zero outside its branch's joints. A span ``[start, stop)`` is
    the smallest range of joint indices that holds a branch (the whole of it when a branch's
    joints are not listed one after the other): row a of ``M_h^-1`` is zero outside joint
    a's span, and fingertip i's Jacobian outside fingertip i's span.

    Attributes:
        joint_span: Each joint's branch's span, (m, 2).
        fingertip_span: Each fingertip's branch's span (empty for a frame on the palm), (n, 2).
    """

    joint_span: np.ndarray
    fingertip_span: np.ndarray


def _rows_view(elements: Any, attribute: str, width: int) -> np.ndarray:
    """Return a read-only (len, width) view of a Pinocchio vector of SE3 (12) or Motion (6).

    Pinocchio keeps ``data.oMi``, ``data.v`` etc. as contiguous C++ vectors, allocated once
    by ``createData``; each element's ``rotation``/``vector`` is a view of its memory. The
    whole vector is viewed as rows starting at element 0's, after checking that every
    element lies where the rows say (else Pinocchio's layout is not the one assumed).
    """
    first = getattr(elements[0], attribute)
    count = len(elements)
    stride = getattr(elements[1], attribute).ctypes.data - first.ctypes.data if count > 1 else 0
    tail = 'translation' if width == 12 else 'angular'
    tail_at = 9 if width == 12 else 3
    for k in range(count):
        element = elements[k]
        head, rest = getattr(element, attribute), getattr(element, tail)
        if (
            head.ctypes.data != first.ctypes.data + k * stride
            or head.strides[0] != 8
            or rest.ctypes.data != head.ctypes.data + 8 * tail_at
            or stride < 8 * width
        ):
            raise HandModelError(
                f"Pinocchio's data.{attribute} vector is not laid out as expected"
            )
    return as_strided(first, shape=(count, width), strides=(stride, 8), writeable=False)


def _read_only(array: np.ndarray) -> np.ndarray:
    """Return a read-only view of ``array`` (its memory stays shared)."""
    view = array.view()
    view.setflags(write=False)
    return view


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
        #: The hand's URDF (its geometry is drawn from it).
        self.urdf_path = urdf_path
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
        #: The fingertip frames' places in Pinocchio's model (for :func:`hand_in_model_order`).
        self.fingertip_frames = self._fingertip_frames()
        #: Where each joint's and fingertip's branch lies (the contact dynamics' sums).
        self.branches = self._branches()
        # Views of Pinocchio's buffers, which its calls overwrite in place (raw_terms).
        self._buffers = tuple(
            _read_only(array)
            for array in (
                _rows_view(self.data.oMf, 'rotation', 12),
                _rows_view(self.data.oMi, 'rotation', 12),
                _rows_view(self.data.v, 'vector', 6),
                _rows_view(self.data.a, 'vector', 6),
                self.data.J,
                self.data.M,
                self.data.nle,
                self.data.g,
            )
        )
        # The caller's joint order is usually the URDF's: then no reordering copies are needed.
        self._in_pin_order = bool(np.array_equal(self._idx, np.arange(self.model.nv)))
        # Pinocchio's crba fills the upper triangle of M only.
        self._upper = np.triu(np.ones((self.model.nv, self.model.nv), dtype=bool))
        self._check_inertia(urdf_path.name)

    def _fingertip_frames(self) -> FingertipFrames:
        """Return the fingertip frames' parents, offsets and supporting velocity columns."""
        model = self.model
        parents = [model.frames[f].parentJoint for f in self.frame_ids]
        support = np.zeros((len(parents), model.nv), dtype=np.bool_)
        for i, parent in enumerate(parents):
            for joint in list(model.supports[parent])[1:]:  # [0] is the universe
                start = model.joints[joint].idx_v
                support[i, start:start + model.joints[joint].nv] = True
        tables = FingertipFrames(
            frame_index=np.array(self.frame_ids, dtype=np.intp),
            parent_joint=np.array(parents, dtype=np.intp),
            offset_in_parent=np.array(
                [model.frames[f].placement.translation for f in self.frame_ids]
            ).reshape(-1, 3),
            support=support,
        )
        return FingertipFrames(*(_read_only(table) for table in tables))

    def _branches(self) -> Branches:
        """Return each joint's and fingertip's span: where the joints of its branch lie."""
        parents = self.model.parents

        def root(joint: int) -> int:
            while joint != 0 and parents[joint] != 0:
                joint = parents[joint]
            return joint

        branch = [root(self.model.getJointId(name)) for name in self.joint_names]
        spans = {
            b: (branch.index(b), len(branch) - branch[::-1].index(b)) for b in set(branch)
        }
        joint = [spans[b] for b in branch]
        tip = [spans.get(root(self.model.frames[f].parentJoint), (0, 0)) for f in self.frame_ids]
        return Branches(
            *(_read_only(np.array(table, dtype=np.intp).reshape(-1, 2)) for table in (joint, tip))
        )

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
        the kinematics with ddq = 0; M^-1 comes from Pinocchio's Cholesky factor of M, which
        follows the kinematic tree. Four calls; everything else is read from views of
        Pinocchio's buffers, from which :func:`hand_in_model_order` forms the fingertip
        terms (:meth:`terms`, and the compiled grasp terms of
        :mod:`grasp_safety_filter.model.packed_terms`).
        """
        model, data = self.model, self.data
        pin.computeAllTerms(model, data, self._to_pin(q), self._to_pin(dq))
        pin.updateFramePlacements(model, data)
        pin.cholesky.decompose(model, data)
        return RawHandTerms(*self._buffers, pin.cholesky.computeMinv(model, data))

    def terms(self, q: np.ndarray, dq: np.ndarray) -> HandTerms:
        """Everything the grasp model needs from the hand at ``(q, dq)``."""
        dq = np.ascontiguousarray(dq, dtype=np.float64)
        raw = self.raw_terms(q, dq)
        p_f, R_f, J, twist, J_dot_dq, M, M_inv, h_bias, gravity = hand_in_model_order(
            raw, self.fingertip_frames, self.pinocchio_index, dq
        )
        return HandTerms(
            M_h=M,
            h_bias=h_bias,
            gravity_torque=gravity,
            p_fingertip_in_palm=p_f,
            R_fingertip_to_palm=R_f,
            J_fingertip=J,
            twist_fingertip=twist,
            J_fingertip_dot_dq=J_dot_dq,
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
