r"""Creep of MuJoCo's soft friction on a held grasp: its law, measured.

``python -m grasp_tools.mujoco_creep`` holds the scenario's grasp still (the nominal
controller's reference frozen at the initial pose, through the safety filter) on MuJoCo
under a table of contact settings and squeezes, and prints per setting and contact the
normal and friction force, MuJoCo's impedance ``d``, the measured slip speed, the speed the
creep law below predicts, and the slip the law forces on the scenario's whole run.

The law. MuJoCo's soft constraints (no no-slip solver) satisfy on every active row
``J a - a_ref = -R f`` with ``a_ref = -B J v - K d r`` and ``B = 2 / (dmax · timeconst)``.
A contact's regulariser is ``R0 = (1 - d)/d · A``: ``d`` its impedance (between
``solimp``'s ``dmin`` and ``dmax``), ``A`` MuJoCo's approximate inverse inertia of the two
bodies (from ``body_invweight0``, a constant of the model). Its friction rows get

- elliptic cone: ``R_t = R0 / impratio``, and along a tangent ``t``
  ``J_t a + B v_t = -R_t f_t`` (a friction row has no position term);
- pyramidal cone: edge rows ``J_n ± μ J_t`` with forces ``f_±`` (``f_t = μ (f_+ - f_-)``)
  and one shared ``R = 2 μ² (1 + μ²) R0 / impratio``; subtracting the two rows cancels
  their position terms: ``2 μ (J_t a + B v_t) = -R (f_+ - f_-)``.

On a held grasp the relative tangential acceleration ``J_t a`` averages to zero, so the
contact slides at the *creep velocity* ``v_t = -R_t f_t / B`` (elliptic) or
``-R (f_+ - f_-) / (2 μ B) = -R f_t / (2 μ² B)`` (pyramidal), whatever the friction margin
``|f_t| / (μ f_n)``: ``v_t = -c f_t`` with ``c = (1 - d)/d · A / (impratio · B)``, times
``1 + μ²`` on the pyramidal cone, m/s per N. A controller sets only the forces and, through
the penetration, ``d``: ``c`` falls at most from ``(1 - dmin)/dmin`` to ``(1 - dmax)/dmax``
(a deeper squeeze; a factor 0.47 with MuJoCo's default ``solimp``). A grasp whose contact
normals are horizontal (the paper's: box faces ±x, +y) carries the object's weight ``m g``
by friction alone, ``Σ_i |f_t,i| ≥ m g``. So over a hold of ``T`` seconds the contacts slip
at least ``Σ_i s_i ≥ c_min m g T`` in total (``c_min``: the smallest coefficient, at
``dmax``), whatever the filter does; with a normal that is not horizontal the bound is not
reported. MuJoCo's no-slip solver (``noslip_iterations`` > 0) recomputes the friction
forces without ``R``: no creep, and no law to check.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass, replace
import json
from pathlib import Path
import sys
from typing import Any

import numpy as np

from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_tools.bench.recorded_run import Scenario
from hand_sim_node.mjcf import MjcfOptions
from hand_sim_node.mujoco_plant import MuJoCoPlant

#: The hold's filter: the diamond cone with a 30 % margin keeps every force well inside
#: MuJoCo's pyramid, so that what slips is creep, not sliding.
HOLD_FILTER = {'no_slip.cone': 'diamond', 'no_slip.friction_margin': 0.3}


@dataclass(frozen=True)
class ContactCreep:
    """MuJoCo's friction rows of the fingertip contacts at one state (NaN: no contact).

    Attributes:
        normal_force: Normal force per contact, shape (n,), N.
        friction_force: Friction force in MuJoCo's contact frame's tangent axes, (n, 2), N.
        slip_velocity: MuJoCo's relative tangential velocity there, (n, 2), m/s.
        creep_velocity: The creep law's velocity from the same rows' R, B and forces, (n, 2),
            m/s.
        impedance: MuJoCo's impedance ``d`` of the contact's rows, shape (n,).
        coefficient: The creep coefficient ``c``, shape (n,), m/s per N.
    """

    normal_force: np.ndarray
    friction_force: np.ndarray
    slip_velocity: np.ndarray
    creep_velocity: np.ndarray
    impedance: np.ndarray
    coefficient: np.ndarray


def contact_creep(plant: MuJoCoPlant) -> ContactCreep:
    """Read the creep law's terms of every fingertip contact (condim 3) at the plant's state."""
    data = plant.mj_data
    pyramidal = plant.options.cone == 'pyramidal'
    n = plant.model.n_contacts
    normal, impedance, coefficient = np.full(n, np.nan), np.full(n, np.nan), np.full(n, np.nan)
    force, slip, creep = np.full((n, 2), np.nan), np.full((n, 2), np.nan), np.full((n, 2), np.nan)
    for i, contact, _ in plant.fingertip_contacts():
        if contact.dim != 3:
            raise ConfigError(
                f'mujoco.condim: the creep law is measured on condim 3 contacts, got {contact.dim}'
            )
        a, mu = contact.efc_address, float(contact.friction[0])
        if pyramidal:
            f, R = data.efc_force[a : a + 4], data.efc_R[a : a + 4]
            vel, B = data.efc_vel[a : a + 4], data.efc_KBIP[a, 1]
            normal[i] = f.sum()
            force[i] = mu * (f[0::2] - f[1::2])
            slip[i] = (vel[0::2] - vel[1::2]) / (2.0 * mu)
            creep[i] = -(R[0::2] * f[0::2] - R[1::2] * f[1::2]) / (2.0 * mu * B)
            coefficient[i] = R.mean() / (2.0 * mu**2 * B)
        else:
            f, R = data.efc_force[a : a + 3], data.efc_R[a : a + 3]
            B = data.efc_KBIP[a + 1 : a + 3, 1]
            normal[i] = f[0]
            force[i] = f[1:]
            slip[i] = data.efc_vel[a + 1 : a + 3]
            creep[i] = -R[1:] * f[1:] / B
            coefficient[i] = float(np.mean(R[1:] / B))
        impedance[i] = data.efc_KBIP[a, 2]
    return ContactCreep(normal, force, slip, creep, impedance, coefficient)


def hold(
    scenario: Scenario, options: MjcfOptions, duration: float = 2.0, window: float = 1.0
) -> dict[str, Any]:
    """Hold the grasp still for ``duration`` s; average the creep terms over the last ``window``.

    Returns per contact (lists, contact order): mean normal force and |friction force| (N),
    mean impedance, measured slip speed ``|mean v|`` and the law's ``|mean v_law|`` (mm/s),
    the law's relative error ``|mean v - mean v_law| / |mean v|``, the creep coefficient
    (mm/s per N), and the lower bound on the total slip of a ``scenario`` run (mm).
    """
    nominal = replace(scenario.nominal_config, amplitude=(0.0,) * 6)
    plant = MuJoCoPlant(scenario.model, scenario.sim_config, options)
    start = plant.grasp_state()
    weight = float(np.linalg.norm(start.w_e[:3]))
    # The bound needs friction to carry the whole weight: every normal of the grasp horizontal.
    normal_in_palm = start.R_contact_to_palm[:, :, 2]
    horizontal = bool(np.all(np.abs(normal_in_palm @ start.w_e[:3]) <= 1e-9 * weight))
    samples: list[ContactCreep] = []
    run = replace(scenario, nominal_config=nominal).run_on(
        plant,
        filtered=True,
        duration=duration,
        after_step=lambda _plant: samples.append(contact_creep(plant)),
    )
    last = samples[-round(window / plant.time_step) :]
    slip = np.nanmean([s.slip_velocity for s in last], axis=0)
    law = np.nanmean([s.creep_velocity for s in last], axis=0)
    impedance = np.nanmean([s.impedance for s in last], axis=0)
    coefficient = np.nanmean([s.coefficient for s in last], axis=0)
    dmax = options.solimp[1]
    # c ∝ (1 - d)/d: its smallest value, at d = dmax.
    c_min = float(np.min(coefficient * ((1 - dmax) / dmax) / ((1 - impedance) / impedance)))

    speed = np.linalg.norm(slip, axis=1)
    figures = {
        'ended': run.stop_reason,
        'normal_force_N': np.nanmean([s.normal_force for s in last], axis=0),
        'friction_force_N': np.nanmean(
            [np.linalg.norm(s.friction_force, axis=1) for s in last], axis=0
        ),
        'impedance': impedance,
        'slip_speed_mm_s': 1e3 * speed,
        'law_speed_mm_s': 1e3 * np.linalg.norm(law, axis=1),
        'law_error': np.linalg.norm(slip - law, axis=1) / np.maximum(speed, 1e-12),
        'coefficient_mm_s_per_N': 1e3 * coefficient,
        'slip_distance_mm': 1e3 * plant.contact_report().slip_distance,
    }
    out: dict[str, Any] = {
        key: np.round(value, 4).tolist() for key, value in figures.items() if key != 'ended'
    }
    out['ended'] = run.stop_reason
    out['run_duration_s'] = scenario.sim_config.duration
    out['noslip'] = options.noslip_iterations > 0
    if options.noslip_iterations == 0 and horizontal:
        out['run_slip_lower_bound_mm'] = round(
            1e3 * c_min * weight * scenario.sim_config.duration, 1
        )
    return out


#: The measured settings: (label, MuJoCo options, nominal squeeze k_f in N/m, filter overrides).
SETTINGS: tuple[tuple[str, dict[str, Any], float, dict[str, Any]], ...] = (
    ('default contacts', {}, 10.0, {}),
    ('squeeze kf 30', {}, 30.0, {}),
    ('squeeze kf 100', {}, 100.0, {}),
    ('friction margin 0.5', {}, 10.0, {'no_slip.friction_margin': 0.5}),
    ('object-surface barrier', {}, 10.0, {'object_workspace.enabled': True}),
    ('impratio 10', {'impratio': 10.0}, 10.0, {}),
    ('solimp dmin = dmax = 0.99', {'solimp': (0.99, 0.99, 0.001, 0.5, 2.0)}, 10.0, {}),
    ('solref 0.01', {'solref': (0.01, 1.0)}, 10.0, {}),
    ('solref 0.004 (stiff)', {'solref': (0.004, 1.0)}, 10.0, {}),
    ('elliptic', {'cone': 'elliptic'}, 10.0, {}),
    ('elliptic, impratio 10', {'cone': 'elliptic', 'impratio': 10.0}, 10.0, {}),
    (
        'elliptic, impratio 10, solref 0.004',
        {'cone': 'elliptic', 'impratio': 10.0, 'solref': (0.004, 1.0)},
        10.0,
        {},
    ),
    ('noslip 10', {'noslip_iterations': 10}, 10.0, {}),
    ('noslip 10, elliptic', {'noslip_iterations': 10, 'cone': 'elliptic'}, 10.0, {}),
)


def measure_settings(config: Path, duration: float, window: float) -> list[dict[str, Any]]:
    """Hold the grasp under every one of :data:`SETTINGS`."""
    rows = []
    for label, mujoco_options, kf, overrides in SETTINGS:
        scenario = Scenario.load(config, {**HOLD_FILTER, **overrides})
        scenario = replace(scenario, nominal_config=replace(scenario.nominal_config, kf=kf))
        figures = hold(scenario, MjcfOptions(**mujoco_options), duration, window)
        rows.append({'setting': label, **figures})
    return rows


def markdown(rows: list[dict[str, Any]]) -> str:
    """Return the rows as docs/mujoco.md's table (per contact ``f1/f2/f3``)."""

    def triple(values: list[float], digits: int) -> str:
        return '/'.join(f'{value:.{digits}f}' for value in values)

    lines = [
        '| setting | f_n, N | \\|f_t\\|, N | d | slip speed, mm/s | law, mm/s | c, mm/s per N '
        f'| {rows[0]["run_duration_s"]:g} s bound on Σ slip, mm |' if rows else '|',
        '| --- | --- | --- | --- | --- | --- | --- | --- |',
    ]
    for row in rows:
        lines.append(
            f'| {row["setting"]} | {triple(row["normal_force_N"], 2)} '
            f'| {triple(row["friction_force_N"], 2)} | {triple(row["impedance"], 3)} '
            f'| {triple(row["slip_speed_mm_s"], 2)} '
            f'| {"–" if row["noslip"] else triple(row["law_speed_mm_s"], 2)} '
            f'| {triple(row["coefficient_mm_s_per_N"], 1)} '
            f'| {row.get("run_slip_lower_bound_mm", "–")} |'
        )
    return '\n'.join(lines)


def main(argv: list[str] | None = None) -> int:
    """Measure every setting; print the table (and write the figures with ``--json``)."""
    parser = argparse.ArgumentParser(
        prog='python -m grasp_tools.mujoco_creep', description=__doc__.splitlines()[0]
    )
    parser.add_argument('--config', type=Path, default=Path('config/paper_scenario.yaml'))
    parser.add_argument('--duration', type=float, default=2.0, help='hold, s')
    parser.add_argument('--window', type=float, default=1.0, help='averaged at the end, s')
    parser.add_argument('--json', type=Path, help='also write the figures here')
    args = parser.parse_args(argv)
    try:
        rows = measure_settings(args.config, args.duration, args.window)
    except (ConfigError, ValueError) as error:
        print(config_error_line('mujoco_creep', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    print(markdown(rows))
    if args.json is not None:
        args.json.write_text(json.dumps(rows, indent=2) + '\n')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
