"""The stacked contact evaluations against the per-contact ContactPair formulas."""

from __future__ import annotations

from grasp_states import P_OBJECT_PAPER, paper_model, Q_PAPER, random_configuration
import numpy as np
import pinocchio as pin
import pytest

from grasp_safety_filter.model.arrays import matvec
from grasp_safety_filter.model.closed_form_stacks import (
    contact_stack,
    SphereOnPlaneStack,
    SphereOnSphereStack,
)
from grasp_safety_filter.model.contact_stack import ContactStack
from grasp_safety_filter.model.rolling import ContactPair
from grasp_safety_filter.model.surface_stacks import SurfaceList
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
        frame = surface.frame(np.zeros(2))
        return ContactPair(pair.fingertip, _Plane(surface.origin, frame[:, 0], frame[:, 1]))
    return ContactPair(pair.fingertip, _Ball(surface.radius, surface.R_chart_to_body))


def _stacks(model):
    yield 'selected', contact_stack(model.contacts)
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
        object_terms = {}
        for name, stack in _stacks(model):
            geometry = stack.geometry(p_f, R_f, c.p_object, c.R_object)
            rates = stack.rolling_rates(geometry, w_in_contact)
            # M_co xi_co_dot = R_psi M_cf xi_cf_dot, and every stack gives the same terms.
            object_terms[name] = stack.object_rate_terms(geometry, rates)
            np.testing.assert_allclose(
                matvec(object_terms[name][0], rates.xi_cf_dot), rates.xi_co_dot, atol=1e-12
            )
            for term, reference in zip(object_terms[name], object_terms['selected'], strict=True):
                np.testing.assert_allclose(term, reference, atol=1e-12, err_msg=name)
            for i, pair in enumerate(model.contacts):
                expected = pair.geometry(p_f[i], R_f[i], c.p_object, c.R_object)
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
                expected_rates = pair.rolling_rates(expected, w_in_contact[i])
                H_dot = pair.H_cf_rate(expected, expected_rates)
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
                tangents = pair.fingertip.tangents(expected.xi_cf)
                np.testing.assert_allclose(
                    expected.R_contact_to_fingertip[:, :2] @ rates.sliding_velocity[i],
                    tangents @ expected_rates.xi_cf_dot,
                    atol=1e-12,
                )
                # d/dt R_fc = R_fc (Omega×), against the surface's closed-form frame rate.
                R_fc_dot = pair.fingertip.frame_rate(expected.xi_cf, expected_rates.xi_cf_dot)
                np.testing.assert_allclose(
                    expected.R_contact_to_fingertip @ pin.skew(rates.frame_angular_velocity[i]),
                    R_fc_dot,
                    atol=1e-12,
                )


def test_the_selected_stack_uses_the_closed_forms_only_for_planes_and_spheres():
    cube = paper_model()
    assert type(contact_stack(cube.contacts)) is SphereOnPlaneStack
    sphere = paper_model(**MODELS['sphere'])
    sphere.bind_contacts(Q_PAPER, P_OBJECT_PAPER, np.eye(3))
    assert type(contact_stack(sphere.contacts)) is SphereOnSphereStack
    for model in (cube, sphere):
        opaque = [_opaque(pair) for pair in model.contacts]
        assert type(contact_stack(opaque)) is ContactStack
        assert isinstance(ContactStack(opaque).object_surfaces, SurfaceList)
    mixed = [*cube.contacts[:-1], sphere.contacts[-1]]
    assert type(contact_stack(mixed)) is ContactStack
