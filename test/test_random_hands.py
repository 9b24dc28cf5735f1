"""The model, the filter and the start-up checks on random hands (test/random_hands.py).

Every hand is drawn from a seed: 3–5 fingers of 3–4 joints, random axes, links, masses,
fingertip spheres, joint order, and a box or sphere object every fingertip touches. What is
checked against what the package did not compute itself:

- the generator's grasp against Pinocchio's own collision placements and the object's
  geometry written out here, and the start-up check passes it;
- M_h and g(q) against the link data (this file's kinematics), C_h dq against the Lagrangian
  ``M_dot dq - 1/2 d/dq (dq^T M dq)`` of that mass matrix;
- Jacobians, G, the rolling rates and xi_cf_ddot against finite differences along rolling
  motions, G against the wrench of forces at the contact points found from the geometry;
- the filter's rows against their documented formulas and u* against two exact QP solvers;
- the nominal torque against the object acceleration of the model's constrained dynamics;
- each configuration mistake refused at start naming its contact, link or parameter, and
  odometry of another object frame refused by the controller and the filter;
- the unactuated plant's energy against ode3's order of accuracy, and a short closed-loop
  run of the lockstep runner with the filter on.
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
import re

from grasp_states import Configuration, moved
import numpy as np
import pinocchio as pin
import pytest
from qp_reference import chebyshev_radius, hard_optimum, relaxed_optimum
from random_hands import random_hand, RandomHand, rotation_about, write_scenario
from test_endpoints import make_filter, make_nominal, make_sim, statuses, through_cdr
from test_filter_on_model import CONFIGS, independent_residuals, independent_rows, row_weights

from grasp_safety_filter.analysis.run_data import load_run
from grasp_safety_filter.control.nominal import NominalConfig, NominalController
from grasp_safety_filter.control.reference import ReferenceSample
from grasp_safety_filter.control.safety_filter import SafetyFilter
from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io.schemas import load_node_parameters
from grasp_safety_filter.model.grasp_check import grasp_findings, load_initial_grasp
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.runner import record_run, RunOptions
from hand_sim_node.config import SimConfig
from hand_sim_node.simulator import Simulator

SEEDS = tuple(range(16))
N_CONFIGURATIONS = 3
EPS = 1e-6
RTOL = 1e-5
#: A box's side faces: the object axis of the outward normal and its sign.
FACE_AXES = {'+x': (0, 1.0), '-x': (0, -1.0), '+y': (1, 1.0), '-y': (1, -1.0)}


@dataclasses.dataclass(frozen=True)
class Case:
    """A random hand, its written scenario, its model and rolling configurations near the grasp."""

    hand: RandomHand
    directory: Path
    params: dict
    model: GraspModel
    configurations: list[Configuration]


def near_grasp(
    case_hand: RandomHand, model: GraspModel, rng: np.random.Generator, count: int
) -> list[Configuration]:
    """Return grasps near the initial one: object moved, fingertips projected, rolling."""
    found = []
    for _ in range(50 * count):
        p_object = case_hand.p_object + rng.uniform(-0.003, 0.003, 3)
        R_object = pin.exp3(rng.uniform(-0.05, 0.05, 3)) @ case_hand.R_object
        q_guess = case_hand.q0 + rng.uniform(-0.03, 0.03, case_hand.q0.size)
        q = model.project_to_contact(q_guess, p_object, R_object)
        if grasp_findings(model, q, p_object, R_object, gap_tolerance=1e-9):
            continue
        twist = rng.normal(0.0, 0.3, 6) * np.array([0.1, 0.1, 0.1, 1.0, 1.0, 1.0])
        dq = model.rolling_joint_velocity(q, p_object, R_object, twist)
        found.append(Configuration(q, dq, p_object, R_object, twist))
        if len(found) == count:
            return found
    raise AssertionError(f'seed {case_hand.seed}: no grasp near the initial one')


@pytest.fixture(scope='module', params=SEEDS, ids=[f'seed{s}' for s in SEEDS])
def case(request, tmp_path_factory) -> Case:
    hand = random_hand(request.param)
    directory = tmp_path_factory.mktemp(f'hand{request.param}')
    path = hand.write(directory)
    params = {**hand.model_parameters(path), **hand.initial_parameters()}
    model = GraspModel.from_parameters(params)
    rng = np.random.default_rng(1000 + request.param)
    return Case(hand, directory, params, model, near_grasp(hand, model, rng, N_CONFIGURATIONS))


def central(f, c: Configuration, **kwargs) -> np.ndarray:
    after, before = moved(c, EPS, **kwargs), moved(c, -EPS, **kwargs)
    return (np.asarray(f(after)) - np.asarray(f(before))) / (2 * EPS)


def assert_close(actual, expected, what: str, rtol: float = RTOL) -> None:
    actual, expected = np.asarray(actual), np.asarray(expected)
    scale = max(float(np.max(np.abs(expected))), 1e-3)
    error = float(np.max(np.abs(actual - expected))) / scale
    assert error <= rtol, f'{what}: relative error {error:.2e} > {rtol:g}\n{actual}\n{expected}'


def outward_normals(
    hand, p_sphere: np.ndarray, p_object: np.ndarray, R_object: np.ndarray
) -> np.ndarray:
    """Return the object's outward normal at each contact (palm frame) from its geometry."""
    if hand.shape == 'sphere':
        d = p_sphere - p_object
        return d / np.linalg.norm(d, axis=1, keepdims=True)
    return np.array([FACE_AXES[f][1] * R_object[:, FACE_AXES[f][0]] for f in hand.faces])


