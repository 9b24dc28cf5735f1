"""The oracle's stacked contact kinematics against the per-contact formulas (oracle_rolling).

Also the model's compiled object-coordinate rate terms against the oracle's, and which
contact surfaces the model's compiled pass takes.
"""

from __future__ import annotations

from grasp_states import P_OBJECT_PAPER, paper_model, Q_PAPER, random_configuration
from model_oracles import ContactStack
import numpy as np
from oracle_geometry import geometry_of
from oracle_rolling import contact_geometry, H_cf_rate, rolling_rates
from oracle_surfaces import SurfaceList
import pinocchio as pin
import pytest
from stacked_arrays import matvec

from grasp_safety_filter.model.contact_surfaces import compiled_contacts
from grasp_safety_filter.model.grasp_model import GraspConfigError
from grasp_safety_filter.model.rolling import ContactPair
from grasp_safety_filter.model.surfaces import FlatSurface, SphereSurface

MODELS = {
    'cube': {},
    'sphere': {'model.object.shape': 'sphere', 'model.object.size': 0.3},
}


class _Plane(FlatSurface):
    """A FlatSurface the stacks do not recognise: evaluated through the Surface interface."""


class _Ball(SphereSurface):
    """A SphereSurface the stacks do not recognise."""


def _opaque(pair: ContactPair) -> ContactPair:
    surface = pair.object_surface
    if isinstance(surface, FlatSurface):
        frame = surface.axes
        return ContactPair(pair.fingertip, _Plane(surface.origin, frame[:, 0], frame[:, 1]))
    return ContactPair(pair.fingertip, _Ball(surface.radius, surface.R_chart_to_body))


def _stacks(model):
    yield 'general', ContactStack(model.contacts)
    yield 'one by one', ContactStack([_opaque(pair) for pair in model.contacts])


@pytest.mark.parametrize('shape', list(MODELS))
def test_stacks_match_the_per_contact_formulas(shape):
    model = paper_model(**MODELS[shape])
    rng = np.random.default_rng(3)
    for _ in range(5):
        c = random_configuration(model, rng)
        p_f, R_f, _ = model.hand.fingertip_placements(c.q)
        w_in_contact = rng.normal(0.0, 1.0, (model.n_contacts, 3))
        compiled = model._compiled_contacts
        for name, stack in _stacks(model):
            geometry = stack.geometry(p_f, R_f, c.p_object, c.R_object)
            rates = stack.rolling_rates(geometry, w_in_contact)
            # M_co xi_co_dot = R_psi M_cf xi_cf_dot, and every stack gives the same terms.
            object_terms = stack.object_rate_terms(geometry, rates)
            np.testing.assert_allclose(
                matvec(object_terms[0], rates.xi_cf_dot), rates.xi_co_dot, atol=1e-12
            )
            # The model's compiled closed form (xi_co_ddot's) gives the same terms.
            ours = compiled.object_rate_terms(
                geometry.xi_cf, geometry.xi_co, geometry.psi, rates.xi_cf_dot,
                rates.xi_co_dot, rates.psi_dot, rates.sliding_velocity,
            )
            for term, reference in zip(ours, object_terms, strict=True):
                np.testing.assert_allclose(term, reference, atol=1e-12, err_msg=name)
            for i, pair in enumerate(model.contacts):
                expected = contact_geometry(pair, p_f[i], R_f[i], c.p_object, c.R_object)
                for field in (
                    'xi_cf',
                    'xi_co',
                    'psi',
                    'penetration',
                    'p_contact_in_palm',
                    'R_contact_to_palm',
                    'R_contact_to_fingertip',
                ):
                    np.testing.assert_allclose(
                        getattr(geometry, field)[i],
                        getattr(expected, field),
                        atol=1e-12,
                        err_msg=f'{name}: {field}[{i}]',
                    )
                expected_rates = rolling_rates(pair, expected, w_in_contact[i])
                H_dot = H_cf_rate(pair, expected, expected_rates)
                for field in ('xi_cf_dot', 'xi_co_dot', 'H_cf'):
                    np.testing.assert_allclose(
                        getattr(rates, field)[i],
                        getattr(expected_rates, field),
                        atol=1e-12,
                        err_msg=f'{name}: {field}[{i}]',
                    )
                assert rates.psi_dot[i] == pytest.approx(expected_rates.psi_dot, abs=1e-12)
                np.testing.assert_allclose(
                    rates.H_cf_dot_w[i], H_dot @ w_in_contact[i], atol=1e-10
                )
                # The sliding velocity is c_xi xi_cf_dot in contact-frame components.
                tangents = geometry_of(pair.fingertip).tangents(expected.xi_cf)
                np.testing.assert_allclose(
                    expected.R_contact_to_fingertip[:, :2] @ rates.sliding_velocity[i],
                    tangents @ expected_rates.xi_cf_dot,
                    atol=1e-12,
                )
                # d/dt R_fc = R_fc (Omega×), against the surface's closed-form frame rate.
                tip = geometry_of(pair.fingertip)
                R_fc_dot = tip.frame_rate(expected.xi_cf, expected_rates.xi_cf_dot)
                np.testing.assert_allclose(
                    expected.R_contact_to_fingertip @ pin.skew(rates.frame_angular_velocity[i]),
                    R_fc_dot,
                    atol=1e-12,
                )


def test_the_model_takes_spherical_fingertips_on_faces_or_on_a_sphere_only():
    cube = paper_model()
    assert compiled_contacts(cube.contacts).flat
    sphere = paper_model(**MODELS['sphere'])
    sphere.bind_contacts(Q_PAPER, P_OBJECT_PAPER, np.eye(3))
    assert not compiled_contacts(sphere.contacts).flat
    for model in (cube, sphere):
        opaque = [_opaque(pair) for pair in model.contacts]
        with pytest.raises(ValueError, match='object surfaces'):
            compiled_contacts(opaque)
        assert isinstance(ContactStack(opaque).object_surfaces, SurfaceList)
    mixed = [*cube.contacts[:-1], sphere.contacts[-1]]
    with pytest.raises(ValueError, match='object surfaces'):
        compiled_contacts(mixed)
    with pytest.raises(GraspConfigError, match='object surfaces'):
        type(cube)(
            cube.hand, cube.object, mixed, cube.contact_names, 0.8, cube.fingertip_workspace
        )
    other_tips = [
        ContactPair(_Ball(pair.fingertip.radius), pair.object_surface) for pair in cube.contacts
    ]
    with pytest.raises(ValueError, match='fingertip'):
        compiled_contacts(other_tips)
