"""The object-state estimator on true plant runs: the tables of docs/object_state_estimate.md.

Runs the paper's filtered scenario 3 s at 1 kHz on our rigid plant and on MuJoCo (elliptic
cone and 10 no-slip iterations: the grasp holds; MuJoCo's default contacts: the object creeps
on the fingertips, so the rolling constraint does not hold), samples the true object pose
with a synthetic tracker (rate, latency, Gaussian noise of std sigma per axis in position and
in the rotation vector, seeded) and runs, tick by tick, what a node would: the newest
delivered samples added, ``estimate`` at the tick's joint velocities, ``model.state`` at the
estimate, ``observe`` of that state. Prints median / p99 / max over 1–3 s of the position
error, orientation error and |penetration| of ``model.state`` at (a) the true pose, (b) the
newest tracker sample held to the tick, (c) the estimate; then how far the kinematics alone
drift.

Usage: ``python -m grasp_tools.object_estimate_study`` (``--tau 0.05 0.1 0.2`` adds a table of
the estimator at those correction times).
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from grasp_safety_filter.estimation.object_state import (
    ObjectEstimateConfig,
    ObjectStateEstimator,
    TrackerSample,
)
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.model.grasp_model import GraspModel
from grasp_tools.bench.recorded_run import Scenario
from grasp_tools.closed_loop import LoopRun
from hand_sim_node.mjcf import MjcfOptions
from hand_sim_node.mujoco_plant import MuJoCoPlant
from hand_sim_node.plant import RigidPlant
from hand_sim_node.simulator import SimState

CONFIG = config_path()
DURATION = 3.0
WARM_UP = 1.0  # s excluded from the statistics (the first samples are being averaged)
#: The plants: ours, MuJoCo with contacts that hold the grasp, MuJoCo's default contacts
#: (soft friction creeps: the object slides on the fingertips, the rolling constraint fails).
PLANTS = {
    'rigid': None,
    'MuJoCo, elliptic cone, 10 no-slip iterations': MjcfOptions(
        cone='elliptic', noslip_iterations=10
    ),
    'MuJoCo, default contacts (creeping)': MjcfOptions(),
}


@dataclass(frozen=True)
class Tracker:
    """A synthetic tracker: rate (Hz), latency range (s), noise std per axis (m, rad)."""

    rate: float
    latency: tuple[float, float]
    sigma_p: float
    sigma_theta: float
    seed: int = 0

    @property
    def label(self) -> str:
        """E.g. ``100 Hz, 10 ms, 0.5 mm / 0.5°``."""
        lo, hi = (round(1e3 * x) for x in self.latency)
        latency = f'{lo}' if lo == hi else f'{lo}–{hi}'
        return (
            f'{self.rate:g} Hz, {latency} ms, {1e3 * self.sigma_p:g} mm / '
            f'{np.degrees(self.sigma_theta):.2g}°'
        )


TRACKERS = (
    Tracker(100.0, (0.010, 0.010), 0.5e-3, np.radians(0.5)),
    Tracker(30.0, (0.030, 0.030), 1.0e-3, np.radians(0.5)),
    Tracker(30.0, (0.050, 0.050), 1.0e-3, np.radians(0.5)),
)


def tick_ns(run: LoopRun, period_ns: int) -> np.ndarray:
    """Integer stamps of the run's ticks (tick index × control period)."""
    return np.arange(len(run.ticks), dtype=np.int64) * period_ns


def tracker_samples(
    run: LoopRun, tracker: Tracker, period_ns: int
) -> list[tuple[int, TrackerSample]]:
    """``(arrival_ns, sample)`` of the tracker over the run, in arrival order."""
    rng = np.random.default_rng(tracker.seed)
    stamps = tick_ns(run, period_ns)
    step = round(1e9 / tracker.rate)
    samples = []
    for capture in range(0, int(stamps[-1]) + 1, step):
        k = round(capture / period_ns)  # the tick nearest the capture (1 ms grid)
        o = run.ticks[k].observation
        p = o.p_object_in_palm + rng.normal(0.0, tracker.sigma_p, 3)
        R = pin.exp3(rng.normal(0.0, tracker.sigma_theta, 3)) @ o.R_object_to_palm
        latency = round(1e9 * rng.uniform(*tracker.latency))
        samples.append((int(stamps[k]) + latency, TrackerSample(int(stamps[k]), p, R, None)))
    return sorted(samples, key=lambda item: item[0])