# -- the generator's grasp -------------------------------------------------------------------


def test_each_fingertip_touches_the_object_by_pinocchios_collision_model(case):
    """Pinocchio's placements of the URDF's collision spheres: on the object, at its radius."""
    hand, urdf = case.hand, case.params['model.urdf_file']
    model = pin.buildModelFromUrdf(urdf)
    geometry = pin.buildGeomFromUrdf(model, urdf, pin.GeometryType.COLLISION)
    data, geometry_data = model.createData(), pin.GeometryData(geometry)
    q = np.empty(model.nq)
    for name, value in zip(hand.joint_names, hand.q0, strict=True):
        q[model.idx_qs[model.getJointId(name)]] = value
    pin.updateGeometryPlacements(model, data, geometry, geometry_data, q)
    spheres = {
        g.name.rsplit('_', 1)[0]: (geometry_data.oMg[k].translation, g.geometry.radius)
        for k, g in enumerate(geometry.geometryObjects)
    }
    for finger, p_ours in zip(hand.fingers, hand.sphere_centres(hand.q0), strict=True):
        link = f'{finger.name}_tip' if finger.sphere_on_tip else f'{finger.name}_distal'
        centre, radius = spheres[link]
        np.testing.assert_allclose(centre, p_ours, rtol=0, atol=1e-12)
        assert radius == finger.radius and 0.01 <= radius <= 0.03
    centres = hand.sphere_centres(hand.q0)
    radii = np.array([f.radius for f in hand.fingers])
    if hand.shape == 'sphere':
        distance = np.linalg.norm(centres - hand.p_object, axis=1) - hand.object_radius
    else:
        # Over its face (inside the face's edges), one radius in front of the face's plane.
        half = 0.5 * np.array(hand.edge_lengths)
        in_object = (centres - hand.p_object) @ hand.R_object
        axes = [FACE_AXES[face][0] for face in hand.faces]
        signs = np.array([FACE_AXES[face][1] for face in hand.faces])
        rows = np.arange(len(centres))
        distance = signs * in_object[rows, axes] - half[axes]
        lateral = np.abs(in_object).copy()
        lateral[rows, axes] = 0.0
        assert np.all(lateral < half), lateral
    np.testing.assert_allclose(distance, radii, rtol=0, atol=1e-12)
    assert grasp_findings(case.model, hand.q0, hand.p_object, hand.R_object) == []


