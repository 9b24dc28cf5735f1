"""grasp-bench: the document's structure, the solver comparison, skipping missing solvers.

No timing is asserted (the machine is shared); only structure, consistency and the
agreement of the independent solvers with the filter's u*.
"""

import contextlib
import importlib.util
import io
import json
import math
import sys
from types import SimpleNamespace

import numpy as np
import pytest

from grasp_safety_filter.control.filter_result import FilterStatus
from grasp_safety_filter.control.qp_solvers import BACKENDS
from grasp_safety_filter.io.messages import MessageNamespace
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.runner import _subscribers, build_endpoints, RunOptions
from grasp_tools.bench import (
    bench_main,
    CALLBACKS_LABEL,
    COMPONENTS,
    CPU_COMPONENTS,
    DenseQP,
    EXTERNAL_SOLVERS,
    external_solvers,
    ExternalAnswer,
    ExternalSolver,
    FilterCallbackTimes,
    fixed_work,
    format_report,
    general_form,
    replay_backends,
    replay_hands,
    run_external,
    Scenario,
)

DURATION = 0.05  # s: 50 ticks of 1 ms
TICKS = 40
EXTERNAL_TICKS = 12
RUNNER_DURATION = 0.01  # s

#: Solvers accurate enough to check our u* against: Clarabel with tight tolerances (an
#: interior-point method at its default gap is only accurate to ~1e-4 N·m here) and daqp.
ACCURATE = {'cvxpy_clarabel', 'daqp'}


def installed(key):
    """Whether the bench's external solver ``key`` can run here."""
    if key.startswith('cvxpy'):
        if importlib.util.find_spec('cvxpy') is None:
            return False
        import cvxpy

        needed = {'cvxpy': None, 'cvxpy_osqp': 'OSQP', 'cvxpy_clarabel': 'CLARABEL'}[key]
        return needed is None or needed in cvxpy.installed_solvers()
    if importlib.util.find_spec('qpsolvers') is None:
        return False
    import qpsolvers

    return 'daqp' in qpsolvers.available_solvers


@pytest.fixture(scope='module')
def bench(tmp_path_factory):
    path = tmp_path_factory.mktemp('bench') / 'bench.json'
    table = io.StringIO()
    with contextlib.redirect_stdout(table), contextlib.redirect_stderr(io.StringIO()):
        rc = bench_main(
            [
                '--duration',
                str(DURATION),
                '--ticks',
                str(TICKS),
                '--warmup',
                '5',
                '--external-ticks',
                str(EXTERNAL_TICKS),
                '--runner-duration',
                str(RUNNER_DURATION),
                '--compare-config',
                str(config_path('four_finger_box.yaml')),
                '--json',
                str(path),
            ]
        )
    return rc, json.loads(path.read_text()), table.getvalue()


def test_bench_exits_zero_and_prints_every_figure(bench):
    rc, document, table = bench
    assert rc == 0
    for label in COMPONENTS.values():
        assert label in table
    for _, label, _ in EXTERNAL_SOLVERS:
        assert label in table
    assert 'real-time factor' in table
    assert f'{document["machine"]["cpu_count"]} CPUs' in table


def test_document_describes_machine_and_run(bench):
    _, document, _ = bench
    machine = document['machine']
    assert machine['python'] == '.'.join(map(str, sys.version_info[:3]))
    assert machine['cpu_count'] >= 1
    assert machine['packages']['numpy'] == np.__version__
    assert machine['packages']['osqp']
    run = document['run']
    assert run['ticks'] == round(DURATION / run['time_step_s'])
    assert run['t_end_s'] == pytest.approx(DURATION)
    assert run['stop_reason'] == 'duration'
    assert sum(run['statuses'].values()) == run['ticks']
    replay = document['replay']
    assert replay['ticks'] == TICKS
    assert sum(replay['statuses'].values()) == TICKS
    # Fresh instances fed the same ticks reproduce the run's u* (warm starts included).
    assert replay['max_deviation_from_run'] <= 1e-12


