"""Is a state of the model a grasp? The start-up check, one finding per problem.

At its first state a run must hold the object the way the model assumes (DESIGN.md §3):

- every joint strictly inside its URDF limits;
- per contact, the fingertip sphere touches its object surface: the gap (or the
  penetration) between them is at most :data:`GAP_TOLERANCE`;
- per contact on a box face, the contact point lies on that face, within its edges (the
  model's chart of a face is the whole plane: without this check a fingertip far from the
  object, touching the face's plane, would pass), and a face declared in
  ``model.contact_faces`` is the face nearest to the fingertip;
- per contact, the fingertip coordinates are inside the fingertip workspace;
- the hand's inertia M_h is positive definite, J_h has full row rank 3n (every contact
  velocity reachable; a free finger's joints add zero columns) and G has rank 6 (the
  contacts can move the object in every direction);
- force closure with each contact's own friction coefficient mu_i: some squeeze keeps every
  contact force strictly inside its friction pyramid.

:func:`grasp_findings` returns what fails, each naming the joint or contact and the distance;
:func:`check_grasp` raises them as one :class:`GraspConfigError`. The paper's initial grasp
passes with a gap of 3e-16 m, its contacts at the face centres (0.13 m from every edge),
0.29 rad from the nearest joint limit, cond(J_h) = 6.1 and cond(G) = 16.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import daqp
import numpy as np

from grasp_safety_filter.model.grasp_model import GraspConfigError, GraspModel
from grasp_safety_filter.model.quaternion import rotation_matrix
from grasp_safety_filter.model.rolling import ContactGeometry
from grasp_safety_filter.model.surfaces import CUBE_FACE_AXES, FlatSurface, Surface

#: Largest gap or penetration between a fingertip and its object surface at start, m.
#: The simulator then moves the joints by the least amount that closes it exactly
#: (``GraspModel.project_to_contact``); a larger one means the configured grasp is not the
#: one the user meant (a wrong object position, face or fingertip frame). A millimetre is
#: 1/60 of the paper's fingertip radius and far above the paper's 3e-16 m.
GAP_TOLERANCE = 1e-3

#: Faces of the friction pyramid inscribed in each cone for the force-closure check (the
#: safety filter's default ``no_slip.pyramid_faces``).
FORCE_CLOSURE_PYRAMID_FACES = 8

#: What a start-up check describes, for the messages.
INITIAL_GRASP = 'initial grasp (initial.joint_positions, initial.object_position/orientation)'


@dataclass(frozen=True)
class GraspFinding:
    """One way a state is not a valid grasp.

    Attributes:
        subject: What it concerns: ``"joint 'finger1_joint2'"``, ``"contact 'finger1'"``,
            ``"hand"``.
        problem: What is wrong, with the values.
    """

    subject: str
    problem: str

    def __str__(self) -> str:
        return f'{self.subject}: {self.problem}'


def _face_label(surface: FlatSurface) -> str:
    """Name the box face (``"face +x"``...) with ``surface``'s outward normal, or ``"plane"``."""
    for label, (axis, sign) in CUBE_FACE_AXES.items():
        if surface.normal[axis] * sign > 1.0 - 1e-9:
            return f'face {label}'
    return 'plane'


def _declared_face_findings(
    model: GraspModel, q: np.ndarray, p_object_in_palm: np.ndarray, R_object_to_palm: np.ndarray
) -> list[GraspFinding]:
    """Find each declared ``model.contact_faces`` face that is not its fingertip's nearest."""
    shape = model.object_shape
    if shape is None or not shape.has_faces:
        return []
    p_f, _, _ = model.hand.fingertip_placements(np.asarray(q, dtype=float))
    p_centres = (p_f - np.asarray(p_object_in_palm, dtype=float)) @ np.asarray(R_object_to_palm)
    findings = []
    for name, face, p in zip(model.contact_names, model.declared_faces, p_centres, strict=True):
        nearest = shape.nearest_face(p)
        if face is not None and face != nearest:
            findings.append(
                GraspFinding(
                    f'contact {name!r}',
                    f'model.contact_faces declares face {face!r}, but the fingertip is nearest '
                    f'face {nearest!r} (expected the declared face to be the nearest, or '
                    "'nearest')",
                )
            )
    return findings


