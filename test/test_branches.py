"""The hand's branches, and the contact dynamics' sums over them.

:class:`~grasp_safety_filter.model.hand.Branches` says where M_h^-1 and the fingertip
Jacobians can be non-zero. Checked against what Pinocchio computes on hands we did not
design: the paper's hand, the four-finger hand, random hands whose joints are listed out
of Pinocchio's order (a branch's joints then need not be consecutive) and the paper's hand
on a wrist (one branch). The dynamics kernels sum over the spans only; with every span the
whole hand (the full sums) every term is the same to rounding, in the model's one-pass
kernel and in the staged oracle (model_oracles), point and soft-finger contacts.
"""

from __future__ import annotations

from pathlib import Path
import re

from grasp_states import (
    CONFIG_DIR,
    Configuration,
    paper_model,
    PAPER_MODEL_PARAMETERS,
    random_configuration,
    random_hand_grasps,
)
from model_oracles import staged_state
import numpy as np
import pytest

from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.hand import Branches, HandModel
from grasp_tools.bench.recorded_run import record_filtered_run, Scenario

AFFINE_TERMS = ('contact_force', 'joint_acceleration', 'object_acceleration', 'xi_cf_ddot')
PLAIN_TERMS = ('J_h', 'G', 'Jh_dot_dq', 'G_dot_T_twist', 'B_ho')


def _four_finger_model() -> tuple[GraspModel, list[Configuration]]:
    """Return the four-finger hand and three instants of its filtered run."""
    scenario = Scenario.load(CONFIG_DIR / 'four_finger_box.yaml')
    ticks = record_filtered_run(scenario, 0.03)[0]
    return scenario.model, [
        Configuration(t.q, t.dq, t.p_object_in_palm, t.R_object_to_palm, t.twist_object)
        for t in ticks[::10]
    ]


def _wrist_hand(directory: Path) -> HandModel:
    """Return the paper's hand carried by a revolute wrist: every finger on one branch."""
    text = (CONFIG_DIR / PAPER_MODEL_PARAMETERS['model.urdf_file']).read_text()
    wrist = (
        '<link name="forearm"/>\n'
        '  <joint name="wrist" type="revolute">\n'
        '    <parent link="forearm"/>\n    <child link="palm"/>\n'
        '    <origin xyz="0 0 0" rpy="0 0 0"/>\n    <axis xyz="0 1 0"/>\n'
        '    <limit lower="-1" upper="1" effort="10" velocity="5"/>\n  </joint>\n  '
    )
    text = re.sub(r'(<robot [^>]*>\s*)', lambda match: match.group(1) + wrist, text, count=1)
    path = directory / 'wrist_hand.urdf'
    path.write_text(text)
    return HandModel(
        path,
        ['wrist', *PAPER_MODEL_PARAMETERS['model.joint_names']],
        list(PAPER_MODEL_PARAMETERS['model.fingertip_frames']),
        np.array([0.0, 0.0, -9.81]),
    )


def _hands(directory: Path) -> dict[str, HandModel]:
    hands = {'paper': paper_model().hand, 'four_finger': _four_finger_model()[0].hand}
    for seed in range(6):
        (directory / str(seed)).mkdir()
        hands[f'random {seed}'] = random_hand_grasps(seed, directory / str(seed))[0].hand
    hands['wrist'] = _wrist_hand(directory)
    return hands


def _outside(span: np.ndarray, m: int) -> np.ndarray:
    mask = np.ones(m, dtype=bool)
    mask[span[0]:span[1]] = False
    return mask


def test_the_spans_hold_every_term_that_can_be_non_zero(tmp_path):
    hands = _hands(tmp_path)
    assert not all(hand._in_pin_order for hand in hands.values()), 'no permuted hand'
    for label, hand in hands.items():
        m, rng = hand.n_joints, np.random.default_rng(7)
        joint_span, fingertip_span = hand.branches
        assert joint_span.shape == (m, 2) and fingertip_span.shape == (len(hand.frame_ids), 2)
        for a in range(m):
            assert joint_span[a, 0] <= a < joint_span[a, 1], f'{label}: joint {a} not in its span'
        for _ in range(5):
            q = rng.uniform(hand.joint_lower_limits, hand.joint_upper_limits)
            terms = hand.terms(q, rng.normal(size=m))
            for a in range(m):
                outside = _outside(joint_span[a], m)
                assert not np.any(terms.M_h[a, outside]), f'{label}: M_h row {a}'
                assert not np.any(terms.M_h_inverse[a, outside]), f'{label}: M_h^-1 row {a}'
            for i, span in enumerate(fingertip_span):
                assert not np.any(terms.J_fingertip[i][:, _outside(span, m)]), f'{label}: J {i}'


@pytest.mark.parametrize(
    ('label', 'branches'),
    [('paper', 3), ('four_finger', 4), ('wrist', 1)],
)
def test_each_finger_hanging_from_the_palm_is_a_branch(label, branches, tmp_path):
    hand = _hands(tmp_path)[label]
    spans = {tuple(span) for span in hand.branches.joint_span}
    assert len(spans) == branches
    assert {tuple(span) for span in hand.branches.fingertip_span} <= spans
    if label == 'wrist':
        # Why the wrist's hand is one branch: its fingers are coupled through it (M_h^-1
        # couples the first finger's joints 1-3 with the others').
        q = 0.5 * (hand.joint_lower_limits + hand.joint_upper_limits)
        terms = hand.terms(q, np.zeros(hand.n_joints))
        assert np.any(terms.M_h[0, 1:]) and np.any(terms.M_h_inverse[1:4, 4:])


def _whole_hand(hand: HandModel) -> Branches:
    m, n = hand.n_joints, len(hand.frame_ids)
    return Branches(np.tile([0, m], (m, 1)), np.tile([0, m], (n, 1)))


def _terms(state) -> dict[str, np.ndarray]:
    out = {name: np.asarray(getattr(state, name)) for name in PLAIN_TERMS}
    for name in AFFINE_TERMS:
        affine = getattr(state, name)
        out[name] = np.column_stack([affine.matrix, affine.offset])
    return out


@pytest.mark.parametrize(
    'case', ['paper', 'paper soft fingers', 'four_finger', 'random 0', 'random 3', 'random 5']
)
def test_the_sums_over_spans_are_the_full_sums(case, tmp_path, monkeypatch):
    if case.startswith('random'):
        model, configurations = random_hand_grasps(int(case.split()[1]), tmp_path)
    elif case == 'four_finger':
        model, configurations = _four_finger_model()
    else:
        model = paper_model(**({'model.soft_finger': True} if 'soft' in case else {}))
        rng = np.random.default_rng(3)
        configurations = [random_configuration(model, rng) for _ in range(3)]
    assert len({tuple(span) for span in model.hand.branches.joint_span}) > 1

    def states():
        for c in configurations:
            args = (c.q, c.dq, c.p_object, c.R_object, c.twist_object)
            yield model.state(0.0, *args)
            yield staged_state(model, 0.0, *args)

    over_spans = [_terms(state) for state in states()]
    monkeypatch.setattr(model.hand, 'branches', _whole_hand(model.hand))
    for spans, full in zip(over_spans, (_terms(state) for state in states()), strict=True):
        for name, value in full.items():
            # The terms outside the spans are exact zeros: only the summation order differs.
            scale = max(float(np.max(np.abs(value))), 1e-300)
            np.testing.assert_allclose(
                spans[name], value, rtol=0, atol=1e-13 * scale, err_msg=f'{case}: {name}'
            )