def test_timings_have_median_and_p99_per_piece(bench):
    _, document, _ = bench
    timings = document['timings_us']
    assert list(timings) == list(COMPONENTS)
    nominal_ticks = document['replay']['statuses'].get('nominal', 0)
    for key, s in timings.items():
        expected = TICKS - nominal_ticks if key == 'filter_qp_solve' else TICKS
        assert s['n'] == expected, key
        assert 0.0 < s['median'] <= s['p99'] <= s['max'], key
    by_status = document['replay']['filter_step_us_by_status']
    assert {k: v['n'] for k, v in by_status.items()} == document['replay']['statuses']
    assert min(v['median'] for v in by_status.values()) <= timings['filter_step']['median']
    assert max(v['median'] for v in by_status.values()) >= timings['filter_step']['median']
    # The node tick is timed as one block around the model terms and the filter step.
    assert timings['node_tick']['median'] >= timings['filter_step']['median']
    assert timings['node_tick']['median'] >= timings['model_state']['median']


def test_cpu_times_are_reported_next_to_wall_times(bench):
    _, document, table = bench
    cpu = document['cpu_timings_us']
    assert list(cpu) == list(CPU_COMPONENTS)
    for key, s in cpu.items():
        assert s['n'] == TICKS, key
        assert 0.0 < s['median'] <= s['p99'] <= s['max'], key
    # Thread CPU time cannot exceed the wall time that brackets it, tick by tick; medians
    # keep that order up to the CPU clock's own reads.
    assert cpu['node_tick']['median'] <= document['timings_us']['node_tick']['max']
    by_status = document['replay']['node_tick_cpu_us_by_status']
    assert {k: v['n'] for k, v in by_status.items()} == document['replay']['statuses']
    assert 'CPU median' in table and 'node tick by status (thread CPU' in table
    step_cpu = document['real_time_factor']['filtered_loop']['simulator_step_cpu_us']
    step_wall = document['real_time_factor']['filtered_loop']['simulator_step_us']
    assert step_cpu['n'] == step_wall['n'] > 0
    assert 0.0 < step_cpu['median'] <= step_cpu['p99'] <= step_cpu['max']
    assert step_cpu['median'] <= step_wall['max']  # as the node tick's, up to the clock reads
    assert f'simulator step (ode3): CPU median {step_cpu["median"]:,.1f} µs' in table


def test_every_qp_backend_replays_the_same_ticks_and_agrees(bench):
    _, document, table = bench
    backends = document['backends']
    assert list(backends) == list(BACKENDS)
    for backend, entry in backends.items():
        assert sum(entry['statuses'].values()) == TICKS, backend
        for key in ('node_tick_cpu_us', 'node_tick_wall_us'):
            assert entry[key]['n'] == TICKS and entry[key]['median'] > 0.0, (backend, key)
        assert entry['max_abs_du_vs_first'] <= 1e-8, backend
        assert entry['compared_ticks'] >= TICKS // 2, backend
        # The QP solve is part of the node tick that brackets it, tick by tick.
        solve = entry['qp_solve_wall_us']
        assert 0 < solve['n'] <= TICKS and 0.0 < solve['median'] <= solve['max'], backend
        assert solve['max'] <= entry['node_tick_wall_us']['max'], backend
        assert entry['node_tick_over_qp_solve'] > 1.0, backend
        assert backend in table
    assert backends[next(iter(BACKENDS))]['max_abs_du_vs_first'] == 0.0


def test_other_hands_are_timed_on_as_many_ticks_in_the_same_run(bench):
    _, document, table = bench
    section = document['hands']
    first, other = section['hands']
    assert first['config'] == str(config_path())
    assert other['config'].endswith('four_finger_box.yaml')
    assert [(hand['joints'], hand['contacts']) for hand in (first, other)] == [(9, 3), (16, 4)]
    for hand in (first, other):
        assert sum(hand['statuses'].values()) == TICKS
        for key in ('node_tick_cpu_us', 'node_tick_wall_us'):
            assert hand[key]['n'] == TICKS and positive_spread(hand[key]), key
        assert hand['cpu_median_over_first'] == pytest.approx(
            hand['node_tick_cpu_us']['median'] / first['node_tick_cpu_us']['median']
        )
        assert f'{hand["cpu_median_over_first"]:.2f}x' in table
        parts = hand['parts_us']
        cpu_parts = ['pinocchio_cpu', 'model_terms_cpu', 'filter_step_cpu']
        assert list(parts) == [*cpu_parts, 'qp_solve_wall']
        for name in cpu_parts:
            assert parts[name]['n'] == TICKS and positive_spread(parts[name]), name
        # Every tick but a nominal one solves a QP here (no fallback in these ticks).
        nominal = hand['statuses'].get(FilterStatus.NOMINAL.value, 0)
        assert parts['qp_solve_wall']['n'] == TICKS - nominal > 0
        for name, figures in parts.items():
            assert figures['over_first'] == pytest.approx(
                figures['median'] / first['parts_us'][name]['median']
            ), name
            assert f'{figures["median"]:.1f} ({figures["over_first"]:.2f}x)' in table, name
    assert 'four_finger_box.yaml' in table


