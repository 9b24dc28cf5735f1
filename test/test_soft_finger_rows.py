"""No-slip rows of soft fingers: the torque about each contact normal bounded too.

The rows are checked against the cones written out here (membership tests that do not use
the rows): the soft-finger bounds ``|f_t| <= mu f_n`` and ``|tau| <= mu_t f_n``, the elliptic
soft-finger cone, and MuJoCo's pyramidal condim-4 cone (the non-negative combinations of
its six edges). Two contacts of different coefficients, with ``f_c = u`` laid out as the
model's: ``(f_x, f_y, f_n)`` per contact, then ``tau_1, tau_2``.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy.optimize import nnls

from grasp_safety_filter.control.constraints import FrictionPyramid
from grasp_safety_filter.control.constraints.friction_cone import (
    DIAMOND,
    INSCRIBED,
    pyramid_rows_into,
    pyramid_rows_packed,
)
from grasp_safety_filter.model.affine import AffineMap

CONTACTS = ('thumb', 'index')
MU = np.array([0.5, 0.9])
MU_T = np.array([0.004, 0.02])  # m
N = len(CONTACTS)
CONES = [INSCRIBED, DIAMOND]
MARGINS = [0.0, 0.2]


class MapState:
    """The one field the no-slip rows read: ``contact_force``."""

    def __init__(self, contact_force: AffineMap) -> None:
        self.contact_force = contact_force


def wrench_state():
    """Return the state whose contact wrenches are ``f_c(u) = u``, 4n entries."""
    return MapState(AffineMap(np.eye(4 * N), np.zeros(4 * N)))


def per_contact(wrench):
    """``(f_x, f_y, f_n, tau)`` per contact, (n, 4), from the model's 4n layout."""
    return np.column_stack((wrench[:3 * N].reshape(N, 3), wrench[3 * N:]))


def stacked(contacts):
    """Return the model's 4n layout of ``(f_x, f_y, f_n, tau)`` per contact."""
    return np.concatenate((contacts[:, :3].reshape(-1), contacts[:, 3]))


def random_wrenches(rng, count):
    """Wrenches around the cone: up to 1.5 of the friction and torsion each can bear."""
    f_n = rng.uniform(-0.2, 5.0, (count, N))
    direction = rng.uniform(0.0, 2.0 * np.pi, (count, N))
    tangential = rng.uniform(0.0, 1.5, (count, N)) * MU * np.abs(f_n)
    tau = rng.uniform(-1.5, 1.5, (count, N)) * MU_T * np.abs(f_n)
    contacts = np.stack(
        (tangential * np.cos(direction), tangential * np.sin(direction), f_n, tau), axis=-1
    )
    return np.array([stacked(c) for c in contacts])


def accepted(family, wrenches):
    """Per wrench and contact, whether every row of that contact holds, (count, n)."""
    rows = family.rows(wrench_state())
    slack = wrenches @ rows.A.T - rows.lower
    return np.all(slack.reshape(len(wrenches), N, -1) >= 0.0, axis=2)


def in_mujoco_condim4(contact, mu, mu_t):
    """Whether ``(f_x, f_y, f_n, tau)`` is a non-negative combination of the six edges."""
    edges = np.array(
        [
            [mu, 0, 1, 0], [-mu, 0, 1, 0], [0, mu, 1, 0], [0, -mu, 1, 0],
            [0, 0, 1, mu_t], [0, 0, 1, -mu_t],
        ],
        dtype=float,
    ).T
    _, residual = nnls(edges, contact)
    return residual <= 1e-9


@pytest.mark.parametrize('margin', MARGINS)
@pytest.mark.parametrize('cone', CONES)
def test_accepted_wrenches_are_inside_the_soft_finger_cone(cone, margin):
    family = FrictionPyramid(CONTACTS, MU, 8, 0.0, margin, cone, torsional_friction=MU_T)
    wrenches = random_wrenches(np.random.default_rng(7), 4000)
    inside = accepted(family, wrenches)
    contacts = np.array([per_contact(w) for w in wrenches])
    f_t = np.hypot(contacts[..., 0], contacts[..., 1])
    f_n, tau = contacts[..., 2], contacts[..., 3]
    mu, mu_t = MU * (1.0 - margin), MU_T * (1.0 - margin)
    tolerance = 1e-12 * np.abs(f_n)
    assert 0.05 < inside.mean() < 0.6
    assert np.all((f_t <= mu * f_n + tolerance)[inside])
    assert np.all((np.abs(tau) <= mu_t * f_n + tolerance)[inside])
    if cone == INSCRIBED:
        elliptic = (f_t / mu) ** 2 + (tau / mu_t) ** 2 <= f_n**2 * (1 + 1e-12)
        assert np.all(elliptic[inside])
        # and not much less: the l1 body inside the polygon's inscribed disc is accepted
        apothem = np.cos(np.pi / 8)
        inner = f_t / (mu * apothem) + np.abs(tau) / mu_t <= f_n * (1 - 1e-12)
        assert np.all(inside[inner]) and inner.sum() > 500


@pytest.mark.parametrize('eps', [0.0, 0.05])
@pytest.mark.parametrize('margin', MARGINS)
def test_diamond_rows_are_mujocos_pyramidal_condim4_cone(margin, eps):
    """With eps, the cone moved up by eps / mu' along f_n (every row's bound is eps)."""
    family = FrictionPyramid(CONTACTS, MU, 8, eps, margin, DIAMOND, torsional_friction=MU_T)
    assert len(family.names) == 8 * N
    wrenches = random_wrenches(np.random.default_rng(11), 1500)
    inside = accepted(family, wrenches)
    mu, mu_t = MU * (1.0 - margin), MU_T * (1.0 - margin)
    for wrench, ok in zip(wrenches, inside, strict=True):
        for i, contact in enumerate(per_contact(wrench)):
            shifted = contact - [0.0, 0.0, eps / mu[i], 0.0]
            assert ok[i] == in_mujoco_condim4(shifted, mu[i], mu_t[i])
    assert 0.05 < inside.mean() < 0.6


