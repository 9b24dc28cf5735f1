"""Random valid grasp states of the paper's hand, for tests: on the contact manifold, rolling."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pinocchio as pin
from random_hands import random_hand

from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_safety_filter.model.grasp_state import GraspState

CONFIG_DIR = Path(__file__).resolve().parent.parent / 'config'

# The scenario file is the one source of the paper's values (test_config_files checks them
# against the paper); the tests build their model and initial grasp from it.
_SCENARIO = load_node_parameters(CONFIG_DIR / 'paper_scenario.yaml', HAND_SIM_NODE)
PAPER_MODEL_PARAMETERS = {k: v for k, v in _SCENARIO.items() if k.startswith('model.')}
Q_PAPER = np.array(_SCENARIO['initial.joint_positions'])
P_OBJECT_PAPER = np.array(_SCENARIO['initial.object_position'])


def paper_model(**overrides: object) -> GraspModel:
    """Return the paper's hand and cube (model parameters of config/paper_scenario.yaml)."""
    return GraspModel.from_parameters({**PAPER_MODEL_PARAMETERS, **overrides}, CONFIG_DIR)


@dataclass(frozen=True)
class Configuration:
    """Arguments of GraspModel.state (without t)."""

    q: np.ndarray
    dq: np.ndarray
    p_object: np.ndarray
    R_object: np.ndarray
    twist_object: np.ndarray

    def state(self, model: GraspModel, t: float = 0.0) -> GraspState:
        return model.state(t, self.q, self.dq, self.p_object, self.R_object, self.twist_object)


def moved(
    c: Configuration, t: float, ddq: np.ndarray | None = None, x_ddot: np.ndarray | None = None
) -> Configuration:
    """Return the configuration after time t (second order when accelerations are given)."""
    ddq = np.zeros_like(c.dq) if ddq is None else ddq
    x_ddot = np.zeros(6) if x_ddot is None else x_ddot
    v, w = c.twist_object[:3], c.twist_object[3:]
    a, alpha = x_ddot[:3], x_ddot[3:]
    return Configuration(
        q=c.q + t * c.dq + 0.5 * t * t * ddq,
        dq=c.dq + t * ddq,
        p_object=c.p_object + t * v + 0.5 * t * t * a,
        R_object=pin.exp3(t * w + 0.5 * t * t * alpha) @ c.R_object,
        twist_object=c.twist_object + t * x_ddot,
    )


def rolling_motion(
    model: GraspModel,
    q: np.ndarray,
    p_object: np.ndarray,
    R_object: np.ndarray,
    twist_object: np.ndarray,
) -> tuple[np.ndarray, np.ndarray]:
    """Return the admissible ``(dq, x_o_dot)`` nearest to rolling with ``twist_object``.

    ``(rolling_joint_velocity(twist), twist)`` projected onto the null space of
    ``[J_h, -G^T]``: with soft fingers (4n rows on m joints) a twist is admissible only if
    the fingers can follow it without spinning on the object.
    """
    state = model.state(0.0, q, np.zeros(model.n_joints), p_object, R_object, np.zeros(6))
    twist = np.asarray(twist_object, dtype=float)
    motion = np.concatenate(
        [model.rolling_joint_velocity(q, p_object, R_object, twist), twist]
    )
    constraint = np.hstack([state.J_h, -state.G.T])
    motion -= np.linalg.lstsq(constraint, constraint @ motion, rcond=None)[0]
    return motion[: model.n_joints], motion[model.n_joints :]


def random_configuration(
    model: GraspModel, rng: np.random.Generator, spread: float = 0.25, speed: float = 0.5
) -> Configuration:
    """Return a grasp near the paper's, rolling.

    The object pose is perturbed, the fingertips projected onto the faces, the object given
    a random twist and the joints the velocity that rolls the fingertips with it.
    """
    while True:
        p_object = P_OBJECT_PAPER + rng.uniform(-0.04, 0.04, 3)
        R_object = pin.exp3(rng.uniform(-spread, spread, 3))
        q_guess = Q_PAPER + rng.uniform(-spread, spread, Q_PAPER.size)
        try:
            q = model.project_to_contact(q_guess, p_object, R_object)
        except ValueError:
            continue
        geometry = model.contact_geometry(q, p_object, R_object)
        a_b = np.array([g.xi_cf for g in geometry])
        # Keep states away from chart singularities (|a| -> pi/2) and inside the joint range.
        if (
            np.any(np.abs(a_b[:, 0]) > 1.2)
            or np.any(a_b[:, 1] > -0.2)
            or np.any(a_b[:, 1] < -np.pi + 0.2)
        ):
            continue
        if np.any(q <= model.joint_lower_limits) or np.any(q >= model.joint_upper_limits):
            continue
        twist = rng.normal(0.0, speed, 6) * np.array([0.3, 0.3, 0.3, 1.0, 1.0, 1.0])
        if model.soft_finger:
            # Fingers that cannot spin on the object follow only some twists.
            dq, twist = rolling_motion(model, q, p_object, R_object, twist)
        else:
            dq = model.rolling_joint_velocity(q, p_object, R_object, twist)
        return Configuration(q, dq, p_object, R_object, twist)


def random_hand_grasps(
    seed: int, directory: Path, count: int = 3
) -> tuple[GraspModel, list[Configuration]]:
    """Return random hand ``seed`` (its URDF written to ``directory``) and grasps of it.

    Each grasp is the hand's own, perturbed, projected onto the faces and rolling with a
    random object twist.
    """
    hand = random_hand(seed)
    path = hand.write(directory)
    model = GraspModel.from_parameters(
        {**hand.model_parameters(path), **hand.initial_parameters()}
    )
    rng = np.random.default_rng(seed)
    configurations = []
    for _ in range(count):
        q = model.project_to_contact(
            hand.q0 + rng.uniform(-0.02, 0.02, hand.q0.size), hand.p_object, hand.R_object
        )
        twist = rng.normal(0.0, 0.3, 6)
        dq = model.rolling_joint_velocity(q, hand.p_object, hand.R_object, twist)
        configurations.append(Configuration(q, dq, hand.p_object, hand.R_object, twist))
    return model, configurations