# -- hand terms ------------------------------------------------------------------------------


def test_mass_matrix_gravity_and_bias_match_the_link_data(case):
    """M_h and g from the URDF's link data (this file), C_h dq from the Lagrangian of that M."""
    hand = case.hand
    for c in case.configurations:
        state = c.state(case.model)
        M, g = hand.mass_matrix(c.q)
        assert_close(state.M_h, M, 'M_h', rtol=1e-10)
        assert_close(state.gravity_torque, g, 'g(q)', rtol=1e-10)
    for c in case.configurations[:1]:
        state = c.state(case.model)
        # C_h dq = M_dot dq - 1/2 grad_q (dq^T M(q) dq), both by central differences.
        h = 1e-6
        M_dot = (hand.mass_matrix(c.q + h * c.dq)[0] - hand.mass_matrix(c.q - h * c.dq)[0]) / (
            2 * h
        )
        gradient = np.array(
            [
                c.dq @ (hand.mass_matrix(c.q + h * e)[0] - hand.mass_matrix(c.q - h * e)[0]) @ c.dq
                for e in np.eye(c.q.size)
            ]
        ) / (2 * h)
        coriolis = M_dot @ c.dq - 0.5 * gradient
        assert_close(state.h_bias - state.gravity_torque, coriolis, 'C_h dq', rtol=1e-5)


# -- kinematics against finite differences ---------------------------------------------------


def test_fingertip_jacobians_match_finite_differences(case):
    model = case.model
    for c in case.configurations:
        state = c.state(model)
        v = central(lambda x: model.hand.fingertip_placements(x.q)[0], c)
        R_plus = model.hand.fingertip_placements(moved(c, EPS).q)[1]
        R_minus = model.hand.fingertip_placements(moved(c, -EPS).q)[1]
        w = np.array([pin.log3(P @ N.T) / (2 * EPS) for P, N in zip(R_plus, R_minus, strict=True)])
        # The fingertip frames are at the sphere centres of this file's kinematics.
        np.testing.assert_allclose(
            state.p_fingertip_in_palm, case.hand.sphere_centres(c.q), rtol=0, atol=1e-12
        )
        for i in range(model.n_contacts):
            twist = state.J_fingertip[i] @ c.dq
            assert_close(twist, np.concatenate([v[i], w[i]]), f'J_s[{i}] dq')


def test_hand_jacobian_and_grasp_map_match_material_point_velocities(case):
    model = case.model
    for c in case.configurations:
        state = c.state(model)
        for i in range(model.n_contacts):
            rows = slice(3 * i, 3 * i + 3)
            p_c, R_cp = state.p_contact_in_palm[i], state.R_contact_to_palm[i].T
            in_tip = state.R_fingertip_to_palm[i].T @ (p_c - state.p_fingertip_in_palm[i])

            def finger_point(x, i=i, in_tip=in_tip):
                p, R, _ = model.hand.fingertip_placements(x.q)
                return p[i] + R[i] @ in_tip

            assert_close(state.J_h[rows] @ c.dq, R_cp @ central(finger_point, c), f'J_h[{i}]')
            in_object = c.R_object.T @ (p_c - c.p_object)
            velocity = central(lambda x, r=in_object: x.p_object + x.R_object @ r, c)
            assert_close(state.G[:, rows].T @ c.twist_object, R_cp @ velocity, f'G[{i}]')
        np.testing.assert_allclose(state.J_h @ c.dq, state.G.T @ c.twist_object, atol=1e-10)