def grasp_findings(
    model: GraspModel,
    q: Sequence[float] | np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    gap_tolerance: float = GAP_TOLERANCE,
) -> list[GraspFinding]:
    """Every way the configuration ``(q, p_o, R_po)`` is not a grasp of the model's object.

    Joint and contact findings come first; the hand's terms (M_h, ranks of J_h and G) are
    checked only when the geometry is right, since they are meaningless otherwise.

    Raises:
        GraspConfigError: ``q`` does not have one angle per joint.
    """
    q = np.asarray(q, dtype=float)
    if q.shape != (model.n_joints,):
        raise GraspConfigError(
            f'{INITIAL_GRASP}: expected {model.n_joints} joint angles ({model.joint_names}), '
            f'got {q.size}'
        )
    findings = []
    for name, value, lower, upper in zip(
        model.joint_names, q, model.joint_lower_limits, model.joint_upper_limits, strict=True
    ):
        if not lower < value < upper:
            findings.append(
                GraspFinding(
                    f'joint {name!r}',
                    f'{value:.6g} rad is not inside its limits ({lower:.6g}, {upper:.6g})',
                )
            )
    geometries = model.contact_geometry(q, p_object_in_palm, R_object_to_palm)
    # A declared face that is not the nearest one comes first among its contact's findings
    # (the gap and edge findings on the wrong face are its consequences).
    wrong_face = {
        finding.subject: finding
        for finding in _declared_face_findings(model, q, p_object_in_palm, R_object_to_palm)
    }
    boxes = model.fingertip_workspace.per_contact(model.n_contacts)
    for name, contact, geometry, box in zip(
        model.contact_names, model.contacts, geometries, boxes, strict=True
    ):
        subject = f'contact {name!r}'
        findings += [wrong_face[subject]] if subject in wrong_face else []
        findings += _contact_findings(
            subject, contact.object_surface, geometry, box, gap_tolerance
        )
    if findings:
        return findings
    return hand_findings(model, q, p_object_in_palm, R_object_to_palm)


def _contact_findings(
    subject: str,
    surface: Surface,
    geometry: ContactGeometry,
    box: np.ndarray,
    gap_tolerance: float,
) -> list[GraspFinding]:
    """Gap or penetration, position on the face and in the fingertip workspace of a contact.

    ``box`` is the contact's own workspace ``(a_min, a_max, b_min, b_max)``, rad.
    """
    findings = []
    where = _face_label(surface) if isinstance(surface, FlatSurface) else 'sphere'
    depth = float(geometry.penetration)
    if depth < -gap_tolerance:
        findings.append(
            GraspFinding(
                subject,
                f'the fingertip is separated from the object by {-depth:.3g} m ({where}; '
                f'expected touching within {gap_tolerance:g} m)',
            )
        )
    elif depth > gap_tolerance:
        findings.append(
            GraspFinding(
                subject,
                f'the fingertip penetrates the object by {depth:.3g} m ({where}; expected '
                f'touching within {gap_tolerance:g} m)',
            )
        )
    if isinstance(surface, FlatSurface):
        outside = surface.outside_distance(geometry.xi_co)
        if outside > 0.0:
            u, v = geometry.xi_co
            h_u, h_v = surface.half_widths
            findings.append(
                GraspFinding(
                    subject,
                    f'the contact point lies {outside:.3g} m beyond the edge of {where} '
                    f'((u, v) = ({u:.4f}, {v:.4f}) m, expected |u| <= {h_u:.4g} m and '
                    f'|v| <= {h_v:.4g} m about its centre)',
                )
            )
    a, b = geometry.xi_cf
    a_min, a_max, b_min, b_max = box.tolist()
    if not (a_min < a < a_max and b_min < b < b_max):
        findings.append(
            GraspFinding(
                subject,
                f'fingertip coordinates (a, b) = ({a:.4g}, {b:.4g}) rad are outside its '
                f'fingertip workspace (model.fingertip_workspace: a in ({a_min:.4g}, '
                f'{a_max:.4g}), b in ({b_min:.4g}, {b_max:.4g}))',
            )
        )
    return findings