def test_hands_take_turns_block_by_block(monkeypatch):
    """Blocks of each hand's ticks alternate, the first hand of a block rotating."""
    import grasp_tools.bench.hands as hands_module

    calls = []

    class Filter:
        def __init__(self, name):
            self.name = name

        def solve(self, state, u_nom):
            calls.append((self.name, state))
            return SimpleNamespace(status=FilterStatus.SOLVED, solve_time=float(state))

    def hand(name, count):
        scenario = SimpleNamespace(
            model=SimpleNamespace(name=name, n_joints=1, n_contacts=1),
            safety_filter=lambda: Filter(name),
        )
        return name, scenario, [SimpleNamespace(index=i, u_nom=None) for i in range(count)]

    def pinocchio_terms(model, tick):
        calls.append(('pinocchio', model.name, tick.index))

    monkeypatch.setattr(hands_module, 'state_of', lambda model, tick: tick.index)
    monkeypatch.setattr(hands_module, 'pinocchio_terms', pinocchio_terms)
    replays = replay_hands([hand('a', 5), hand('b', 4)], block=2, warmup=1)
    assert calls == [
        ('a', 0), ('b', 0),  # warm-up
        ('a', 0), ('a', 1), ('b', 0), ('b', 1),
        ('b', 2), ('b', 3), ('a', 2), ('a', 3),
        # Pinocchio's calls afterwards, in the node ticks' order.
        ('pinocchio', 'a', 0), ('pinocchio', 'a', 1), ('pinocchio', 'b', 0), ('pinocchio', 'b', 1),
        ('pinocchio', 'b', 2), ('pinocchio', 'b', 3), ('pinocchio', 'a', 2), ('pinocchio', 'a', 3),
    ]
    assert [r.cpu.size for r in replays] == [4, 4] and replays[1].statuses == {'solved': 4}
    for replay in replays:
        np.testing.assert_array_equal(replay.solve, [0.0, 1.0, 2.0, 3.0])  # each tick's own
        np.testing.assert_allclose(replay.model_cpu + replay.filter_cpu, replay.cpu)
    with pytest.raises(ValueError, match='block: expected >= 1'):
        replay_hands([hand('a', 1)], block=0)
    with pytest.raises(ValueError, match='at least one tick'):
        replay_hands([hand('a', 1), hand('b', 0)])


def test_replay_backends_refuses_an_unknown_backend():
    with pytest.raises(ValueError, match='backends: expected one or more of'):
        replay_backends(Scenario.load(config_path('paper_scenario.yaml')), [], ['gurobi'])


def test_real_time_factors_are_simulated_over_wall_seconds(bench):
    _, document, _ = bench
    rates = document['real_time_factor']
    for key in ('nominal_loop', 'filtered_loop', 'runner_with_bag'):
        rate = rates[key]
        assert rate['simulated_s'] > 0.0 and rate['wall_s'] > 0.0, key
        assert rate['real_time_factor'] == pytest.approx(rate['simulated_s'] / rate['wall_s'])
    assert rates['filtered_loop']['simulated_s'] == pytest.approx(DURATION)
    assert rates['runner_with_bag']['simulated_s'] == pytest.approx(RUNNER_DURATION)


def positive_spread(stats):
    """Whether ``stats`` has a finite positive median and a finite p99 at least the median."""
    median, p99 = stats['median'], stats['p99']
    return math.isfinite(median) and math.isfinite(p99) and 0.0 < median <= p99


def test_noise_floor_times_the_same_work_once_per_replayed_tick(bench):
    _, document, table = bench
    floor = document['noise_floor']
    assert floor['iterations'] >= 1
    assert floor['cpu_us']['n'] == TICKS
    assert positive_spread(floor['cpu_us'])
    assert floor['p99_over_median'] == pytest.approx(
        floor['cpu_us']['p99'] / floor['cpu_us']['median']
    )
    line = next(line for line in table.splitlines() if 'noise floor' in line)
    assert f'CPU median {floor["cpu_us"]["median"]:,.1f} µs' in line
    assert f'p99/median {floor["p99_over_median"]:.2f}' in line
    # Printed right after the per-tick table, whose last rows are the node's.
    lines = table.splitlines()
    assert lines.index(line) == lines.index(next(x for x in lines if CALLBACKS_LABEL in x)) + 1