def test_grasp_map_is_the_wrench_of_forces_at_the_geometric_contact_points(case):
    """Contact points and normals from the object's geometry; the wrench summed directly."""
    rng = np.random.default_rng(case.hand.seed)
    for c in case.configurations:
        state = c.state(case.model)
        centres = case.hand.sphere_centres(c.q)
        normals = outward_normals(case.hand, centres, c.p_object, c.R_object)
        radii = np.array([f.radius for f in case.hand.fingers])
        p_contact = centres - radii[:, None] * normals
        np.testing.assert_allclose(state.p_contact_in_palm, p_contact, rtol=0, atol=1e-10)
        np.testing.assert_allclose(state.R_contact_to_palm[:, :, 2], -normals, atol=1e-10)
        f = rng.normal(size=3 * case.model.n_contacts)
        forces = np.einsum('ijk,ik->ij', state.R_contact_to_palm, f.reshape(-1, 3))
        torque = np.cross(p_contact - c.p_object, forces).sum(axis=0)
        np.testing.assert_allclose(
            state.G @ f, np.concatenate([forces.sum(axis=0), torque]), rtol=0, atol=1e-12
        )


def test_jacobian_time_derivatives_match_finite_differences(case):
    for c in case.configurations:
        state = c.state(case.model)
        assert_close(
            state.Jh_dot_dq, central(lambda x: x.state(case.model).J_h, c) @ c.dq, 'J_h_dot dq'
        )
        G_dot = central(lambda x: x.state(case.model).G, c)
        assert_close(state.G_dot_T_twist, G_dot.T @ c.twist_object, 'G_dot^T x_o_dot')


def test_rolling_rates_match_the_geometric_coordinates(case):
    model = case.model
    for c in case.configurations:
        state = c.state(model)

        def coordinates(x):
            return np.array(
                [
                    np.concatenate([g.xi_cf, g.xi_co, [g.psi]])
                    for g in model.contact_geometry(x.q, x.p_object, x.R_object)
                ]
            )

        rates = central(coordinates, c)
        for i in range(model.n_contacts):
            assert_close(state.xi_cf_dot[i], rates[i, :2], f'xi_cf_dot[{i}]')
            assert_close(state.xi_co_dot[i], rates[i, 2:4], f'xi_co_dot[{i}]')
            assert_close(state.psi_dot[i], rates[i, 4], f'psi_dot[{i}]')


def test_contact_coordinate_accelerations_match_finite_differences(case):
    rng = np.random.default_rng(case.hand.seed + 1)
    for c in case.configurations:
        state = c.state(case.model)
        u = rng.normal(0.0, 0.3, case.model.n_joints)
        ddq, x_ddot = state.joint_acceleration(u), state.object_acceleration(u)
        rate = central(lambda x: x.state(case.model).xi_cf_dot, c, ddq=ddq, x_ddot=x_ddot)
        assert_close(state.xi_cf_ddot(u).reshape(-1, 2), rate, 'xi_cf_ddot')


def test_accelerations_obey_both_dynamics_and_pinocchios_forward_dynamics(case):
    rng = np.random.default_rng(case.hand.seed + 2)
    hand = case.model.hand
    for c in case.configurations:
        state = c.state(case.model)
        u = rng.normal(0.0, 0.3, case.model.n_joints)
        f_c, ddq, x_ddot = (
            state.contact_force(u),
            state.joint_acceleration(u),
            state.object_acceleration(u),
        )
        np.testing.assert_allclose(
            state.J_h @ ddq + state.Jh_dot_dq,
            state.G.T @ x_ddot + state.G_dot_T_twist,
            atol=1e-8,
        )
        np.testing.assert_allclose(
            state.M_o @ x_ddot + state.C_o_twist, state.G @ f_c + state.w_e, atol=1e-10
        )
        tau = np.empty(hand.model.nv)
        tau[hand._idx] = u - state.J_h.T @ f_c
        ddq_pin = pin.aba(hand.model, hand.data, hand._to_pin(c.q), hand._to_pin(c.dq), tau)
        np.testing.assert_allclose(
            ddq, ddq_pin[hand._idx], rtol=0, atol=1e-8 * (1 + abs(ddq).max())
        )


