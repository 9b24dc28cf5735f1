r"""Our model against MuJoCo at the torques of a run: ``python -m grasp_tools.mujoco_compare``.

Runs the scenario's nominal or filtered closed loop on MuJoCo and, at every tick, compares
what our rigid model predicts at MuJoCo's state under the torque applied there (the contact
forces ``f_c(u)`` and the object acceleration ``x_o_ddot(u)``, the affine maps the filter's
rows are built from) with what MuJoCo computed for the same state and torque (its contact
forces in our contact frames and its object acceleration, of the step's first MuJoCo step).
Prints the median / p99 / max of the errors (per-contact force error norm, N; object
linear, m/s², and angular, rad/s², acceleration error norm) and of their scale, and writes a
figure (``--figure``): the normal forces of both over time, and the error norms.

With soft fingers (``--plant-set model.torsional_friction=...`` > 0) it also compares each
contact's torsion, the torque on the object about the normal ``n_i`` (N·m): MuJoCo has one
with ``--condim 4`` (or 6), and with a torsional friction large enough that nothing spins
its contacts are soft fingers too (MuJoCo's torsion is a soft constraint whose regulariser
grows as 1 / mu_t²: at 0.05 m it still creeps, at 5 m it holds).

Example (the paper's filtered run, default contacts; then stiff ones)::

    python -m grasp_tools.mujoco_compare --mode filtered --figure /tmp/compare.png
    python -m grasp_tools.mujoco_compare --mode filtered --solref 0.004 1.0 \
        --solimp 0.99 0.99 0.001 0.5 2 --cone elliptic --figure /tmp/compare-stiff.png

Soft fingers on both sides (stiff contacts, no spin)::

    python -m grasp_tools.mujoco_compare --mode nominal \
        --plant-set model.torsional_friction=0.05 --condim 4 --torsional-friction 5 \
        --cone elliptic --solref 0.004 1.0 --solimp 0.99 0.99 0.001 0.5 2
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
import json
from pathlib import Path
import sys
from typing import Any

import numpy as np

from grasp_safety_filter.cli import parse_override
from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_tools.bench.recorded_run import Scenario
from hand_sim_node.mjcf import CONDIMS, CONES, MjcfOptions
from hand_sim_node.mujoco_plant import MuJoCoPlant


@dataclass(frozen=True)
class Comparison:
    """Model and MuJoCo side by side, one row per tick.

    Attributes:
        t: Tick times, (k,), s.
        force_model: Our model's contact forces ``f_c(u)``, (k, n, 3), N, contact frames.
        force_mujoco: MuJoCo's, (k, n, 3), N, the same frames.
        acceleration_model: Our model's ``x_o_ddot(u) = (a_o, alpha_o)``, (k, 6), palm frame.
        acceleration_mujoco: MuJoCo's, (k, 6).
        torsion_model: With soft fingers, our model's torsions (k, n), N·m, the torque on the
            object about each contact normal; None with point contacts.
        torsion_mujoco: MuJoCo's (0 below ``condim`` 4), or None.
    """

    t: np.ndarray
    force_model: np.ndarray
    force_mujoco: np.ndarray
    acceleration_model: np.ndarray
    acceleration_mujoco: np.ndarray
    torsion_model: np.ndarray | None = None
    torsion_mujoco: np.ndarray | None = None

    def errors(self) -> dict[str, np.ndarray]:
        """Error norms per tick: per contact force (k, n), N; linear and angular, (k,).

        With soft fingers also the torsion error per contact, ``torsion_Nm`` (k, n), N·m.
        """
        difference = self.acceleration_model - self.acceleration_mujoco
        errors = {
            'force_N': np.linalg.norm(self.force_model - self.force_mujoco, axis=2),
            'linear_acceleration_m_s2': np.linalg.norm(difference[:, :3], axis=1),
            'angular_acceleration_rad_s2': np.linalg.norm(difference[:, 3:], axis=1),
        }
        if self.torsion_model is not None and self.torsion_mujoco is not None:
            errors['torsion_Nm'] = np.abs(self.torsion_model - self.torsion_mujoco)
        return errors

    def scales(self) -> dict[str, np.ndarray]:
        """Return MuJoCo's magnitudes of the same quantities, to read the errors against."""
        scales = {
            'force_N': np.linalg.norm(self.force_mujoco, axis=2),
            'linear_acceleration_m_s2': np.linalg.norm(self.acceleration_mujoco[:, :3], axis=1),
            'angular_acceleration_rad_s2': np.linalg.norm(self.acceleration_mujoco[:, 3:], axis=1),
        }
        if self.torsion_mujoco is not None:
            scales['torsion_Nm'] = np.abs(self.torsion_mujoco)
        return scales


def compare(
    scenario: Scenario, options: MjcfOptions, mode: str, duration: float
) -> tuple[Comparison, str]:
    """Run ``mode`` (``"nominal"`` or ``"filtered"``) on MuJoCo.

    Returns:
        The comparison of every tick, and the run's stop reason.
    """
    plant = MuJoCoPlant(scenario.model, scenario.sim_config, options)
    rows: list[tuple[float, np.ndarray, np.ndarray, np.ndarray, np.ndarray]] = []

    def record(_plant: object) -> None:
        report = plant.last_report
        assert report is not None
        state, u = report.grasp_state, report.effort
        rows.append(
            (
                state.t,
                state.contact_force(u),
                report.contact_force,
                state.object_acceleration(u),
                plant.last_object_acceleration_in_palm,
            )
        )

    run = scenario.run_on(plant, mode == 'filtered', duration, after_step=record)
    n = scenario.model.n_contacts
    t, f_model, f_mujoco, a_model, a_mujoco = (
        np.array(column) for column in zip(*rows, strict=True)
    )
    # A soft finger's wrench: the 3n forces, then the n torsions.
    soft = scenario.model.soft_finger
    comparison = Comparison(
        t,
        f_model[:, : 3 * n].reshape(-1, n, 3),
        f_mujoco[:, : 3 * n].reshape(-1, n, 3),
        a_model,
        a_mujoco,
        f_model[:, 3 * n :] if soft else None,
        f_mujoco[:, 3 * n :] if soft else None,
    )
    return comparison, run.stop_reason