def test_fixed_work_is_deterministic():
    assert fixed_work(1000) == fixed_work(1000)
    assert fixed_work(0) == 0.5
    assert fixed_work(1) == pytest.approx(3.9 * 0.5 * 0.5)


def test_filter_node_callbacks_are_timed_per_tick_in_the_runner_run(bench):
    _, document, table = bench
    callbacks = document['filter_node_callbacks_cpu_us']
    # One tick per simulator state, the start's included, each with its three callbacks.
    assert callbacks['n'] == document['real_time_factor']['runner_with_bag']['steps'] + 1
    assert positive_spread(callbacks)
    row = next(line for line in table.splitlines() if line.startswith(CALLBACKS_LABEL))
    assert f'{callbacks["median"]:,.1f}' in row and f'{callbacks["n"]:d}' in row


def test_the_runner_hands_exactly_the_filters_callbacks_to_the_wrapper():
    from rosbags.typesys import get_typestore, Stores

    msgs = MessageNamespace.from_typestore(get_typestore(Stores.ROS2_JAZZY))
    sim, nominal, safety_filter = build_endpoints(RunOptions(config_path()), msgs)
    wrapped = []

    def wrap(callback):
        wrapped.append(callback)
        return lambda msg: ['wrapped', msg]

    subscribers = _subscribers(sim, nominal, safety_filter, wrap)
    assert wrapped == [
        safety_filter.on_joint_states,
        safety_filter.on_odom,
        safety_filter.on_effort_nominal,
    ]
    unwrapped = _subscribers(sim, nominal, safety_filter)
    for topic, callbacks in subscribers.items():
        for callback, original in zip(callbacks, unwrapped[topic], strict=True):
            if original in wrapped:
                assert callback('m') == ['wrapped', 'm']
            else:
                assert callback == original


def test_callback_times_pass_messages_through_and_sum_complete_ticks():
    times = FilterCallbackTimes()
    outgoing = {name: [object()] for name in ('joint_states', 'odom', 'effort_nominal')}
    callbacks = {name: times.wrap(lambda msg, name=name: outgoing[name]) for name in outgoing}

    def message(sec, nanosec):
        return SimpleNamespace(
            header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec))
        )

    for stamp in ((0, 0), (0, 1_000_000)):
        for name, callback in callbacks.items():
            assert callback(message(*stamp)) is outgoing[name]
    callbacks['joint_states'](message(0, 2_000_000))  # a tick whose other inputs never came
    per_tick = times.per_tick()
    assert per_tick.shape == (2,)
    assert np.all(per_tick >= 0.0)


@pytest.mark.parametrize('key', [key for key, _, _ in EXTERNAL_SOLVERS])
def test_external_solvers_agree_with_the_filter(bench, key):
    _, document, _ = bench
    external = document['external']
    entry = external['solvers'][key]
    assert entry['available'] == installed(key)
    if not entry['available']:
        assert 'not installed' in entry['reason']
        return
    assert entry['qps'] == external['qps'] == len(external['ticks']) == EXTERNAL_TICKS
    assert sum(entry['statuses'].values()) == entry['qps']
    assert entry['time_us']['n'] == entry['qps']
    assert entry['ratio_to_filter_step']['median'] == pytest.approx(
        entry['time_us']['median'] / external['filter_step_us']['median']
    )
    # Early in the run every hard QP is feasible and each solver returns a solution.
    assert entry['infeasible'] == 0
    assert entry['missing'] == 0
    assert entry['compared'] == entry['qps']
    if key in ACCURATE:
        assert entry['max_abs_du'] <= 1e-5
    else:
        # OSQP through cvxpy stops at its own tolerances: reported, not held to 1e-5.
        assert np.isfinite(entry['max_abs_du'])


def test_json_to_stdout_with_a_filter_override():
    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        rc = bench_main(
            [
                '--duration',
                '0.01',
                '--warmup',
                '0',
                '--external-ticks',
                '0',
                '--runner-duration',
                '0',
                '--set',
                'osqp.eps_abs=1e-3',
                '--json',
            ]
        )
    assert rc == 0
    document = json.loads(out.getvalue())  # stdout holds the JSON only
    assert document['filter_parameters']['osqp.eps_abs'] == 1e-3
    assert document['external']['qps'] == 0
    assert document['real_time_factor']['runner_with_bag'] is None
    assert document['filter_node_callbacks_cpu_us'] is None
    assert positive_spread(document['noise_floor']['cpu_us'])
    table = err.getvalue()
    row = next(line for line in table.splitlines() if line.startswith(CALLBACKS_LABEL))
    assert row.endswith('not measured (runner not run)')