# -- the filter ------------------------------------------------------------------------------


def test_filter_rows_and_optimum_match_the_formulas_and_two_exact_solvers(case):
    """Every family on: rows against their definitions, u* against daqp and Goldfarb-Idnani.

    u_nom is drawn around the centre of the largest ball in the feasible set (an LP), inside
    and outside it; where the hard QP is infeasible the relaxed optimum is the reference.
    """
    model = case.model
    config = CONFIGS['cubic' if case.hand.seed % 2 else 'linear']
    assert config.no_slip_enabled and config.joint_limits_enabled
    assert config.fingertip_workspace_enabled
    filter_ = SafetyFilter.from_config(model, config)
    effort = np.asarray(model.effort_limits, dtype=float)
    rng = np.random.default_rng(case.hand.seed + 3)
    for c in case.configurations:
        state = c.state(model)
        names, A, lower = independent_rows(model, config, state)
        rows = filter_.constraint_rows(state)
        assert rows.names == names
        np.testing.assert_allclose(rows.A, A, rtol=0, atol=1e-9 * (1.0 + np.abs(A).max()))
        np.testing.assert_allclose(rows.lower, lower, rtol=0, atol=1e-9 * (1 + abs(lower).max()))
        centre, radius = chebyshev_radius(A, lower, effort)
        for reach in (0.3, 3.0, 30.0):
            direction = rng.normal(size=model.n_joints)
            u_nom = centre + reach * max(abs(radius), 1e-3) * direction / np.linalg.norm(direction)
            result = filter_.solve(state, u_nom)
            u = result.u
            assert np.all(np.isfinite(u)) and np.all(np.abs(u) <= effort + 1e-12)
            feasible, u_reference = hard_optimum(A, lower, u_nom, -effort, effort)
            if feasible:
                assert not result.relaxed, result.status
                residual = independent_residuals(model, config, state, u)[1]
                assert residual.min() >= -1e-6, names[int(np.argmin(residual))]
            else:
                assert result.relaxed
                u_reference = relaxed_optimum(
                    A, lower, row_weights(config, names), u_nom, -effort, effort
                )[0]
            np.testing.assert_allclose(u, u_reference, rtol=0, atol=1e-5)


# -- start-up checks -------------------------------------------------------------------------


def _cut(text: str, match: re.Match, replacement: str = '') -> str:
    return text[: match.start()] + replacement + text[match.end() :]


def no_sphere(hand, i):
    """Leave the fingertip's collision sphere out of the URDF."""
    finger = hand.fingers[i]
    link = f'{finger.name}_tip' if finger.sphere_on_tip else f'{finger.name}_distal'
    text = hand.urdf()
    start = text.index(f'<link name="{link}">')
    sphere = re.compile(r'    <collision>.*?</collision>\n', flags=re.DOTALL).search(text, start)
    return {'urdf': _cut(text, sphere)}, (
        'model.fingertip_frames',
        f"'{hand.fingers[i].name}_tip'",
        '<collision><sphere>',
    )


def radius_scaled(factor, words):
    def mistake(hand, i):
        finger = hand.fingers[i]
        text = hand.urdf()
        old = f'<sphere radius="{finger.radius!r}"/>'
        assert text.count(old) == 1
        new = f'<sphere radius="{finger.radius * factor!r}"/>'
        return {'urdf': text.replace(old, new)}, (f"contact '{finger.name}'", *words)

    return mistake


def radius_parameter(hand, i):
    """``model.fingertip_radius`` other than the URDF's sphere of the first contact."""
    first = hand.fingers[0]
    return {'model': {'fingertip_radius': first.radius * 1.1}}, (
        'model.fingertip_radius',
        f"'{first.name}'",
        f"'{first.name}_tip'" if first.sphere_on_tip else f"'{first.name}_distal'",
    )