def hand_findings(
    model: GraspModel, q: np.ndarray, p_object_in_palm: np.ndarray, R_object_to_palm: np.ndarray
) -> list[GraspFinding]:
    """M_h positive definite, rank J_h = 3n, rank G = 6 at the configuration, at rest."""
    try:
        with np.errstate(all='ignore'):
            state = model.state(
                0.0, q, np.zeros(model.n_joints), p_object_in_palm, R_object_to_palm, np.zeros(6)
            )
    except np.linalg.LinAlgError:
        return [
            GraspFinding(
                'hand',
                'B_ho = J_h M_h^-1 J_h^T + G^T M_o^-1 G is singular: the contact forces are not '
                'determined',
            )
        ]
    terms = {'M_h': state.M_h, 'J_h': state.J_h, 'G': state.G, 'B_ho': state.B_ho}
    infinite = [name for name, matrix in terms.items() if not np.all(np.isfinite(matrix))]
    if infinite:
        return [GraspFinding('hand', f'{", ".join(infinite)} not finite')]
    findings = []
    smallest = float(np.linalg.eigvalsh(state.M_h)[0])
    if not smallest > 0.0:
        findings.append(
            GraspFinding(
                'hand', f'M_h is not positive definite (smallest eigenvalue {smallest:.3g})'
            )
        )
    n = model.n_contacts
    # The force rows: a soft finger's torsion rows only add to what they can hold.
    J_h, G = state.J_h[: 3 * n], state.G[:, : 3 * n]
    rank = int(np.linalg.matrix_rank(J_h))
    if rank < 3 * n:
        findings.append(
            GraspFinding(
                'hand',
                f'J_h has rank {rank}, expected {3 * n} (3 per contact): a finger is at a '
                'singular configuration',
            )
        )
    rank = int(np.linalg.matrix_rank(G))
    if rank < 6:
        findings.append(
            GraspFinding(
                'hand',
                f'the grasp map G has rank {rank}, expected 6: the contacts cannot move the '
                'object in every direction',
            )
        )
    elif not squeezes_inside_friction_cones(G, model.friction_coefficient):
        mu = model.friction_coefficient.tolist()
        findings.append(
            GraspFinding(
                'hand',
                'no force closure: no squeeze (internal force, G f = 0) keeps every contact '
                f'force inside its friction pyramid (mu = {mu} per contact, '
                f'{FORCE_CLOSURE_PYRAMID_FACES} faces): expected contacts on opposing faces '
                'or a larger model.friction_coefficient',
            )
        )
    return findings