def test_a_model_override_reaches_every_part(monkeypatch):
    """``--set model.*`` builds the model with it (filter and simulator share one model)."""
    loaded = []
    original = Scenario.load.__func__

    def spy(cls, config, filter_overrides=None, plant_overrides=None):
        loaded.append(original(cls, config, filter_overrides, plant_overrides))
        return loaded[-1]

    monkeypatch.setattr(Scenario, 'load', classmethod(spy))
    out = io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(io.StringIO()):
        rc = bench_main(
            '--duration 0.01 --warmup 0 --external-ticks 0 --runner-duration 0 --backends= '
            '--set model.torsional_friction=0.005 --set osqp.eps_abs=1e-3 --json'.split()
        )
    assert rc == 0
    document = json.loads(out.getvalue())
    assert document['model_overrides'] == {'model.torsional_friction': 0.005}
    assert document['filter_parameters']['osqp.eps_abs'] == 1e-3
    assert loaded and all(scenario.model.soft_finger for scenario in loaded)


def test_unknown_filter_override_is_refused():
    with pytest.raises(ValueError, match=r'osqp\.eps_absolute'):
        Scenario.load(config_path(), {'osqp.eps_absolute': 1e-3})


def test_missing_solvers_are_skipped_with_a_reason(monkeypatch, bench):
    for module in ('cvxpy', 'qpsolvers'):
        monkeypatch.setitem(sys.modules, module, None)  # import now raises ImportError
    solvers = external_solvers()
    assert [s.key for s in solvers] == [key for key, _, _ in EXTERNAL_SOLVERS]
    for solver in solvers:
        assert solver.solve is None
        assert 'not installed' in solver.unavailable
    _, document, _ = bench
    for solver in solvers:
        document['external']['solvers'][solver.key] = {
            'label': solver.label,
            'available': False,
            'reason': solver.unavailable,
        }
    assert format_report(document).count('skipped: not installed') == len(solvers)


def random_qp(rng, k=6, m=4):
    A = rng.normal(size=(k, m))
    C = np.vstack((A, np.eye(m)))
    lower = np.concatenate((rng.normal(size=k), np.full(m, -1.0)))
    upper = np.concatenate((np.full(k, np.inf), np.full(m, 2.0)))
    upper[0] = lower[0] + 1.0  # one two-sided general row
    return DenseQP(np.eye(m), rng.normal(size=m), C, lower, upper)


def test_general_form_describes_the_same_feasible_set():
    rng = np.random.default_rng(3)
    qp = random_qp(rng)
    form = general_form(qp)
    np.testing.assert_array_equal(form.lb, -1.0)
    np.testing.assert_array_equal(form.ub, 2.0)
    assert form.G.shape == (6 + 1, 4)  # k lower sides and one upper side
    for x in rng.uniform(-3.0, 3.0, size=(2000, 4)):
        inside = np.all(qp.lower <= qp.C @ x) and np.all(qp.C @ x <= qp.upper)
        general = np.all(form.G @ x <= form.h) and np.all(form.lb <= x) and np.all(x <= form.ub)
        assert inside == general


def test_run_external_counts_agreement_misses_and_infeasibility():
    rng = np.random.default_rng(4)
    qps = [random_qp(rng) for _ in range(4)]
    ours = rng.normal(size=(4, 4))
    answers = [ours[0] + 1e-3, None, None, ours[3] - 2e-3]

    def fake(qp):
        index = next(i for i, other in enumerate(qps) if np.array_equal(other.q, qp.q))
        x = answers[index]
        return ExternalAnswer(x, 'solved' if x is not None else 'infeasible', 'fake', 1e-6)

    times, comparison = run_external(
        ExternalSolver('fake', 'fake', fake),
        qps,
        ours,
        certified=np.array([True, True, False, True]),
    )
    assert times.shape == (4,)
    assert comparison['compared'] == 2
    assert comparison['max_abs_du'] == pytest.approx(2e-3)
    assert comparison['missing'] == 1
    assert comparison['infeasible'] == 1
    assert comparison['infeasible_agreed'] == 1
    assert comparison['statuses'] == {'solved': 2, 'infeasible': 2}
    assert comparison['solver_time_us']['median'] == pytest.approx(1.0)
