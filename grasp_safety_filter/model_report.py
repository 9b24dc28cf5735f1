"""``grasp-model-report``: a scenario's initial grasp and its distance to every constraint."""

from __future__ import annotations

import argparse
from pathlib import Path
import sys

import numpy as np

from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.model.quaternion import rotation_matrix


def main(argv: list[str] | None = None) -> int:
    """``grasp-model-report``: the initial grasp and its distance to every constraint."""
    from grasp_safety_filter.model.grasp_check import load_initial_grasp

    parser = argparse.ArgumentParser(prog='grasp-model-report', description=main.__doc__)
    parser.add_argument(
        '--config', type=Path, default=config_path(), help='scenario parameter file'
    )
    args = parser.parse_args(argv)
    try:
        model, params = load_initial_grasp(args.config, {})
        p_object = np.asarray(params['initial.object_position'], dtype=float)
        R_object = rotation_matrix(params['initial.object_orientation'])
        q = model.project_to_contact(params['initial.joint_positions'], p_object, R_object)
    except ConfigError as error:
        print(config_error_line('grasp-model-report', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    state = model.state(0.0, q, np.zeros(model.n_joints), p_object, R_object, np.zeros(6))
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
    return 0