def errors(
    model: GraspModel, o: SimState, p: np.ndarray, R: np.ndarray
) -> tuple[float, float, float]:
    """Position error (m), orientation error (rad), max |penetration| (m) of a pose."""
    state = model.state(o.t, o.q, o.dq, p, R, o.twist_object)
    return (
        float(np.linalg.norm(p - o.p_object_in_palm)),
        float(np.linalg.norm(pin.log3(R @ o.R_object_to_palm.T))),
        float(np.abs(state.penetration).max()),
    )


def replay(
    model: GraspModel,
    run: LoopRun,
    tracker: Tracker,
    config: ObjectEstimateConfig,
    period_ns: int,
) -> dict[str, np.ndarray]:
    """Run the estimator over the run; errors per tick (after the warm-up) of each source."""
    estimator = ObjectStateEstimator(config)
    samples = tracker_samples(run, tracker, period_ns)
    stamps = tick_ns(run, period_ns)
    rows: dict[str, list] = {'true pose': [], 'raw tracker held': [], 'estimator': []}
    delivered = 0
    newest = None
    for stamp, tick in zip(stamps, run.ticks, strict=True):
        o = tick.observation
        while delivered < len(samples) and samples[delivered][0] <= stamp:
            newest = samples[delivered][1]
            estimator.add_tracker_sample(newest)
            delivered += 1
        estimate = estimator.estimate(int(stamp), o.dq)
        if estimate is None:
            continue
        state = model.state(
            o.t,
            o.q,
            o.dq,
            estimate.p_object_in_palm,
            estimate.R_object_to_palm,
            estimate.twist_object,
        )
        estimator.observe(state)
        if stamp < WARM_UP * 1e9:
            continue
        rows['true pose'].append(errors(model, o, o.p_object_in_palm, o.R_object_to_palm))
        rows['raw tracker held'].append(
            errors(model, o, newest.p_object_in_palm, newest.R_object_to_palm)
        )
        rows['estimator'].append(
            (
                float(np.linalg.norm(estimate.p_object_in_palm - o.p_object_in_palm)),
                float(np.linalg.norm(pin.log3(estimate.R_object_to_palm @ o.R_object_to_palm.T))),
                float(np.abs(state.penetration).max()),
            )
        )
    return {name: np.array(values) for name, values in rows.items()}


def true_runs(scenario: Scenario) -> dict[str, LoopRun]:
    """Run the paper's filtered scenario on each plant."""
    runs = {}
    for name, options in PLANTS.items():
        if options is None:
            plant = RigidPlant(scenario.model, scenario.sim_config)
        else:
            plant = MuJoCoPlant(scenario.model, scenario.sim_config, options=options)
        run = scenario.run_on(plant, filtered=True, duration=DURATION)
        if run.stop_reason != 'duration':
            raise RuntimeError(f'{name} run stopped early: {run.stop_reason}')
        runs[name] = run
    return runs


def kinematic_drift(model: GraspModel, run: LoopRun, period_ns: int) -> list[float]:
    """Twist error of the kinematics and the drift of its integral, never corrected.

    The estimator is given the true pose and twist once, at the start, and no sample after.
    Returns p99 / max of the linear (mm/s) and angular (deg/s) twist error, and the
    position (mm) and orientation (deg) errors at 1 s and at the end.
    """
    first = run.ticks[0].observation
    estimator = ObjectStateEstimator(ObjectEstimateConfig())
    estimator.add_tracker_sample(
        TrackerSample(0, first.p_object_in_palm, first.R_object_to_palm, first.twist_object)
    )
    twist_errors, pose_errors = [], []
    for stamp, tick in zip(tick_ns(run, period_ns), run.ticks, strict=True):
        o = tick.observation
        estimate = estimator.estimate(int(stamp), o.dq)
        estimator.observe(
            model.state(
                o.t,
                o.q,
                o.dq,
                estimate.p_object_in_palm,
                estimate.R_object_to_palm,
                estimate.twist_object,
            )
        )
        error = estimate.twist_object - o.twist_object
        twist_errors.append((np.linalg.norm(error[:3]), np.linalg.norm(error[3:])))
        pose_errors.append(
            errors(model, o, estimate.p_object_in_palm, estimate.R_object_to_palm)[:2]
        )
    twist = np.array(twist_errors) * [1e3, np.degrees(1.0)]
    pose = np.array(pose_errors) * [1e3, np.degrees(1.0)]
    at_1s = round(1e9 / period_ns)
    return [
        *np.percentile(twist[:, 0], [99, 100]),
        *np.percentile(twist[:, 1], [99, 100]),
        *pose[at_1s],
        *pose[-1],
    ]