def tip_z_sideways(hand, i):
    """Turn the tip frame's z axis to 100 degrees from the contact: z not out of the tip."""
    finger = hand.fingers[i]
    centres = hand.sphere_centres(hand.q0)
    inward = -outward_normals(hand, centres, hand.p_object, hand.R_object)[i]
    R_distal = finger.link_frames(hand.finger_q(hand.q0)[i])[-1][0]
    d = (R_distal @ finger.tip_rotation).T @ inward  # the contact direction, tip frame
    z = np.array([0.0, 0.0, 1.0])
    axis = np.cross(z, d)
    angle = math.atan2(np.linalg.norm(axis), d @ z)
    away = rotation_about(axis / np.linalg.norm(axis), -(math.radians(100.0) - angle))
    fingers = list(hand.fingers)
    fingers[i] = dataclasses.replace(finger, tip_rotation=finger.tip_rotation @ away)
    return {'urdf': dataclasses.replace(hand, fingers=fingers).urdf()}, (
        f"contact '{finger.name}'",
        'outside its fingertip workspace',
    )


OPPOSITE = {'+x': '-x', '-x': '+x', '+y': '-y', '-y': '+y'}


def wrong_face(hand, i):
    """Declare the face opposite to the one the fingertip touches."""
    faces = list(hand.faces)
    faces[i] = OPPOSITE[faces[i]]
    return {'model': {'contact_faces': faces}}, (
        f"contact '{hand.fingers[i].name}'",
        f"declares face '{faces[i]}'",
        f"nearest face '{hand.faces[i]}'",
    )


def past_the_edges(hand, i):
    """Move the box along its own z by its height: every contact beyond its face's edge."""
    shifted = hand.p_object + hand.R_object[:, 2] * hand.edge_lengths[2]
    return {'initial': {'object_position': [float(x) for x in shifted]}}, (
        *(f"contact '{name}'" for name in hand.contact_names),
        'beyond the edge',
    )


def two_contacts(hand, i):
    """Only the first two fingertips named: the grasp map has rank 5."""
    model = {
        'fingertip_frames': [f'{f.name}_tip' for f in hand.fingers[:2]],
        'contact_names': hand.contact_names[:2],
    }
    if hand.declare_faces:
        model['contact_faces'] = list(hand.faces[:2])
    return {'model': model}, ('grasp map G has rank 5', 'expected 6')


def no_inertial(hand, i):
    """Drop the <inertial> of a finger's distal (and tip) link: its last joint moves no mass."""
    finger = hand.fingers[i]
    fingers = list(hand.fingers)
    distal = dataclasses.replace(finger.links[-1], mass=0.0)
    fingers[i] = dataclasses.replace(finger, links=[*finger.links[:-1], distal], tip_link=None)
    text = dataclasses.replace(hand, fingers=fingers).urdf()
    text = re.sub(
        rf'(<link name="{finger.name}_distal">\n)    <inertial>.*?</inertial>\n',
        r'\1',
        text,
        flags=re.DOTALL,
    )
    return {'urdf': text}, (f"joint '{finger.joint_names[-1]}'", 'moves no inertia')


MISTAKES = {
    'no fingertip sphere': no_sphere,
    'URDF sphere too large': radius_scaled(1.4, ('penetrates',)),
    'URDF sphere too small': radius_scaled(0.6, ('separated',)),
    'fingertip_radius parameter': radius_parameter,
    'tip frame z sideways': tip_z_sideways,
    'declared face wrong': wrong_face,
    'box past the fingertips': past_the_edges,
    'two contacts': two_contacts,
    'distal link without inertial': no_inertial,
}
#: Mistakes that need faces (a box).
BOX_ONLY = ('declared face wrong', 'box past the fingertips')


def _merge(document: dict, edits: dict) -> None:
    for section, values in edits.items():
        node = (
            document['/**']['ros__parameters']
            if section == 'model'
            else (document['hand_sim_node']['ros__parameters'])
        )
        node[section].update(values)


