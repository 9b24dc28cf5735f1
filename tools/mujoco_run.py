r"""The scenario's runs on the MuJoCo plant, measured: ``python -m grasp_tools.mujoco_run``.

Runs the nominal and/or the filtered closed loop (:func:`~grasp_tools.closed_loop.
run_closed_loop`) on :class:`~hand_sim_node.mujoco_plant.MuJoCoPlant` and prints, per run,
what MuJoCo measured: when each contact was first lost and when the object dropped, the slip
distance per contact, the largest slip speed, the deepest penetration, the joint limits
passed, the filter's statuses. ``--json`` writes the figures to a file. A measurement, not a
test: nothing is asserted.

Example (the paper's two runs, MuJoCo's default contacts, then stiff ones, then without the
creep of soft friction)::

    python -m grasp_tools.mujoco_run --config config/paper_scenario.yaml --mode both
    python -m grasp_tools.mujoco_run --config config/paper_scenario.yaml --mode both \
        --solref 0.004 1.0
    python -m grasp_tools.mujoco_run --config config/paper_scenario.yaml --mode both \
        --noslip-iterations 10
    python -m grasp_tools.mujoco_run --config config/paper_scenario.yaml --mode filtered \
        --set torque_rate.enabled=true --set torque_rate.max_step=0.05
    python -m grasp_tools.mujoco_run --config config/paper_scenario.yaml --mode filtered \
        --noslip-iterations 10 --set no_slip.cone=diamond --set no_slip.friction_margin=0.3

Soft fingers (``--plant-set`` overrides the simulator's parameters, the model's among them)
on MuJoCo's torsional contacts, and on our rigid plant::

    python -m grasp_tools.mujoco_run --mode nominal --condim 4 \
        --plant-set model.torsional_friction=0.005
    python -m grasp_tools.mujoco_run --mode nominal --plant rigid \
        --plant-set model.torsional_friction=0.005
"""

from __future__ import annotations

import argparse
from collections import Counter
import json
from pathlib import Path
import sys
from typing import Any

import numpy as np

from grasp_safety_filter.cli import parse_override
from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_tools.bench.recorded_run import Scenario
from grasp_tools.closed_loop import LoopRun
from hand_sim_node.mjcf import CONES, INTEGRATORS, MjcfOptions
from hand_sim_node.mujoco_plant import ContactReport, MuJoCoPlant
from hand_sim_node.plant import RigidPlant

#: Times at which the slip distance so far is reported too, s.
SLIP_CHECKPOINTS = (0.3, 1.0, 5.0)

#: ``--mode`` values: the runs each one makes.
MODES = {'nominal': ('nominal',), 'filtered': ('filtered',), 'both': ('nominal', 'filtered')}


def measure(run: LoopRun, reports: list[ContactReport], plant: MuJoCoPlant) -> dict[str, Any]:
    """Figures of one run from its ticks and MuJoCo's contact report after every step."""
    model = plant.model
    names = model.contact_names
    present = np.array([report.present for report in reports])
    t = np.array([report.t for report in reports])
    lost = {
        name: (float(t[np.flatnonzero(~present[:, i])[0]]) if (~present[:, i]).any() else None)
        for i, name in enumerate(names)
    }
    dropped = [report.t for report in reports if report.object_dropped]
    q = np.vstack([run.array('q'), run.final.q[None]])
    below = np.max(model.joint_lower_limits - q, axis=0)
    above = np.max(q - model.joint_upper_limits, axis=0)
    passed = {
        name: float(max(lo, hi))
        for name, lo, hi in zip(model.joint_names, below, above, strict=True)
        if max(lo, hi) > 0.0
    }
    last = reports[-1]
    statuses = Counter(str(tick.status.value) for tick in run.ticks if tick.status is not None)
    return {
        'stop_reason': run.stop_reason,
        't_end_s': run.final.t,
        'wall_s': run.wall,
        'contact_first_lost_s': lost,
        'object_dropped_s': dropped[0] if dropped else None,
        'slip_distance_mm': dict(zip(names, (1e3 * last.slip_distance).tolist(), strict=True)),
        'slip_distance_mm_at_s': {
            str(checkpoint): (1e3 * reports[index].slip_distance).round(3).tolist()
            for checkpoint in SLIP_CHECKPOINTS
            if (index := int(np.searchsorted(t, checkpoint - 1e-9))) < len(reports)
        },
        'max_slip_speed_mm_s': dict(
            zip(
                names,
                (1e3 * np.max([r.slip_speed for r in reports], axis=0)).tolist(),
                strict=True,
            )
        ),
        'max_penetration_mm': dict(
            zip(
                names, (-1e3 * np.min([r.distance for r in reports], axis=0)).tolist(), strict=True
            )
        ),
        'joint_limits_passed_rad': passed,
        'object_position_end_m': run.final.p_object_in_palm.tolist(),
        'max_abs_torque_Nm': float(np.max(np.abs(run.array('u')))),
        'max_torque_step_Nm': max_torque_step(run.array('u')),
        'filter_statuses': dict(statuses),
    }


def max_torque_step(u: np.ndarray) -> float:
    """Largest ``|u_k,j - u_k-1,j|`` over ticks k and joints j (u shape (ticks, m)), N·m."""
    return float(np.max(np.abs(np.diff(u, axis=0)))) if len(u) > 1 else 0.0