def statistics(values: np.ndarray) -> dict[str, float]:
    """Median, 99th percentile and maximum over every entry."""
    flat = np.asarray(values, dtype=float).ravel()
    return {
        'median': float(np.median(flat)),
        'p99': float(np.percentile(flat, 99)),
        'max': float(np.max(flat)),
    }


def summary(comparison: Comparison) -> dict[str, Any]:
    """Return the errors' and scales' statistics (the force over every contact and tick)."""
    scales = comparison.scales()
    return {
        name: {'error': statistics(error), 'mujoco': statistics(scales[name])}
        for name, error in comparison.errors().items()
    }


def draw(comparison: Comparison, contact_names: list[str], path: Path) -> None:
    """Draw the normal forces of both over time (a panel per contact), then the errors."""
    import matplotlib

    matplotlib.use('Agg')
    import matplotlib.pyplot as plt

    n = len(contact_names)
    figure, axes = plt.subplots(n + 1, 1, figsize=(8, 2.2 * (n + 1)), sharex=True)
    t = comparison.t
    for i, name in enumerate(contact_names):
        axes[i].plot(t, comparison.force_mujoco[:, i, 2], label='MuJoCo f_n')
        axes[i].plot(t, comparison.force_model[:, i, 2], '--', label='model f_n(u)')
        axes[i].set_ylabel(f'{name}, N')
        axes[i].legend(loc='upper right', fontsize='small')
    errors = comparison.errors()
    for i, name in enumerate(contact_names):
        axes[n].semilogy(t, errors['force_N'][:, i], label=f'|Δf| {name}, N')
    axes[n].semilogy(t, errors['linear_acceleration_m_s2'], 'k', label='|Δa_o|, m/s²')
    axes[n].set_xlabel('t, s')
    axes[n].legend(loc='upper right', fontsize='small')
    figure.tight_layout()
    figure.savefig(path, dpi=120)
    plt.close(figure)


def main(argv: list[str] | None = None) -> int:
    """Compare, print the statistics as JSON, optionally draw the figure."""
    parser = argparse.ArgumentParser(
        prog='python -m grasp_tools.mujoco_compare', description=__doc__.splitlines()[0]
    )
    defaults = MjcfOptions()
    parser.add_argument('--config', type=Path, default=Path('config/paper_scenario.yaml'))
    parser.add_argument('--mode', choices=('nominal', 'filtered'), default='filtered')
    parser.add_argument('--duration', type=float, help="s (default: the scenario's)")
    parser.add_argument('--solref', type=float, nargs=2, default=defaults.solref)
    parser.add_argument('--solimp', type=float, nargs=5, default=defaults.solimp)
    parser.add_argument('--cone', choices=CONES, default=defaults.cone)
    parser.add_argument('--condim', type=int, choices=CONDIMS, default=defaults.condim)
    parser.add_argument(
        '--torsional-friction',
        type=float,
        default=defaults.torsional_friction,
        help="MuJoCo's, m (condim 4 and 6)",
    )
    parser.add_argument('--noslip-iterations', type=int, default=defaults.noslip_iterations)
    parser.add_argument(
        '--plant-set',
        type=parse_override,
        action='append',
        default=[],
        dest='overrides',
        metavar='NAME=VALUE',
        help="override a parameter of the simulator's (e.g. model.torsional_friction=0.05)",
    )
    parser.add_argument('--figure', type=Path, help='write the figure here (PNG)')
    parser.add_argument('--json', type=Path, help='also write the statistics here')
    args = parser.parse_args(argv)
    try:
        options = MjcfOptions(
            solref=tuple(args.solref),
            solimp=tuple(args.solimp),
            cone=args.cone,
            condim=args.condim,
            torsional_friction=args.torsional_friction,
            noslip_iterations=args.noslip_iterations,
        )
        scenario = Scenario.load(args.config, plant_overrides=dict(args.overrides))
    except (ConfigError, ValueError) as error:
        print(config_error_line('mujoco_compare', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    comparison, stop_reason = compare(
        scenario, options, args.mode, args.duration or scenario.sim_config.duration
    )
    figures = {
        'mode': args.mode,
        'stop_reason': stop_reason,
        't_end_s': float(comparison.t[-1]),
        'model_torsional_friction': (
            None
            if scenario.model.torsional_friction is None
            else scenario.model.torsional_friction.tolist()
        ),
        'mujoco': {
            'solref': list(options.solref),
            'solimp': list(options.solimp),
            'cone': options.cone,
            'condim': options.condim,
            'torsional_friction': options.torsional_friction,
            'noslip_iterations': options.noslip_iterations,
        },
        **summary(comparison),
    }
    text = json.dumps(figures, indent=2)
    print(text)
    if args.json is not None:
        args.json.write_text(text + '\n')
    if args.figure is not None:
        draw(comparison, scenario.model.contact_names, args.figure)
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