@pytest.mark.parametrize('mistake', list(MISTAKES))
@pytest.mark.parametrize('seed', SEEDS[:5])
def test_each_mistake_is_refused_at_start_naming_it(tmp_path, seed, mistake):
    import yaml

    hand = random_hand(seed)
    if mistake in BOX_ONLY and hand.shape != 'box':
        hand = random_hand(seed + 1)
    index = seed % hand.n_fingers
    edits, words = MISTAKES[mistake](hand, index)
    text = edits.pop('urdf', None)
    path = write_scenario(hand, tmp_path, urdf_text=text)
    if edits:
        document = yaml.safe_load(path.read_text())
        _merge(document, edits)
        path.write_text(yaml.safe_dump(document, sort_keys=False))
    with pytest.raises(ConfigError) as error:
        load_initial_grasp(path)
    message = str(error.value)
    for word in words:
        assert word in message, f'{word!r} not in {message!r}'
    # The same scenario without the mistake passes.
    right = tmp_path / 'right'
    right.mkdir()
    load_initial_grasp(write_scenario(hand, right))


@pytest.mark.parametrize('seed', SEEDS[:4])
def test_the_tip_frames_origin_does_not_move_the_fingertip(tmp_path, seed):
    """A tip frame at the distal link's origin: the sphere's centre is still the fingertip."""
    hand = random_hand(seed)
    moved_tips = [dataclasses.replace(finger, tip_origin=np.zeros(3)) for finger in hand.fingers]
    other = dataclasses.replace(hand, fingers=moved_tips)
    assert other.urdf() != hand.urdf()
    (tmp_path / 'moved').mkdir()
    model, _ = load_initial_grasp(write_scenario(other, tmp_path / 'moved'))
    reference, _ = load_initial_grasp(write_scenario(hand, tmp_path))
    p, R, J = model.hand.fingertip_placements(hand.q0)
    _, R_ref, J_ref = reference.hand.fingertip_placements(hand.q0)
    np.testing.assert_allclose(p, hand.sphere_centres(hand.q0), rtol=0, atol=1e-12)
    np.testing.assert_allclose(R, R_ref, rtol=0, atol=1e-12)
    np.testing.assert_allclose(J, J_ref, rtol=0, atol=1e-12)


@pytest.mark.parametrize('seed', SEEDS[:3])
def test_odometry_of_another_object_frame_is_refused_naming_both(tmp_path, seed):
    """The simulator stamps ``object``; consumers configured for another frame refuse it."""
    hand = random_hand(seed)
    path = write_scenario(hand, tmp_path)
    nodes = ('hand_sim_node', 'nominal_controller_node', 'safety_filter_node')
    params = {node: load_node_parameters(path, node) for node in nodes}
    sim = make_sim(params)
    odometry = next(through_cdr(o.msg) for o in sim.start() if o.topic.endswith('odom'))
    assert odometry.child_frame_id == 'object'
    other = {node: {**values, 'model.object_frame': 'held_box'} for node, values in params.items()}
    for endpoint, name in (
        (make_nominal(other), 'nominal_controller'),
        (make_filter(other), 'safety_filter'),
    ):
        reports = statuses(endpoint.on_odom(odometry), name)
        assert reports, f'{name} accepted odometry of another object frame'
        for word in ('child_frame_id', "'held_box'", "'object'"):
            assert word in reports[0].message, reports[0].message


