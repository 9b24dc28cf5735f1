"""The grasp model against finite differences, invariants and closed forms."""

from __future__ import annotations

from pathlib import Path

from grasp_states import CONFIG_DIR, Configuration, moved, paper_model, random_configuration
import numpy as np
import pinocchio as pin
import pytest

N_STATES = 20
EPS = 1e-6
RTOL = 1e-5


def _hand_with_tip_radii(directory: Path, radii: np.ndarray) -> Path:
    """Write the paper's hand.urdf with fingertip collision spheres of radii ``radii`` (m)."""
    text = (CONFIG_DIR / 'hand.urdf').read_text()
    tip = '<collision>\n      <geometry><sphere radius="0.06"/></geometry>'
    assert text.count(tip) == len(radii)
    for radius in radii:
        text = text.replace(tip, tip.replace('0.06', repr(float(radius))).replace('<c', '<C'), 1)
    path = directory / 'hand_random_tips.urdf'
    path.write_text(text.replace('<Collision>', '<collision>'))
    return path


#: The models every test runs on: each object surface type, faces declared or found, the
#: paper's tips and random ones (one radius per contact, from the URDF's collision spheres).
MODELS = {
    'paper cube, declared faces': {},
    'box 0.2604 x 0.2604 x 0.34, nearest faces': {
        'model.object.shape': 'box',
        'model.object.edge_lengths': [0.2604, 0.2604, 0.34],
        'model.contact_faces': ['nearest'],
    },
    'sphere object, charts turned per contact': {
        'model.object.shape': 'sphere',
        'model.object.size': 0.3,
    },
    'paper cube, soft fingers': {'model.torsional_friction': 0.005},
    'paper cube, rigid soft fingers': {
        'model.torsional_friction': 0.005,
        'model.torsional_compliance': 0.0,
    },
    'sphere object, soft fingers': {
        'model.object.shape': 'sphere',
        'model.object.size': 0.3,
        'model.torsional_friction': [0.004, 0.005, 0.006],
    },
    'random tip radii, box': 'random',
    'random tip radii, sphere object': 'random sphere',
}


@pytest.fixture(scope='module', params=list(MODELS))
def model(request, tmp_path_factory):
    overrides = MODELS[request.param]
    if isinstance(overrides, str):
        rng = np.random.default_rng(len(overrides))
        radii = rng.uniform(0.045, 0.075, 3)
        urdf = _hand_with_tip_radii(tmp_path_factory.mktemp('tips'), radii)
        shape = (
            {'model.object.shape': 'sphere', 'model.object.size': 0.28}
            if 'sphere' in overrides
            else {
                'model.object.shape': 'box',
                'model.object.edge_lengths': [0.25, 0.27, 0.3],
                'model.contact_faces': ['nearest'],
            }
        )
        model = paper_model(**{'model.urdf_file': str(urdf), **shape})
        np.testing.assert_array_equal([tip.radius for tip in model.hand.fingertips], radii)
        return model
    return paper_model(**overrides)


@pytest.fixture(scope='module')
def configurations(model):
    rng = np.random.default_rng(7)
    return [random_configuration(model, rng) for _ in range(N_STATES)]


def central(f, c: Configuration, **kwargs) -> np.ndarray:
    return (np.asarray(f(moved(c, EPS, **kwargs))) - np.asarray(f(moved(c, -EPS, **kwargs)))) / (
        2 * EPS
    )


def assert_close(actual: np.ndarray, expected: np.ndarray, what: str) -> None:
    scale = max(np.max(np.abs(expected)), 1e-3)
    error = np.max(np.abs(actual - expected)) / scale
    assert error <= RTOL, f'{what}: relative error {error:.2e} > {RTOL:g}\n{actual}\n{expected}'


def test_fingertip_jacobians_match_finite_differences(model, configurations):
    for c in configurations:
        state = c.state(model)

        def tips(x):
            p, _, _ = model.hand.fingertip_placements(x.q)
            return p

        v_fd = central(tips, c)
        R_plus = model.hand.fingertip_placements(moved(c, EPS).q)[1]
        R_minus = model.hand.fingertip_placements(moved(c, -EPS).q)[1]
        w_fd = np.array(
            [pin.log3(Rp @ Rm.T) / (2 * EPS) for Rp, Rm in zip(R_plus, R_minus, strict=True)]
        )
        for i in range(model.n_contacts):
            assert_close(
                state.J_fingertip[i] @ c.dq, np.concatenate([v_fd[i], w_fd[i]]), f'J_s[{i}] dq'
            )
            assert_close(state.twist_fingertip[i], state.J_fingertip[i] @ c.dq, f'twist_f[{i}]')


