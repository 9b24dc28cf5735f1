"""Inverse kinematics on the project's hand model, and the fingertip frames set after it.

:func:`solve_fingertip_centres` finds joint angles that put every fingertip sphere's centre
at its target, with the package's own kinematics (:meth:`~grasp_safety_filter.model.hand.
HandModel.fingertip_placements`: Pinocchio's forward kinematics and frame Jacobians) and
SciPy's bounded trust-region least squares, from random starts. A finger's solution counts
when its centre is within :data:`IK_TOLERANCE` of the target, its joints' and links'
midpoints stay out of the object and above the palm, and its position Jacobian is not near
singular; fingers are independent, so each restart solves only the fingers still unsolved.

:func:`tip_rotation` turns a fingertip frame so that the contact lies at chosen fingertip
coordinates ``(a, b)`` of the chart ``c(a, b) = R (-cos a cos b, sin a, -cos a sin b)``,
its z axis as close as that allows to the distal link's.
"""

from __future__ import annotations

from collections.abc import Sequence
import math

import numpy as np
from scipy.optimize import least_squares
from scipy.spatial.transform import Rotation

from grasp_safety_filter.model.hand import HandModel
from grasp_tools.hands.kinematics import FingerDesign
from grasp_tools.hands.objects import DrawRejectedError, ObjectDesign

#: Largest distance of a solved fingertip centre from its target, m.
IK_TOLERANCE = 1e-10
#: Least distance of a joint or link midpoint from the object's surface, m.
LINK_CLEARANCE = 0.004
#: Least singular value of a finger's fingertip-centre position Jacobian, m/rad.
MIN_SINGULAR_VALUE = 0.004
#: Where the solver may look: joint 1 (abduction or rotation), then the flexions, rad.
SEARCH_BOUNDS = {'first': (-0.7, 0.7), 'flexion': (-0.3, 1.9)}


def signed_distance(obj: ObjectDesign, p_in_palm: np.ndarray) -> np.ndarray:
    """Signed distance of points (k, 3) from the object's surface, positive outside, m."""
    p = (np.atleast_2d(p_in_palm) - obj.p_object_in_palm) @ obj.R_object_to_palm
    if obj.shape == 'sphere':
        return np.linalg.norm(p, axis=1) - obj.radius
    excess = np.abs(p) - 0.5 * np.asarray(obj.edge_lengths)
    outside = np.linalg.norm(np.maximum(excess, 0.0), axis=1)
    return outside + np.minimum(excess.max(axis=1), 0.0)


def search_bounds(fingers: Sequence[FingerDesign]) -> tuple[np.ndarray, np.ndarray]:
    """Return the solver's box of joint angles, in the hand's joint order, rad."""
    lower, upper = [], []
    for finger in fingers:
        for k in range(finger.n_joints):
            lo, hi = SEARCH_BOUNDS['first' if k == 0 else 'flexion']
            lower.append(lo)
            upper.append(hi)
    return np.array(lower), np.array(upper)


def solve_fingertip_centres(
    rng: np.random.Generator,
    hand: HandModel,
    fingers: Sequence[FingerDesign],
    p_target_in_palm: np.ndarray,
    obj: ObjectDesign,
    restarts: int = 12,
) -> np.ndarray:
    """Joint angles (m,), rad, that put each fingertip sphere centre on its target.

    Args:
        rng: Draws the random starts.
        hand: The hand model, fingertip frames at the spheres' centres, joints finger by
            finger in ``fingers`` order.
        fingers: The fingers, in contact order.
        p_target_in_palm: The sphere centres' targets, (n, 3), m.
        obj: The object the links must stay out of.
        restarts: Random starts per finger before giving up.

    Raises:
        DrawRejectedError: A finger has no acceptable solution after ``restarts`` starts.
    """
    lower, upper = search_bounds(fingers)
    spans = np.cumsum([0, *(finger.n_joints for finger in fingers)])
    n = len(fingers)

    def residual(q: np.ndarray) -> np.ndarray:
        p, _, _ = hand.fingertip_placements(q)
        return (p - p_target_in_palm).ravel()

    def jacobian(q: np.ndarray) -> np.ndarray:
        _, _, J = hand.fingertip_placements(q)
        return J[:, :3, :].reshape(3 * n, -1)

    q = rng.uniform(lower, upper)
    solved = np.zeros(n, dtype=bool)
    for _ in range(restarts):
        result = least_squares(
            residual, q, jac=jacobian, bounds=(lower, upper), method='trf',
            xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=200,
        )  # fmt: skip
        accepted = _acceptable(hand, fingers, result.x, p_target_in_palm, obj)
        for i in range(n):
            block = slice(spans[i], spans[i + 1])
            if not solved[i] and accepted[i]:
                q[block] = result.x[block]
                solved[i] = True
            elif not solved[i]:
                q[block] = rng.uniform(lower[block], upper[block])
        if solved.all():
            return q
    raise DrawRejectedError('inverse kinematics')


def _acceptable(
    hand: HandModel,
    fingers: Sequence[FingerDesign],
    q: np.ndarray,
    p_target_in_palm: np.ndarray,
    obj: ObjectDesign,
) -> np.ndarray:
    """Whether each finger's part of ``q`` is a solution (module docstring), (n,)."""
    p, _, J = hand.fingertip_placements(q)  # also Pinocchio's joint placements, data.oMi
    ok = np.linalg.norm(p - p_target_in_palm, axis=1) <= IK_TOLERANCE
    for i, finger in enumerate(fingers):
        joints = [hand.model.getJointId(name) for name in finger.joint_names]
        origins = np.array([hand.data.oMi[j].translation for j in joints] + [p[i]])
        points = np.vstack((origins, 0.5 * (origins[1:] + origins[:-1])))
        clear = signed_distance(obj, points).min() >= LINK_CLEARANCE
        above = points[:, 2].min() >= 0.0
        columns = [hand.joint_names.index(name) for name in finger.joint_names]
        smallest = np.linalg.svd(J[i, :3][:, columns], compute_uv=False)[-1]
        ok[i] &= clear and above and smallest >= MIN_SINGULAR_VALUE
    return ok


def chart_direction(a: float, b: float) -> np.ndarray:
    """Return the fingertip chart's unit direction at ``(a, b)`` in the fingertip frame."""
    return np.array([-math.cos(a) * math.cos(b), math.sin(a), -math.cos(a) * math.sin(b)])


def tip_rotation(
    R_distal_to_palm: np.ndarray, n_outward_in_palm: np.ndarray, a: float, b: float
) -> np.ndarray:
    """``R_tip_to_palm`` putting the contact at fingertip coordinates ``(a, b)`` (rad).

    The contact direction from the sphere's centre is ``-n`` (n the object's outward normal);
    among the rotations that map the chart direction at ``(a, b)`` onto it, the one whose z
    axis is nearest the distal link's.
    """
    rotation, _ = Rotation.align_vectors(
        [-np.asarray(n_outward_in_palm), R_distal_to_palm[:, 2]],
        [chart_direction(a, b), [0.0, 0.0, 1.0]],
        weights=[np.inf, 1.0],
    )
    return rotation.as_matrix()
