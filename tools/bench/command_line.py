"""``grasp-bench`` command line: the benchmark, or ``--soak`` for the long-run one."""

from __future__ import annotations

import argparse
from collections.abc import Callable
import json
from pathlib import Path
import sys
from typing import Any

from grasp_safety_filter.cli import parse_override
from grasp_safety_filter.control.qp_solvers import BACKENDS
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import MODEL_PARAMETERS
from grasp_tools.bench.report import benchmark, format_report


def bench_parser() -> argparse.ArgumentParser:
    """Return ``grasp-bench``'s argument parser."""
    parser = argparse.ArgumentParser(prog='grasp-bench', description=bench_main.__doc__)
    parser.add_argument(
        '--config', type=Path, default=config_path(), help='scenario parameter file'
    )
    parser.add_argument(
        '--duration', type=float, default=15.0, help='simulated time of the runs, s (15)'
    )
    parser.add_argument('--ticks', type=int, help='replay at most N ticks (default: all)')
    parser.add_argument(
        '--warmup', type=int, default=200, help='untimed warm-up ticks before the replay (200)'
    )
    parser.add_argument(
        '--external-ticks',
        type=int,
        default=1000,
        help='hard QPs, evenly spaced, given to cvxpy and daqp (1000; 0: none)',
    )
    parser.add_argument(
        '--runner-duration',
        type=float,
        default=2.0,
        help='simulated time of the runner run with bag recording, s (2; 0: skip)',
    )
    parser.add_argument(
        '--backends',
        type=lambda text: [b for b in text.split(',') if b],
        default=list(BACKENDS),
        metavar='NAMES',
        help='QP backends (qp.solver) compared on the same ticks, comma-separated '
        f'(default: {",".join(BACKENDS)}; empty: none)',
    )
    parser.add_argument(
        '--compare-config',
        type=Path,
        action='append',
        default=[],
        metavar='PATH',
        help="another scenario whose hand's node tick is compared with --config's in the "
        'same run, tick after tick in alternating blocks (repeatable; e.g. '
        'config/four_finger_box.yaml)',
    )
    parser.add_argument(
        '--set',
        dest='overrides',
        metavar='NAME=VALUE',
        type=parse_override,
        action='append',
        default=[],
        help='override a safety-filter parameter, e.g. --set osqp.eps_abs=1e-3, or a model '
        'parameter, which every part reads, e.g. --set model.torsional_friction=0.005',
    )
    parser.add_argument(
        '--soak',
        type=float,
        metavar='SECONDS',
        help='instead: the soak benchmark, a recorded filtered run of SECONDS simulated s '
        '(memory growth, bag size, analysis memory; grasp_tools.soak)',
    )
    parser.add_argument(
        '--soak-interval',
        type=float,
        default=1.0,
        help='simulated s between two memory samples of the soak (1)',
    )
    parser.add_argument(
        '--soak-out',
        type=Path,
        default=Path('soak'),
        help='directory of the soak bags and analyses (replaced; default: soak)',
    )
    parser.add_argument(
        '--json',
        nargs='?',
        const='-',
        metavar='PATH',
        help='print the figures as JSON (the table then goes to stderr), or write them to PATH',
    )
    return parser


def bench_main(argv: list[str] | None = None) -> int:
    """``grasp-bench``: time the model, the QP and the filter over the paper's filtered run."""
    parser = bench_parser()
    args = parser.parse_args(argv)
    if args.duration <= 0:
        parser.error(f'--duration: expected > 0 s, got {args.duration}')
    if args.ticks is not None and args.ticks < 1:
        parser.error(f'--ticks: expected >= 1, got {args.ticks}')
    unknown = [b for b in args.backends if b not in BACKENDS]
    if unknown:
        parser.error(f'--backends: expected names among {", ".join(BACKENDS)}, got {unknown[0]!r}')

    def log(message: str) -> None:
        print(f'grasp-bench: {message}', file=sys.stderr, flush=True)

    from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
    from grasp_safety_filter.model.grasp_check import load_initial_grasp

    overrides = dict(args.overrides)
    # The model's parameters go to every part (the simulator's model is the filter's).
    model_names = {spec.name for spec in MODEL_PARAMETERS}
    model_overrides = {name: overrides.pop(name) for name in model_names & set(overrides)}
    try:
        for config in (args.config, *args.compare_config):
            load_initial_grasp(config, model_overrides)  # the simulator's start-up checks
    except ConfigError as error:
        print(config_error_line('grasp-bench', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    if args.soak is not None:
        return _soak_main(args, parser, log)
    document = benchmark(
        args.config,
        args.duration,
        max_ticks=args.ticks,
        warmup=max(0, args.warmup),
        external_ticks=max(0, args.external_ticks),
        runner_duration=max(0.0, args.runner_duration),
        filter_overrides=overrides,
        backends=args.backends,
        model_overrides=model_overrides,
        log=log,
        compare_configs=args.compare_config,
    )
    _print(format_report(document), document, args.json)
    return 0


def _soak_main(
    args: argparse.Namespace, parser: argparse.ArgumentParser, log: Callable[[str], None]
) -> int:
    """``grasp-bench --soak SECONDS``: see :mod:`grasp_tools.soak`."""
    from grasp_tools.soak import format_soak, soak

    if args.soak <= 0 or args.soak_interval <= 0:
        parser.error('--soak and --soak-interval: expected > 0 s')
    document = soak(
        args.config,
        args.soak,
        args.soak_out,
        interval=args.soak_interval,
        overrides=dict(args.overrides),
        log=log,
    )
    _print(format_soak(document), document, args.json)
    return 0


def _print(report: str, document: dict[str, Any], json_target: str | None) -> None:
    """Print the table; the JSON to stdout (``-``, table to stderr) or to a file."""
    text = json.dumps(document, indent=2) + '\n'
    if json_target == '-':
        print(report, file=sys.stderr)
        sys.stdout.write(text)
    else:
        print(report)
        if json_target is not None:
            Path(json_target).write_text(text)


if __name__ == '__main__':
    sys.exit(bench_main())