def squeezes_inside_friction_cones(G: np.ndarray, mu: np.ndarray) -> bool:
    """Whether some internal force lies strictly inside every contact's friction pyramid.

    With G of rank 6 this is force closure (Murray, Li & Sastry, *A Mathematical
    Introduction to Robotic Manipulation*, 1994, Prop. 5.2): squeezing with that force,
    scaled, balances any wrench. Internal forces are ``f = N z`` with N an orthonormal basis
    of null(G); since the pyramids are cones, a force strictly inside all of them exists iff
    one with every face margin ``mu_i cos(pi / l) f_n,i - cos(th_j) f_x,i - sin(th_j) f_y,i
    >= 1`` does: a QP in z (least norm) that DAQP solves or proves infeasible.

    Args:
        G: The grasp map, (6, 3n).
        mu: Each contact's friction coefficient, (n,).
    """
    n = mu.size
    _, singular, vt = np.linalg.svd(G)
    rank = int(np.count_nonzero(singular > singular[0] * max(G.shape) * np.finfo(float).eps))
    null_basis = vt[rank:].T  # (3n, 3n - rank), orthonormal
    if null_basis.shape[1] == 0:
        return False
    faces = FORCE_CLOSURE_PYRAMID_FACES
    theta = 2.0 * np.pi * np.arange(faces) / faces
    # Face rows per contact, (n, l, 3): margin_ij = rows_ij . f_i.
    rows = np.empty((n, faces, 3))
    rows[:, :, 0] = -np.cos(theta)
    rows[:, :, 1] = -np.sin(theta)
    rows[:, :, 2] = (mu * np.cos(np.pi / faces))[:, np.newaxis]
    A = np.zeros((n * faces, 3 * n))
    for i in range(n):
        A[i * faces : (i + 1) * faces, 3 * i : 3 * i + 3] = rows[i]
    A_z = A @ null_basis
    k = null_basis.shape[1]
    _, _, flag, _ = daqp.solve(
        np.eye(k), np.zeros(k), A_z, np.full(n * faces, 1e30), np.ones(n * faces)
    )
    return flag > 0


def check_grasp(
    model: GraspModel,
    q: Sequence[float] | np.ndarray,
    p_object_in_palm: np.ndarray,
    R_object_to_palm: np.ndarray,
    gap_tolerance: float = GAP_TOLERANCE,
    what: str = INITIAL_GRASP,
) -> None:
    """Raise one GraspConfigError listing every :func:`grasp_findings`; return if none.

    Args:
        model: The grasp model.
        q: Joint angles, model order, rad.
        p_object_in_palm: Object position, m.
        R_object_to_palm: Object orientation.
        gap_tolerance: Largest gap or penetration per contact, m.
        what: What the state is, at the start of the message.
    """
    findings = grasp_findings(model, q, p_object_in_palm, R_object_to_palm, gap_tolerance)
    if findings:
        raise GraspConfigError(f'{what}: ' + '; '.join(map(str, findings)))


def check_initial_grasp(
    model: GraspModel, params: Mapping[str, Any], gap_tolerance: float = GAP_TOLERANCE
) -> None:
    """Check the initial grasp of ``hand_sim_node``'s validated parameters (:func:`check_grasp`).

    Raises:
        GraspConfigError: Listing every finding, each naming its joint or contact.
    """
    check_grasp(
        model,
        params['initial.joint_positions'],
        np.asarray(params['initial.object_position'], dtype=float),
        rotation_matrix(params['initial.object_orientation']),
        gap_tolerance,
    )


def load_initial_grasp(
    config: Path, overrides: Mapping[str, Any] | None = None
) -> tuple[GraspModel, dict[str, Any]]:
    """Load a scenario file's simulator parameters and model; check its initial grasp.

    The start-up check of the ROS-free tools, as ``hand_sim_node`` makes it.

    Args:
        config: The scenario parameter file.
        overrides: ``{key: value}`` of any node; those that apply to ``hand_sim_node``
            (its names, and ``hand_sim_node/NAME``: :func:`~grasp_safety_filter.io.schemas.
            node_overrides`) do.

    Returns:
        The model and the validated ``hand_sim_node`` parameters.

    Raises:
        ConfigError: The file, an override, the URDF or the initial grasp is wrong (a
            ``ParameterError``, ``HandModelError`` or ``GraspConfigError``).
    """
    from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters, node_overrides

    own = node_overrides(overrides or {}, HAND_SIM_NODE)
    params = load_node_parameters(config, HAND_SIM_NODE, overrides=own)
    model = GraspModel.from_parameters(params)
    check_initial_grasp(model, params)
    return model, params