def test_hand_jacobian_and_grasp_map_match_material_point_velocities(model, configurations):
    for c in configurations:
        state = c.state(model)
        for i in range(model.n_contacts):
            rows = slice(3 * i, 3 * i + 3)
            p_c = state.p_contact_in_palm[i]
            R_cp = state.R_contact_to_palm[i].T
            # Material point of the fingertip at the contact, carried by the finger's motion.
            p_fc_in_f = state.R_fingertip_to_palm[i].T @ (p_c - state.p_fingertip_in_palm[i])

            def finger_point(x, i=i, p_fc_in_f=p_fc_in_f):
                p, R, _ = model.hand.fingertip_placements(x.q)
                return p[i] + R[i] @ p_fc_in_f

            assert_close(
                state.J_h[rows] @ c.dq, R_cp @ central(finger_point, c), f'J_h contact {i}'
            )
            # Material point of the object at the contact, carried by the object's motion.
            p_oc_in_o = c.R_object.T @ (p_c - c.p_object)

            def object_point(x, p_oc_in_o=p_oc_in_o):
                return x.p_object + x.R_object @ p_oc_in_o

            assert_close(
                state.G[:, rows].T @ c.twist_object,
                R_cp @ central(object_point, c),
                f'G contact {i}',
            )
        if model.soft_finger:
            # Torsion rows: each body's angular velocity about the contact normal.
            R_plus = model.hand.fingertip_placements(moved(c, EPS).q)[1]
            R_minus = model.hand.fingertip_placements(moved(c, -EPS).q)[1]
            n = model.n_contacts
            assert state.J_h.shape[0] == state.G.shape[1] == 4 * n
            for i in range(n):
                normal = state.R_contact_to_palm[i][:, 2]
                w_f = pin.log3(R_plus[i] @ R_minus[i].T) / (2 * EPS)
                assert_close(state.J_h[3 * n + i] @ c.dq, normal @ w_f, f'spin row {i}')
                assert_close(
                    state.G[:, 3 * n + i], np.concatenate([np.zeros(3), normal]), f'G torsion {i}'
                )
        # On a rolling motion the two material velocities agree (the no-slip constraint).
        np.testing.assert_allclose(state.J_h @ c.dq, state.G.T @ c.twist_object, atol=1e-10)


def test_jacobian_time_derivatives_match_finite_differences(model, configurations):
    for c in configurations:
        state = c.state(model)
        Jh_dot = central(lambda x: x.state(model).J_h, c)
        G_dot = central(lambda x: x.state(model).G, c)
        assert_close(state.Jh_dot_dq, Jh_dot @ c.dq, 'J_h_dot dq')
        assert_close(state.G_dot_T_twist, G_dot.T @ c.twist_object, 'G_dot^T x_o_dot')


def test_rolling_rates_match_geometric_coordinates(model, configurations):
    for c in configurations:
        state = c.state(model)

        def coordinates(x):
            geometry = model.contact_geometry(x.q, x.p_object, x.R_object)
            return np.array([np.concatenate([g.xi_cf, g.xi_co, [g.psi]]) for g in geometry])

        rates = central(coordinates, c)
        # Contact by contact, so that one contact's large rates cannot hide another's error.
        for i in range(model.n_contacts):
            assert_close(state.xi_cf_dot[i], rates[i, :2], f'xi_cf_dot[{i}]')
            assert_close(state.xi_co_dot[i], rates[i, 2:4], f'xi_co_dot[{i}]')
            assert_close(state.psi_dot[i], rates[i, 4], f'psi_dot[{i}]')
        # Rolling at |w| of order 1 rad/s, no chart rate is far larger where the charts are
        # regular (at a sphere chart's pole xi_co_dot and psi_dot grow without bound).
        speed = np.linalg.norm(c.twist_object[3:]) + np.max(np.abs(c.dq))
        bound = 50.0 * speed
        assert np.max(np.abs(state.xi_co_dot)) < bound and np.max(np.abs(state.psi_dot)) < bound