@pytest.mark.parametrize('seed', (5, 6, 11))
def test_a_short_filtered_run_holds_the_grasp(tmp_path, seed):
    """200 ticks of the lockstep runner, filter on: finite, every constraint kept, held."""
    hand = random_hand(seed)
    path = write_scenario(hand, tmp_path, duration=0.2)
    recording = record_run(RunOptions(path, 'filtered'), tmp_path / 'bag')
    run = load_run(tmp_path / 'bag')
    assert recording.interrupted is None and recording.t_end == pytest.approx(0.2)
    assert recording.stop_reason == 'duration'
    assert run.stop_reason == 'duration' and run.t.size >= 200
    for family, record in recording.live_log.families.items():
        assert record.count == 0 and record.min_margin > 0.0, (family, record)
    assert np.all(np.isfinite(run.u_command)) and np.all(np.isfinite(run.force))
    effort = np.array(
        [
            f.effort[f.joint_names.index(j)]
            for j in hand.joint_names
            for f in hand.fingers
            if j in f.joint_names
        ]
    )
    assert np.all(np.abs(run.u_command) <= effort + 1e-9)
    # Held: every normal force pushes, every contact needs less friction than it has.
    assert run.force[:, :, 2].min() > 0.0
    assert run.required_friction.max() < hand.friction_coefficient


@pytest.mark.parametrize('seed', (3, 6))
def test_the_unactuated_plant_conserves_energy_to_integrator_accuracy(tmp_path, seed):
    """Zero torque for 50 ms, no stabilisation: the drift is ode3's (halving the step: ~1/8).

    Rolling contact does no work, so the hand's and object's kinetic plus potential energy
    (gravity tilted off -z for seeds 3 and 6) changes only by the integrator's error. The
    fingers fall freely to ~20 rad/s in 50 ms; longer, at 75 rad/s, 2 ms steps are too coarse
    for the third order to show.
    """
    model, params = load_initial_grasp(write_scenario(random_hand(seed), tmp_path))
    config = dataclasses.replace(
        SimConfig.from_parameters(params),
        integrator='ode3',
        position_gain=0.0,
        velocity_gain=0.0,
        stop_on_workspace_exit=False,
    )
    drifts = []
    for time_step in (0.002, 0.001):
        simulator = Simulator(model, dataclasses.replace(config, time_step=time_step))
        energy_0 = model.total_energy(simulator.grasp_state())
        drift, kinetic = 0.0, 0.0
        for _ in range(round(0.05 / time_step)):
            simulator.step(np.zeros(model.n_joints))
            state = simulator.grasp_state()
            drift = max(drift, abs(model.total_energy(state) - energy_0))
            kinetic = max(kinetic, 0.5 * state.dq @ state.M_h @ state.dq)
        assert simulator.stop_reason is None
        drifts.append(drift)
    assert kinetic > 1e-4, kinetic  # the hand really moved
    assert drifts[1] <= 1e-5 * kinetic, drifts
    assert 6.0 < drifts[0] / drifts[1] < 10.5, drifts


def test_nominal_torque_gives_the_desired_object_acceleration(case):
    """Computed torque: x_o_ddot(u_nom) is the desired one; squeeze and posture move nothing.

    The object acceleration comes from the model's constrained dynamics, not from the
    controller's M_ho and C_ho; the internal force lies in null(G) and the null-space
    posture torque changes neither the contact forces nor the object's acceleration.
    """
    rng = np.random.default_rng(case.hand.seed + 4)
    controller = NominalController(NominalConfig(), posture=case.hand.q0)
    for c in case.configurations:
        state = c.state(case.model)
        pose = np.concatenate((c.p_object, rng.normal(0.0, 0.1, 3)))
        sample = ReferenceSample(
            r=pose + rng.normal(0.0, 0.01, 6),
            r_dot=rng.normal(0.0, 0.05, 6),
            r_ddot=rng.normal(0.0, 0.1, 6),
        )
        output = controller.compute(state, sample)
        desired = output.object_acceleration_desired
        scale = 1.0 + np.abs(desired).max()
        np.testing.assert_allclose(
            state.object_acceleration(output.u), desired, rtol=0, atol=1e-8 * scale
        )
        np.testing.assert_allclose(state.G @ output.u_internal, 0.0, atol=1e-12)
        without_posture = output.u - output.u_null_space
        np.testing.assert_allclose(
            state.contact_force(output.u),
            state.contact_force(without_posture),
            rtol=0,
            atol=1e-9 * (1.0 + np.abs(state.contact_force(output.u)).max()),
        )