@pytest.mark.parametrize('cone', CONES)
def test_values_are_the_rows_margins_and_the_names_say_the_sign(cone):
    family = FrictionPyramid(CONTACTS, MU, 6, 0.03, 0.1, cone, torsional_friction=MU_T)
    faces = 4 if cone == DIAMOND else 6
    assert family.names[:3] == (
        'no_slip/thumb/face0/torsion+',
        'no_slip/thumb/face0/torsion-',
        'no_slip/thumb/face1/torsion+',
    )
    assert family.names[-1] == f'no_slip/index/face{faces - 1}/torsion-'
    assert len(set(family.names)) == len(family.names) == 2 * faces * N
    rows = family.rows(wrench_state())
    for wrench in random_wrenches(np.random.default_rng(3), 50):
        h = family.values(wrench_state(), wrench).h
        np.testing.assert_allclose(h, rows.residual(wrench) + 0.03, rtol=0, atol=1e-12)
        # a "+" row reads +tau: turning the torque round swaps each pair
        turned = np.concatenate((wrench[:3 * N], -wrench[3 * N:]))
        swapped = family.values(wrench_state(), turned).h.reshape(-1, 2)[:, ::-1]
        np.testing.assert_allclose(swapped.reshape(-1), h, rtol=0, atol=1e-12)


@pytest.mark.parametrize('margin', MARGINS)
@pytest.mark.parametrize('cone', CONES)
def test_the_force_part_of_each_row_pair_is_the_point_contact_row(cone, margin):
    """Point contacts: rows and names as before; the soft rows add the torque's column."""
    point = FrictionPyramid(CONTACTS, MU, 8, 0.02, margin, cone)
    soft = FrictionPyramid(CONTACTS, MU, 8, 0.02, margin, cone, torsional_friction=MU_T)
    faces = 4 if cone == DIAMOND else 8
    assert point.names == tuple(f'no_slip/{c}/face{j}' for c in CONTACTS for j in range(faces))
    rng = np.random.default_rng(5)
    force = AffineMap(rng.normal(size=(3 * N, 5)), rng.normal(size=3 * N))
    wrench = AffineMap(
        np.vstack((force.matrix, np.zeros((N, 5)))), np.concatenate((force.offset, np.zeros(N)))
    )
    point_rows = point.rows(MapState(force))
    soft_rows = soft.rows(MapState(wrench))
    np.testing.assert_array_equal(soft_rows.A, np.repeat(point_rows.A, 2, axis=0))
    np.testing.assert_array_equal(soft_rows.lower, np.repeat(point_rows.lower, 2))
    with pytest.raises(ValueError, match=f'state.contact_force: expected {4 * N} rows'):
        soft.rows(MapState(force))
    with pytest.raises(ValueError, match=f'state.contact_force: expected {3 * N} rows'):
        point.rows(MapState(wrench))


@pytest.mark.parametrize('torsion', [None, MU_T])
def test_packed_rows_are_the_rows_to_the_bit(torsion):
    """The packed writer reads ``[F | f_0]`` (3n or 4n rows) at its place in a buffer."""
    family = FrictionPyramid(CONTACTS, MU, 8, 0.01, 0.1, torsional_friction=torsion)
    rows, m = (3 if torsion is None else 4) * N, 7
    rng = np.random.default_rng(9)
    augmented = rng.normal(size=(rows, m + 1))
    terms = np.concatenate((rng.normal(size=13), augmented.reshape(-1), rng.normal(size=4)))
    A, lower = np.empty((len(family.names), m)), np.empty(len(family.names))
    pyramid_rows_into(
        family._negative_faces, augmented[:, :m].copy(), augmented[:, m].copy(), 0.01, A, lower, 0
    )
    A_packed, lower_packed = np.full((len(family.names) + 3, m), np.nan), np.zeros(
        len(family.names) + 3
    )
    pyramid_rows_packed(family._negative_faces, terms, 13, 0.01, A_packed, lower_packed, 2)
    np.testing.assert_array_equal(A_packed[2:-1], A)
    np.testing.assert_array_equal(lower_packed[2:-1], lower)
    assert np.all(np.isnan(A_packed[[0, 1, -1]]))


@pytest.mark.parametrize(
    ('torsion', 'message'),
    [
        (0.0, "'torsional_friction' of contact 'thumb': expected a finite number > 0, got 0.0"),
        ([0.01, -0.02], "'torsional_friction' of contact 'index': expected .* got -0.02"),
        ([0.01, np.nan], "'torsional_friction' of contact 'index': expected .* got nan"),
        ([0.01, np.inf], "'torsional_friction' of contact 'index': expected .* got inf"),
        ([0.01, 0.01, 0.01], "'torsional_friction': expected one number or 2"),
        ('stiff', "'torsional_friction': expected one number or 2"),
    ],
)
def test_bad_torsional_friction_is_refused_naming_it(torsion, message):
    with pytest.raises(ValueError, match=message):
        FrictionPyramid(CONTACTS, MU, torsional_friction=torsion)


def test_one_coefficient_is_every_contacts():
    family = FrictionPyramid(CONTACTS, MU, torsional_friction=[0.01])
    np.testing.assert_array_equal(family.torsional_friction, [0.01, 0.01])
    assert not family.torsional_friction.flags.writeable
