"""HandModel.terms, formed from views of Pinocchio's buffers, against Pinocchio's own calls.

:func:`~grasp_safety_filter.model.hand_kernel.hand_in_model_order` forms the fingertip
placements, frame Jacobians (LOCAL_WORLD_ALIGNED) and classical accelerations from the
joint placements, velocities, accelerations and the world Jacobian Pinocchio's
``computeAllTerms`` leaves in its data, with the operations of Pinocchio's
``getFrameJacobian`` and ``getFrameClassicalAcceleration`` in their order. Placements and
Jacobians are those calls' numbers to the last bit (the oracle here), on the paper's hand
and on random hands whose joints are not in Pinocchio's order. The classical accelerations
agree to rounding only: Pinocchio's compiled products may fuse a multiply and an add (one
rounding instead of two) where the kernel does not, which shows on hands whose fingertip
offsets have more than one non-zero component; the twists ``J dq`` (BLAS's dgemv, as numpy's
product) agree to rounding because dgemv's summation order depends on memory alignment.
"""

from __future__ import annotations

from grasp_states import paper_model
import numpy as np
import pinocchio as pin
from random_hands import random_hand

from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.hand import HandModel

#: Terms equal to rounding only (see the module's docstring), and their tolerance relative
#: to each row's largest entry; rnea's C dq + g is computeAllTerms' by another recursion.
ROUNDING = {'twist_fingertip': 1e-14, 'J_fingertip_dot_dq': 1e-14, 'h_bias': 1e-12}


def _pinocchio_terms(hand: HandModel, q: np.ndarray, dq: np.ndarray) -> dict[str, np.ndarray]:
    """Return the fingertip terms by Pinocchio's frame calls, in the model's joint order."""
    model, data = hand.model, hand.data
    pin.computeAllTerms(model, data, hand._to_pin(q), hand._to_pin(dq))
    pin.updateFramePlacements(model, data)
    world_aligned = pin.LOCAL_WORLD_ALIGNED
    J = np.array(
        [pin.getFrameJacobian(model, data, f, world_aligned) for f in hand.frame_ids]
    )[:, :, hand.pinocchio_index]
    return {
        'p_fingertip_in_palm': np.array([data.oMf[f].translation for f in hand.frame_ids]),
        'R_fingertip_to_palm': np.array([data.oMf[f].rotation for f in hand.frame_ids]),
        'J_fingertip': J,
        'twist_fingertip': J @ dq,
        'J_fingertip_dot_dq': np.array(
            [
                pin.getFrameClassicalAcceleration(model, data, f, world_aligned).vector
                for f in hand.frame_ids
            ]
        ),
        'h_bias': pin.rnea(model, data, hand._to_pin(q), hand._to_pin(dq), np.zeros(model.nv))[
            hand.pinocchio_index
        ],
    }


def _assert_pinocchios(hand: HandModel, rng: np.random.Generator, count: int) -> None:
    for _ in range(count):
        q = rng.uniform(hand.joint_lower_limits, hand.joint_upper_limits)
        dq = rng.normal(0.0, 1.0, hand.n_joints) * rng.choice([1e-3, 1.0, 10.0])
        terms = hand.terms(q, dq)
        expected = _pinocchio_terms(hand, q, dq)
        for name, value in expected.items():
            ours = getattr(terms, name)
            if name in ROUNDING:
                # A few units in the last place of the largest entry of each row.
                scale = np.max(np.abs(value), axis=-1, keepdims=True)
                assert np.all(np.abs(ours - value) <= ROUNDING[name] * scale), name
            else:
                np.testing.assert_array_equal(ours, value, err_msg=name)


def test_the_paper_hands_terms_are_pinocchios_to_the_last_bit():
    hand = paper_model().hand
    _assert_pinocchios(hand, np.random.default_rng(21), 50)


def test_a_hand_out_of_pinocchios_joint_order_gives_pinocchios_terms(tmp_path):
    permuted = 0
    for seed in range(8):
        spec = random_hand(seed)
        (tmp_path / str(seed)).mkdir()
        path = spec.write(tmp_path / str(seed))
        model = GraspModel.from_parameters(
            {**spec.model_parameters(path), **spec.initial_parameters()}
        )
        permuted += not model.hand._in_pin_order
        _assert_pinocchios(model.hand, np.random.default_rng(seed), 5)
    assert permuted, "no random hand of these seeds has its joints out of Pinocchio's order"


def test_the_views_follow_pinocchios_buffers_and_are_read_only():
    """The raw terms are views: a later call's values, never a stale copy."""
    hand = paper_model().hand
    rng = np.random.default_rng(3)
    for _ in range(3):
        q = rng.uniform(hand.joint_lower_limits, hand.joint_upper_limits)
        raw = hand.raw_terms(q, rng.normal(size=hand.n_joints))
        data = hand.data
        np.testing.assert_array_equal(raw.J_joints, data.J)
        np.testing.assert_array_equal(raw.M_upper, data.M)
        np.testing.assert_array_equal(raw.nle, data.nle)
        np.testing.assert_array_equal(raw.g, data.g)
        for k in range(len(data.oMi)):
            np.testing.assert_array_equal(raw.joint_placements[k, :9].reshape(3, 3).T,
                                          data.oMi[k].rotation)
            np.testing.assert_array_equal(raw.joint_placements[k, 9:], data.oMi[k].translation)
            np.testing.assert_array_equal(raw.joint_velocities[k], data.v[k].vector)
            np.testing.assert_array_equal(raw.joint_accelerations[k], data.a[k].vector)
        for f in hand.frame_ids:
            np.testing.assert_array_equal(raw.frame_placements[f, 9:], data.oMf[f].translation)
        assert not any(array.flags.writeable for array in raw[:-1])
