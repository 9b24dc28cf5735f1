"""``grasp-model-report``: a scenario's initial grasp, its distance to every constraint, advice.

The advice (:mod:`~grasp_safety_filter.control.startup_advice`) is the filter node's, at the
simulator's initial grasp: what each barrier family still allows there, whether the QP is
feasible at rest and with what margin, and class-K gains to try when a family is frozen.
"""

from __future__ import annotations

import argparse
from collections.abc import Mapping
from pathlib import Path
import sys
from typing import Any

import numpy as np

from grasp_safety_filter.control.startup_advice import StartupAdvice
from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.model.grasp_state import GraspState
from grasp_safety_filter.model.quaternion import rotation_matrix


def main(argv: list[str] | None = None) -> int:
    """``grasp-model-report``: the initial grasp and its distance to every constraint."""
    from grasp_safety_filter.cli import parse_override
    from grasp_safety_filter.model.grasp_check import load_initial_grasp

    parser = argparse.ArgumentParser(prog='grasp-model-report', description=main.__doc__)
    parser.add_argument(
        '--config', type=Path, default=config_path(), help='scenario parameter file'
    )
    parser.add_argument(
        '--set', dest='overrides', action='append', default=[], metavar='NAME=VALUE',
        type=parse_override, help="override a parameter, as grasp-demo's --set",
    )  # fmt: skip
    args = parser.parse_args(argv)
    overrides = dict(args.overrides)
    try:
        model, params = load_initial_grasp(args.config, overrides)
        state = initial_state(model, params)
        advice = scenario_advice(args.config, overrides)
    except ConfigError as error:
        print(config_error_line('grasp-model-report', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    q = state.q
    print(f'scenario: {args.config}')
    print(
        f'hand: {model.n_joints} joints, {model.n_contacts} contacts; '
        f'object mass {model.object.mass} kg'
    )
    print('\njoint                q [rad]   q - q_min   q_max - q')
    for name, value, lo, hi in zip(
        model.joint_names, q, model.joint_lower_limits, model.joint_upper_limits, strict=True
    ):
        print(f'{name:18s} {value:9.4f} {value - lo:11.4f} {hi - value:11.4f}')
    print('\ncontact     a [rad]   b [rad]   workspace margin [rad]   penetration [m]')
    margins = model.fingertip_workspace.margins(state.xi_cf)
    for name, xi, margin, gap in zip(
        model.contact_names, state.xi_cf, margins, state.penetration, strict=True
    ):
        print(f'{name:10s} {xi[0]:8.4f} {xi[1]:9.4f} {margin.min():14.4f} {gap:22.2e}')
    print(
        f'\ncond(J_h) = {np.linalg.cond(state.J_h):.3g}, cond(G) = {np.linalg.cond(state.G):.3g}, '
        f'min eig(B_ho) = {np.linalg.eigvalsh(state.B_ho).min():.3g}'
    )
    print('\nstart-up advice (the filter node logs it at its first tick):')
    for line in advice.lines():
        print(f'  {line}')
    return 0


def scenario_advice(config: Path, overrides: Mapping[str, Any] | None = None) -> StartupAdvice:
    """Return the filter node's start-up advice at a scenario's initial grasp.

    The filter's model and configuration are the filter node's parameters (``overrides``
    as ``--set``); the grasp is the simulator's ``initial.*``, its contacts closed.

    Raises:
        ConfigError: The file, an override, the URDF or the initial grasp is wrong.
    """
    from grasp_safety_filter.control.safety_filter import SafetyFilter, SafetyFilterConfig
    from grasp_safety_filter.control.startup_advice import startup_advice
    from grasp_safety_filter.io.schemas import (
        load_node_parameters,
        node_overrides,
        SAFETY_FILTER_NODE,
    )
    from grasp_safety_filter.model.grasp_check import load_initial_grasp
    from grasp_safety_filter.model.grasp_model import GraspModel

    _, sim_params = load_initial_grasp(config, overrides)
    own = node_overrides(overrides or {}, SAFETY_FILTER_NODE)
    params = load_node_parameters(config, SAFETY_FILTER_NODE, overrides=own)
    model = GraspModel.from_parameters(params)
    safety_filter = SafetyFilter.from_config(model, SafetyFilterConfig.from_parameters(params))
    return startup_advice(safety_filter, initial_state(model, sim_params))


def initial_state(model: Any, sim_params: Mapping[str, Any]) -> GraspState:
    """Return ``model``'s state at the simulator's ``initial.*`` grasp, contacts closed, at rest.

    Raises:
        GraspConfigError: The fingertips cannot be brought onto the object.
    """
    p_object = np.asarray(sim_params['initial.object_position'], dtype=float)
    R_object = rotation_matrix(sim_params['initial.object_orientation'])
    q = model.project_to_contact(sim_params['initial.joint_positions'], p_object, R_object)
    return model.state(0.0, q, np.zeros(model.n_joints), p_object, R_object, np.zeros(6))