def test_contact_coordinate_accelerations_match_finite_differences(model, configurations):
    rng = np.random.default_rng(3)
    for c in configurations:
        state = c.state(model)
        u = rng.normal(0.0, 1.0, model.n_joints)
        ddq = state.joint_acceleration(u)
        x_ddot = state.object_acceleration(u)
        rate = central(lambda x: x.state(model).xi_cf_dot, c, ddq=ddq, x_ddot=x_ddot)
        assert_close(state.xi_cf_ddot(u).reshape(-1, 2), rate, 'xi_cf_ddot')


def test_object_contact_coordinate_accelerations_match_finite_differences(model, configurations):
    """xi_co_ddot(u) against the rate of xi_co_dot along the motion u causes (face and chart)."""
    rng = np.random.default_rng(13)
    for c in configurations:
        state = c.state(model)
        u = rng.normal(0.0, 1.0, model.n_joints)
        ddq = state.joint_acceleration(u)
        x_ddot = state.object_acceleration(u)
        rate = central(lambda x: x.state(model).xi_co_dot, c, ddq=ddq, x_ddot=x_ddot)
        actual = state.xi_co_ddot(u).reshape(-1, 2)
        for i in range(model.n_contacts):
            assert_close(actual[i], rate[i], f'xi_co_ddot[{i}]')


def test_mass_matrices_are_symmetric_positive_definite(model, configurations):
    for c in configurations:
        state = c.state(model)
        for name in ('M_h', 'M_o', 'B_ho'):
            matrix = getattr(state, name)
            np.testing.assert_allclose(matrix, matrix.T, atol=1e-12, err_msg=name)
            assert np.linalg.eigvalsh(matrix).min() > 0.0, name


def test_accelerations_satisfy_the_differentiated_rolling_constraint(model, configurations):
    rng = np.random.default_rng(11)
    for c in configurations:
        state = c.state(model)
        for _ in range(3):
            u = rng.normal(0.0, 2.0, model.n_joints)
            ddq = state.joint_acceleration(u)
            x_ddot = state.object_acceleration(u)
            lhs = state.J_h @ ddq + state.Jh_dot_dq
            rhs = state.G.T @ x_ddot + state.G_dot_T_twist
            f_c = state.contact_force(u)
            if model.soft_finger:
                # A compliant spin row accelerates at rho (B_ho)_tt tau_i (0 when rigid).
                t = slice(3 * model.n_contacts, None)
                rhs[t] += model.torsional_compliance * np.diag(state.B_ho)[t] * f_c[t]
            np.testing.assert_allclose(lhs, rhs, atol=1e-9)
            # And both dynamics hold with the same contact force.
            np.testing.assert_allclose(
                state.M_h @ ddq + state.h_bias, u - state.J_h.T @ f_c, atol=1e-9
            )
            np.testing.assert_allclose(
                state.M_o @ x_ddot + state.C_o_twist, state.G @ f_c + state.w_e, atol=1e-9
            )


def test_joint_accelerations_match_pinocchio_forward_dynamics(model, configurations):
    """Independent check of ddq(u): Pinocchio's ABA with the contact forces as joint torques."""
    rng = np.random.default_rng(5)
    hand = model.hand
    for c in configurations[:5]:
        state = c.state(model)
        u = rng.normal(0.0, 2.0, model.n_joints)
        tau = u - state.J_h.T @ state.contact_force(u)
        tau_pin = np.empty(hand.model.nv)
        tau_pin[hand._idx] = tau
        q_pin, dq_pin = hand._to_pin(c.q), hand._to_pin(c.dq)
        ddq_pin = pin.aba(hand.model, hand.data, q_pin, dq_pin, tau_pin)[hand._idx]
        np.testing.assert_allclose(state.joint_acceleration(u), ddq_pin, atol=1e-9)


def test_state_is_read_only(model, configurations):
    state = configurations[0].state(model)
    with pytest.raises(ValueError):
        state.q[0] = 1.0
    with pytest.raises(ValueError):
        state.contact_force.matrix[0, 0] = 1.0
