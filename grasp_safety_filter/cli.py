"""Command-line entry points (work without ROS)."""

from __future__ import annotations

import argparse
from collections.abc import Callable
import json
from pathlib import Path
import sys
from typing import Any, TYPE_CHECKING

from grasp_safety_filter.analysis.report import print_summary, verdict_document
from grasp_safety_filter.errors import config_error_line, ConfigError, EXIT_CONFIG_ERROR
from grasp_safety_filter.io.parameters import ParameterError, parse_parameter_value
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.plant_schema import PLANTS

if TYPE_CHECKING:
    from grasp_safety_filter.analysis.bag_scenario import BagScenario


def _progress_printer(label: str) -> Callable[[float, float], None] | None:
    """Show one line of progress on a terminal (nothing when output is redirected)."""
    if not sys.stderr.isatty():
        return None
    last = [-1]

    def show(t: float, duration: float) -> None:
        percent = int(100 * t / duration) if duration > 0 else 100
        if percent != last[0]:
            last[0] = percent
            end = '\n' if percent >= 100 else ''
            print(
                f'\r{label}: t = {t:6.2f} / {duration:g} s ({percent:3d} %)',
                end=end,
                file=sys.stderr,
                flush=True,
            )

    return show


def parse_override(text: str) -> tuple[str, Any]:
    """Parse ``--set NAME=VALUE`` (also the MuJoCo tools'), the value typed as in a file."""
    name, separator, value = text.partition('=')
    if not separator or not name:
        raise argparse.ArgumentTypeError(f'expected NAME=VALUE, got {text!r}')
    try:
        return name.strip(), parse_parameter_value(value)
    except ParameterError as error:
        raise argparse.ArgumentTypeError(f'{text!r}: {error}') from None


def _interrupt_message(interrupt: Any) -> str:
    """Say what an interrupted run left (a ``demo_runs.Interruption``)."""
    by = f'interrupted by {interrupt.signal}'
    if interrupt.bag is None:
        return f'{by} before recording: this run left no bag, no summary'
    if interrupt.summary is None:
        return f'{by}: the bag is in {interrupt.bag}; it holds too little of the run for a summary'
    return f'{by}: the bag and summary are in {interrupt.summary.parent}'


def demo_main(argv: list[str] | None = None) -> int:
    """``grasp-demo``: a scenario's runs (default: the paper's), with figures and verdicts."""
    try:
        from grasp_safety_filter.io.interrupts import interrupt_on_signals

        # Start-up too: the grasp check compiles or loads kernels, and a signal that lands
        # in numba's code is sent again after it, not raised in a finalizer.
        with interrupt_on_signals():
            return _demo(argv)
    except KeyboardInterrupt:
        # Outside a run (start-up, between runs, the verdict): no partial run to report.
        print('\ngrasp-demo: interrupted before or between runs: no partial run', file=sys.stderr)
        return 130