def run_on_mujoco(
    scenario: Scenario, options: MjcfOptions, mode: str, duration: float
) -> dict[str, Any]:
    """One run (``"nominal"`` or ``"filtered"``) of ``scenario`` on MuJoCo, measured."""
    plant = MuJoCoPlant(scenario.model, scenario.sim_config, options)
    reports: list[ContactReport] = []
    run = scenario.run_on(
        plant,
        mode == 'filtered',
        duration,
        after_step=lambda _plant: reports.append(plant.contact_report()),
    )
    return measure(run, reports, plant)


def run_on_rigid(scenario: Scenario, mode: str, duration: float) -> dict[str, Any]:
    """Run on our rigid plant: steps violating each constraint family, statuses."""
    plant = RigidPlant(scenario.model, scenario.sim_config)
    events: Counter[str] = Counter()

    def count(_plant: object) -> None:
        if plant.last_report is not None:
            events.update(event.family for event in plant.last_report.events)

    run = scenario.run_on(plant, mode == 'filtered', duration, after_step=count)
    statuses = Counter(str(tick.status.value) for tick in run.ticks if tick.status is not None)
    return {
        'stop_reason': run.stop_reason,
        't_end_s': run.final.t,
        'violation_steps': dict(events),
        'first_violated_s': {
            family: record['first_t']
            for family, record in plant.log.violations().items()
            if record['first_t'] is not None
        },
        'max_torque_step_Nm': max_torque_step(run.array('u')),
        'filter_statuses': dict(statuses),
    }


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Command line (see the module docstring)."""
    parser = argparse.ArgumentParser(
        prog='python -m grasp_tools.mujoco_run', description=__doc__.splitlines()[0]
    )
    parser.add_argument('--config', type=Path, default=Path('config/paper_scenario.yaml'))
    parser.add_argument('--mode', choices=sorted(MODES), default='both')
    parser.add_argument('--duration', type=float, help="s (default: the scenario's)")
    parser.add_argument(
        '--plant',
        choices=('mujoco', 'rigid'),
        default='mujoco',
        help='rigid: the same runs on our own plant (MuJoCo options unused)',
    )
    defaults = MjcfOptions()
    parser.add_argument(
        '--solref',
        type=float,
        nargs=2,
        default=defaults.solref,
        metavar=('TIMECONST', 'DAMPRATIO'),
    )
    parser.add_argument('--cone', choices=CONES, default=defaults.cone)
    parser.add_argument('--condim', type=int, default=defaults.condim)
    parser.add_argument(
        '--torsional-friction',
        type=float,
        default=defaults.torsional_friction,
        help="MuJoCo's, m (condim 4 and 6)",
    )
    parser.add_argument('--impratio', type=float, default=defaults.impratio)
    parser.add_argument(
        '--noslip-iterations',
        type=int,
        default=defaults.noslip_iterations,
        help="MuJoCo no-slip post-solver iterations (0: off, MuJoCo's default)",
    )
    parser.add_argument('--timestep', type=float, default=defaults.timestep, help='MuJoCo step, s')
    parser.add_argument('--integrator', choices=INTEGRATORS, default=defaults.integrator)
    parser.add_argument('--friction', type=float, help="plant mu (default: the model's)")
    parser.add_argument(
        '--set',
        type=parse_override,
        action='append',
        default=[],
        metavar='NAME=VALUE',
        help='override a safety-filter parameter (repeatable), e.g. torque_rate.enabled=true',
    )
    parser.add_argument(
        '--plant-set',
        type=parse_override,
        action='append',
        default=[],
        metavar='NAME=VALUE',
        help="override a simulator's parameter (repeatable), e.g. model.torsional_friction=0.005",
    )
    parser.add_argument('--json', type=Path, help='also write the figures here')
    return parser.parse_args(argv)


def main(argv: list[str] | None = None) -> int:
    """Run and print the figures as JSON."""
    args = parse_args(argv)
    try:
        options = MjcfOptions(
            friction_coefficient=args.friction,
            cone=args.cone,
            condim=args.condim,
            torsional_friction=args.torsional_friction,
            solref=tuple(args.solref),
            impratio=args.impratio,
            noslip_iterations=args.noslip_iterations,
            timestep=args.timestep,
            integrator=args.integrator,
        )
        scenario = Scenario.load(args.config, dict(args.set), dict(args.plant_set))
    except (ConfigError, ValueError) as error:
        print(config_error_line('mujoco_run', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    duration = args.duration or scenario.sim_config.duration
    figures = {
        'config': str(args.config),
        'filter_overrides': dict(args.set),
        'plant_overrides': dict(args.plant_set),
        'duration_s': duration,
        'plant': args.plant,
        'mujoco': {
            'solref': list(options.solref),
            'solimp': list(options.solimp),
            'cone': options.cone,
            'condim': options.condim,
            'torsional_friction': options.torsional_friction,
            'impratio': options.impratio,
            'noslip_iterations': options.noslip_iterations,
            'timestep_s': options.timestep,
            'integrator': options.integrator,
            'friction': options.friction(scenario.model).tolist(),
        },
    }
    for mode in MODES[args.mode]:
        figures[mode] = (
            run_on_rigid(scenario, mode, duration)
            if args.plant == 'rigid'
            else run_on_mujoco(scenario, options, mode, duration)
        )
    text = json.dumps(figures, indent=2)
    print(text)
    if args.json is not None:
        args.json.write_text(text + '\n')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