def row(label: str, values: np.ndarray) -> str:
    """One table row: median / p99 / max of mm, deg, mm."""
    scale = np.array([1e3, np.degrees(1.0), 1e3])
    stats = np.percentile(values * scale, [50, 99, 100], axis=0).T
    cells = [' / '.join(f'{x:.2f}' for x in column) for column in stats]
    return f'| {label} | ' + ' | '.join(cells) + ' |'


def main(argv: list[str] | None = None) -> int:
    """Print the tables."""
    parser = argparse.ArgumentParser(
        prog='python -m grasp_tools.object_estimate_study', description=__doc__.splitlines()[0]
    )
    parser.add_argument(
        '--tau', type=float, nargs='*', default=[], help='correction times to compare (s)'
    )
    args = parser.parse_args(argv)
    scenario = Scenario.load(CONFIG)
    period_ns = round(scenario.sim_config.time_step * 1e9)
    runs = true_runs(scenario)
    default = ObjectEstimateConfig()
    print(
        f"Median / p99 / max over {WARM_UP:g}–{DURATION:g} s of the paper's filtered run, "
        f'1 kHz; estimator with tau = {default.correction_time:g} s; tracker: rate, latency, '
        'noise std per axis (position / rotation vector)\n'
    )
    print(
        '| plant; tracker / source | position error, mm | orientation error, deg '
        '| abs(penetration), mm |'
    )
    print('|---|---|---|---|')
    for plant, run in runs.items():
        for tracker in TRACKERS:
            print(f'| **{plant}; {tracker.label}** | | | |')
            result = replay(scenario.model, run, tracker, default, period_ns)
            for name, values in result.items():
                print(row(name, values))
    print(
        '\nKinematics alone (true pose at t = 0, never corrected): twist error p99 / max, '
        'pose error at 1 s and at the end\n'
    )
    print(
        f'| plant | linear, mm/s | angular, deg/s | at 1 s: mm, deg | at {DURATION:g} s: mm, deg |'
    )
    print('|---|---|---|---|---|')
    for plant, run in runs.items():
        d = kinematic_drift(scenario.model, run, period_ns)
        print(
            f'| {plant} | {d[0]:.3f} / {d[1]:.3f} | {d[2]:.3f} / {d[3]:.3f} '
            f'| {d[4]:.3f}, {d[5]:.3f} | {d[6]:.3f}, {d[7]:.3f} |'
        )
    if args.tau:
        print('\nEstimator at other tau: p99 position error / p99 abs(penetration), mm\n')
        print('| plant; tracker | ' + ' | '.join(f'tau {tau:g} s' for tau in args.tau) + ' |')
        print('|---|' + '---|' * len(args.tau))
        for plant, run in runs.items():
            for tracker in TRACKERS:
                cells = []
                for tau in args.tau:
                    config = ObjectEstimateConfig(correction_time=tau)
                    values = replay(scenario.model, run, tracker, config, period_ns)['estimator']
                    p99 = np.percentile(values, 99, axis=0) * 1e3
                    cells.append(f'{p99[0]:.2f} / {p99[2]:.2f}')
                print(f'| {plant}; {tracker.label} | ' + ' | '.join(cells) + ' |')
    return 0


if __name__ == '__main__':
    raise SystemExit(main())