def _demo(argv: list[str] | None) -> int:
    from grasp_safety_filter.demo_runs import fork_available, one_after_the_other, side_by_side
    from grasp_safety_filter.io.files import OutputError, write_file
    from grasp_safety_filter.model.grasp_check import load_initial_grasp
    from grasp_safety_filter.output_dir import check_output_dir, VERDICT_FILE
    from grasp_safety_filter.run_types import RunOptions

    parser = argparse.ArgumentParser(
        prog='grasp-demo',
        description=demo_main.__doc__,
        epilog=VERDICT_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument(
        '--mode',
        choices=('nominal', 'filtered', 'both'),
        default='both',
        help='nominal controller alone, with the safety filter, or both runs',
    )
    parser.add_argument(
        '--out',
        type=Path,
        default=Path('results'),
        help='output directory (with --mode both: OUT/nominal and OUT/filtered)',
    )
    parser.add_argument(
        '--config', type=Path, default=config_path(), help='scenario parameter file'
    )
    parser.add_argument('--duration', type=float, help='simulated time, s (default: scenario)')
    parser.add_argument('--dt', type=float, help='integration step, s (default: scenario)')
    parser.add_argument('--integrator', choices=('ode3', 'rk4'), help='default: scenario')
    parser.add_argument(
        '--storage', choices=('mcap', 'sqlite3'), default='mcap', help='bag storage format'
    )
    parser.add_argument(
        '--plant',
        choices=PLANTS,
        help="simulated plant (default: the scenario's plant parameter, rigid); the same as "
        "--set plant=NAME; MuJoCo's options: --set mujoco.cone=elliptic, ...",
    )
    parser.add_argument(
        '--set',
        dest='overrides',
        action='append',
        default=[],
        metavar='NAME=VALUE',
        type=parse_override,
        help='override a parameter of every node that declares it, e.g. '
        'barrier.alpha1.gain=10.0, or of one node with NODE/NAME=VALUE, e.g. '
        'hand_sim_node/model.friction_coefficient=0.6 (the plant only: a model mismatch) '
        '(YAML value, repeatable)',
    )
    parser.add_argument(
        '--force', action='store_true',
        help='write into OUT even if it holds files that are not a previous output',
    )  # fmt: skip
    parser.add_argument(
        '--jobs',
        type=int,
        choices=(1, 2),
        default=2 if fork_available() else 1,
        help='with --mode both: 2 runs the nominal run in a second process beside the '
        'filtered one (same outputs, on two cores), 1 one after the other '
        '(default: %(default)s)',
    )
    parser.add_argument(
        '--no-animation',
        dest='animate',
        action='store_false',
        help="skip each run's animation.gif",
    )
    args = parser.parse_args(argv)
    if args.plant is not None:
        args.overrides.append(('plant', args.plant))
    modes = ('nominal', 'filtered') if args.mode == 'both' else (args.mode,)
    verdicts = {}
    try:
        _, params = load_initial_grasp(args.config, dict(args.overrides))
    except ConfigError as error:
        print(config_error_line('grasp-demo', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    try:
        check_output_dir(args.out, args.force)
    except OutputError as error:
        print(f'grasp-demo: {error}', file=sys.stderr)
        return 2
    runs = []
    for mode in modes:
        try:
            options = RunOptions(
                args.config, mode, args.duration, args.dt, args.integrator, args.storage,
                dict(args.overrides), args.animate,
            )  # fmt: skip
        except ConfigError as error:
            print(config_error_line('grasp-demo', error), file=sys.stderr)
            return EXIT_CONFIG_ERROR
        runs.append((options, args.out / mode if args.mode == 'both' else args.out))
    runner = side_by_side if len(runs) == 2 and args.jobs == 2 else one_after_the_other
    status = 0
    for outcome in runner(runs, _progress_printer, args.force):
        if outcome.error is not None:
            print(outcome.error, file=sys.stderr)
            return outcome.exit_code
        if outcome.interruption is not None:
            left = _interrupt_message(outcome.interruption)
            print(f'\n[{outcome.mode}] {left}', file=sys.stderr)
            status = 130
            continue
        verdict, expected = print_summary(
            outcome.mode, outcome.summary, outcome.out_dir, params['expected_outcome']
        )
        verdicts[outcome.mode] = verdict_document(verdict, expected)
    if status:
        return status
    write_file(args.out / VERDICT_FILE, json.dumps(verdicts, indent=2) + '\n')
    return 1 if any(v.get('reproduced') is False for v in verdicts.values()) else 0


VERDICT_EPILOG = """\
Each run is judged from its summary.json: "held for the duration: yes" when it ran its
requested duration with no constraint violated, else "no" with its stop reason and time;
for each constraint family (fingertip_workspace, joint_limits, slip, separation, ...) the
steps violated and when and by which contact or joint it was first violated. A scenario
file whose hand_sim_node section sets expected_outcome (config/paper_scenario.yaml:
"paper") is also judged against that outcome: "paper outcome reproduced" or "NOT
reproduced" (an interrupted run's recording: "not judged"). grasp-demo writes the
verdicts to OUT/verdict.json.

On MuJoCo (--plant mujoco) a run is judged by MuJoCo's real contact events: "held" when
it ran its duration with no contact lost, the object not dropped and no joint limit
passed; the slip distance per contact is reported; the paper's expected outcome is about
the rigid plant and is "not judged".

exit codes:
  0    the runs completed as asked (a run that slips or stops early is an outcome)
  1    a run did not show its scenario's expected outcome (expected_outcome), or a run
       failed (grasp-demo --jobs 2: the nominal run's own process raised or died)
  2    a user error: a bad scenario file, parameter, bag or output directory
  130  interrupted (SIGINT, SIGTERM)
"""

ANALYZE_EPILOG = """\
A bag whose writer died without closing it (SIGKILL, the OOM killer, a power loss) has no
metadata.yaml and an unfinished mcap or sqlite3 file. grasp-analyze recovers such a bag in
place before analysing it and says so in one line (messages recovered, the last stamp):
the intact messages are rewritten to a new storage file with its metadata.yaml, which
replace the old file; what was lost is at most the writer's last {period:g} s of stamps.
--recover does only that, also for a bag with a metadata.yaml whose file cannot be read,
so that ros2 bag info and rosbags read it. A bag still being written by a live
grasp-demo or grasp-record is refused.

The bag records its scenario, not its scenario file: --config FILE (default: the paper's)
applies FILE's expected_outcome when the bag records FILE's scenario (duration, time step
and integrator aside), and FILE's hand groups the joints by finger in the figures when the
bag records its joint and contact names (else one group of every joint).

"""


def analyze_main(argv: list[str] | None = None) -> int:
    """``grasp-analyze BAG``: figures and summary.json of any recorded run of this package."""
    try:
        from grasp_safety_filter.io.interrupts import interrupt_on_signals

        with interrupt_on_signals():  # SIGTERM as SIGINT
            return _analyze(argv)
    except KeyboardInterrupt as interrupt:
        # Each output is written whole (temporary file + rename) and a recovery is staged:
        # what exists is complete, the original bag untouched.
        from grasp_safety_filter.io.interrupts import signal_name

        print(
            f'\ngrasp-analyze: interrupted by {signal_name(interrupt)}: outputs already '
            'written are complete, the others were not written; the bag is unchanged',
            file=sys.stderr,
        )
        return 130


def _analyze(argv: list[str] | None) -> int:
    from grasp_safety_filter.analysis.run_data import RunDataError
    from grasp_safety_filter.io.bag import BagReadError
    from grasp_safety_filter.io.bag_recovery import recover_bag
    from grasp_safety_filter.io.bag_storage import FLUSH_PERIOD_NS, needs_recovery
    from grasp_safety_filter.io.files import OutputError
    from grasp_safety_filter.output_dir import ANALYSIS_DIRECTORY, SUMMARY_FILE
    from grasp_safety_filter.runner import analyze_bag

    parser = argparse.ArgumentParser(
        prog='grasp-analyze',
        description=analyze_main.__doc__,
        epilog=ANALYZE_EPILOG.format(period=FLUSH_PERIOD_NS / 1e9) + VERDICT_EPILOG,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument('bag', type=Path, help='rosbag2 directory (mcap or sqlite3)')
    parser.add_argument(
        '--out',
        type=Path,
        help='output directory (default: next to the bag, or its analysis/ directory when '
        'a summary.json is already there, e.g. that of the grasp-demo run)',
    )
    parser.add_argument(
        '--force', action='store_true',
        help='write into OUT even if it holds files that are not a previous output',
    )  # fmt: skip
    parser.add_argument(
        '--config',
        type=Path,
        help='scenario file of the run: its expected outcome and hand (default: the paper '
        "scenario's, for a bag that records it; see below)",
    )
    parser.add_argument(
        '--recover',
        action='store_true',
        help='only make an incomplete bag readable (metadata.yaml, a repaired storage '
        'file); no analysis',
    )
    parser.add_argument(
        '--animate',
        action='store_true',
        help='also animation.gif: the grasp in space over the run, in real time',
    )
    args = parser.parse_args(argv)
    try:
        if args.recover or needs_recovery(args.bag):
            recovery = recover_bag(args.bag)
            if recovery is not None:
                print(f'grasp-analyze: {recovery.describe()}')
            elif args.recover:
                print(f'grasp-analyze: {args.bag}: complete, nothing to recover')
    except BagReadError as error:
        print(f'grasp-analyze: {error}', file=sys.stderr)
        return 2
    if args.recover:
        return 0
    out_dir = args.out
    if out_dir is None:
        out_dir = args.bag.resolve().parent
        if (out_dir / SUMMARY_FILE).exists() or (out_dir / SUMMARY_FILE).is_symlink():
            # The run's own summary (it may say "interrupted"): keep it.
            out_dir = out_dir / ANALYSIS_DIRECTORY
    try:
        scenario = _bag_scenario(args.bag, args.config)
    except ConfigError as error:
        print(config_error_line('grasp-analyze', error), file=sys.stderr)
        return EXIT_CONFIG_ERROR
    try:
        summary, figures = analyze_bag(
            args.bag,
            out_dir,
            force=args.force,
            fingers=scenario.fingers,
            model=scenario.model,
            animate=args.animate,
        )
    except (RunDataError, OutputError) as error:
        print(f'grasp-analyze: {error}', file=sys.stderr)
        return 2
    _, expected = print_summary(summary['mode'], summary, out_dir, scenario.expected_outcome)
    if scenario.note is not None:
        print(f'  {scenario.note}')
    print(f'  summary: {out_dir / SUMMARY_FILE}')
    for figure in figures:
        print(f'  figure: {figure}')
    return 1 if expected is not None and expected.met is False else 0


def _bag_scenario(bag: Path, config: Path | None) -> BagScenario:
    """Apply the scenario file (``--config``, else the paper's) to ``bag``.

    A bag whose scenario cannot be read gets nothing from it: the analysis then reports
    the bag's problem.
    """
    from grasp_safety_filter.analysis.bag_scenario import (
        bag_scenario,
        BagScenario,
        load_scenario_file,
    )
    from grasp_safety_filter.analysis.run_data import read_scenario, RunDataError
    from grasp_safety_filter.io.schemas import NO_OUTCOME

    try:
        recorded = read_scenario(bag)
    except RunDataError:
        return BagScenario(NO_OUTCOME, None)
    scenario_file = load_scenario_file(config_path() if config is None else config)
    return bag_scenario(recorded, scenario_file, given=config is not None)
