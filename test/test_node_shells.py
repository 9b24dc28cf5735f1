"""The rclpy node shells and launch files: structure checks always, spinning where rclpy is."""

from __future__ import annotations

import ast
from pathlib import Path
import py_compile
import subprocess
import sys
import textwrap
import time

import numpy as np
import pytest

from grasp_safety_filter.io import topics

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
PACKAGES = ('grasp_safety_filter', 'hand_sim_node')
LAUNCH_FILES = sorted((REPO / 'launch').glob('*.launch.py'))

#: The nodes' modules: ``ros2 run grasp_safety_filter <name>`` runs ``<module>.main``
#: (through ``grasp_safety_filter.nodes.entry_points``, see
#: test_console_scripts_are_the_entry_points_of_every_node).
CONSOLE_SCRIPTS = {
    'hand_sim_node': 'hand_sim_node.node:main',
    'nominal_controller_node': 'grasp_safety_filter.nodes.nominal_controller_node:main',
    'safety_filter_node': 'grasp_safety_filter.nodes.safety_filter_node:main',
    'grasp_markers_node': 'grasp_safety_filter.nodes.grasp_markers_node:main',
}


#: The message-level endpoints (and what they use): importable without ROS.
PURE_MODULES = (
    'grasp_safety_filter.nodes.outgoing',
    'grasp_safety_filter.nodes.scenario',
    'grasp_safety_filter.nodes.nominal_controller',
    'grasp_safety_filter.nodes.safety_filter',
    'grasp_safety_filter.nodes.grasp_markers',
    'hand_sim_node.endpoint',
    'hand_sim_node.hardware',
    'hand_sim_node.start_up',
)

ROS_PACKAGES = ('rclpy', 'launch', 'launch_ros', 'ament_index_python', 'std_msgs', 'sensor_msgs')


def module_path(module: str) -> Path:
    return REPO.joinpath(*module.split('.')).with_suffix('.py')


def python_files() -> list[Path]:
    return sorted(p for package in PACKAGES for p in (REPO / package).rglob('*.py'))


def is_shell(path: Path) -> bool:
    return path.name == 'node.py' or path.name.endswith('_node.py')


def imported_roots(path: Path) -> set[str]:
    """Top-level packages a module imports when it is imported (not inside functions)."""
    roots = set()
    for node in ast.parse(path.read_text(encoding='utf-8')).body:
        if isinstance(node, ast.Import):
            roots.update(alias.name.split('.')[0] for alias in node.names)
        elif isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
            roots.add(node.module.split('.')[0])
    return roots


def function(tree: ast.Module, name: str) -> ast.FunctionDef | None:
    for node in tree.body:
        if isinstance(node, ast.FunctionDef) and node.name == name:
            return node
    return None


# ----------------------------------------------------------------------------------------
# Always (no ROS needed)


@pytest.mark.parametrize(
    'path',
    [*(module_path(m.split(':')[0]) for m in CONSOLE_SCRIPTS.values()), *LAUNCH_FILES],
    ids=lambda p: p.name,
)
def test_node_modules_and_launch_files_compile(path, tmp_path):
    py_compile.compile(str(path), cfile=str(tmp_path / 'out.pyc'), doraise=True)


def test_launch_files_exist_and_define_generate_launch_description():
    assert {p.name for p in LAUNCH_FILES} >= {'paper_demo.launch.py', 'safety_filter.launch.py'}
    for path in LAUNCH_FILES:
        tree = ast.parse(path.read_text(encoding='utf-8'))
        generate = function(tree, 'generate_launch_description')
        assert generate is not None, path.name
        assert not generate.args.args, path.name


@pytest.mark.parametrize('name', list(CONSOLE_SCRIPTS))
def test_every_executable_has_a_main_taking_optional_args(name):
    module, _, entry = CONSOLE_SCRIPTS[name].partition(':')
    tree = ast.parse(module_path(module).read_text(encoding='utf-8'))
    main = function(tree, entry)
    assert main is not None
    assert [a.arg for a in main.args.args] == ['args']
    assert len(main.args.defaults) == 1
    assert isinstance(main.args.defaults[0], ast.Constant)
    assert main.args.defaults[0].value is None


def test_console_scripts_are_the_entry_points_of_every_node():
    from importlib.metadata import entry_points as installed_entry_points

    from grasp_safety_filter.nodes import entry_points

    assert entry_points.NODE_MODULES == {
        name: script.partition(':')[0] for name, script in CONSOLE_SCRIPTS.items()
    }
    installed = {ep.name: ep.value for ep in installed_entry_points(group='console_scripts')}
    for name in CONSOLE_SCRIPTS:
        assert installed[name] == f'grasp_safety_filter.nodes.entry_points:{name}'
        assert callable(getattr(entry_points, name))


def test_only_the_node_shells_import_rclpy_at_import_time():
    importers = {
        p.relative_to(REPO).as_posix() for p in python_files() if 'rclpy' in imported_roots(p)
    }
    assert importers, 'no module imports rclpy: the node shells are missing'
    assert {p for p in importers if not is_shell(REPO / p)} == set()
    for script in CONSOLE_SCRIPTS.values():
        assert is_shell(module_path(script.split(':')[0])), script


def test_endpoints_import_without_any_ros_package():
    """Import the pure modules in a fresh interpreter in which every ROS package is missing."""
    code = textwrap.dedent(
        f"""
        import importlib
        import sys

        class NoRos:
            def find_spec(self, name, path=None, target=None):
                if name.split('.')[0] in {ROS_PACKAGES!r}:
                    raise ImportError('ROS package imported: ' + name)
                return None

        sys.meta_path.insert(0, NoRos())
        for module in {PURE_MODULES!r}:
            importlib.import_module(module)
        print('ok')
        """
    )
    result = subprocess.run(
        [sys.executable, '-c', code], cwd=REPO, capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    assert result.stdout.strip() == 'ok'


def test_paper_demo_records_every_topic_of_the_table_as_mcap():
    from grasp_safety_filter.io.launch_arguments import recorder_command

    source = (REPO / 'launch' / 'paper_demo.launch.py').read_text(encoding='utf-8')
    constants = {
        node.value for node in ast.walk(ast.parse(source)) if isinstance(node, ast.Constant)
    }
    command = recorder_command('bag')
    assert command[:3] == ['ros2', 'bag', 'record'] and {'-s', 'mcap', '-o', '--topics'} <= set(
        command
    )
    assert command[command.index('--topics') + 1 :] == [spec.name for spec in topics.TOPICS]
    assert 'recorder_command(' in source
    assert {'filter', 'config', 'record', 'bag'} <= constants
    assert len(topics.TOPICS) == len({spec.name for spec in topics.TOPICS})


# ----------------------------------------------------------------------------------------
# With rclpy (a ROS 2 Jazzy install)


@pytest.fixture
def ros_context():
    import rclpy  # a test dependency: a missing rclpy fails here, it is not skipped
    context = rclpy.Context()
    rclpy.init(context=context)
    yield context
    rclpy.try_shutdown(context=context)


def make_nodes(context, duration, sim_parameters=()):
    from rclpy.parameter import Parameter

    from grasp_safety_filter.nodes.nominal_controller_node import NominalControllerNode
    from grasp_safety_filter.nodes.safety_filter_node import SafetyFilterNode
    from hand_sim_node.node import HandSimNode

    args = ['--ros-args', '--params-file', str(CONFIG)]
    sim_time = Parameter('use_sim_time', value=True)
    return (
        HandSimNode(
            context=context,
            cli_args=args,
            parameter_overrides=[
                sim_time,
                Parameter('duration', value=duration),
                *(Parameter(name, value=value) for name, value in sim_parameters),
            ],
        ),
        NominalControllerNode(context=context, cli_args=args, parameter_overrides=[sim_time]),
        SafetyFilterNode(context=context, cli_args=args, parameter_overrides=[sim_time]),
    )


def test_nodes_run_the_lockstep_loop_to_the_end(ros_context):
    from rclpy.executors import SingleThreadedExecutor

    sim, nominal, safety_filter = make_nodes(ros_context, duration=0.005)
    executor = SingleThreadedExecutor(context=ros_context)
    for node in (sim, nominal, safety_filter):
        executor.add_node(node)
    try:
        deadline = time.monotonic() + 60.0
        while not sim.endpoint.finished and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert sim.endpoint.finished
        assert sim.endpoint.stop_reason == 'duration'
        assert sim.endpoint.simulator.step_index == 5
        assert safety_filter.endpoint.hold.rejected_ticks == 0
        assert nominal.endpoint.last_output is not None
    finally:
        executor.shutdown()
        for node in (sim, nominal, safety_filter):
            node.destroy_node()


#: Code that records in ``loaded`` the name of each kernel numba loads from then on.
COUNT_KERNEL_LOADS = """
from numba.core.dispatcher import Dispatcher

loaded = []
load = Dispatcher._compile_for_args


def counted(self, *args, **kwargs):
    loaded.append(self.py_func.__name__)
    return load(self, *args, **kwargs)


Dispatcher._compile_for_args = counted
"""


#: Code that defines ``delivered(endpoint, t, q, dq, p_o, R_po, twist, u_nom)``: one tick's
#: joint state, odometry and nominal effort for the endpoint's hand, as rclpy delivers them.
DELIVER_TICK = """
from rclpy.serialization import deserialize_message, serialize_message

from grasp_safety_filter.io.messages import effort_to_msg, joint_state_to_msg, odometry_to_msg


def delivered(endpoint, t, q, dq, p_o, R_po, twist, u_nom):
    model, msgs = endpoint.model, endpoint.msgs
    names = list(model.joint_names)
    made = [
        joint_state_to_msg(msgs, t, names, q, dq, None),
        odometry_to_msg(msgs, t, p_o, R_po, twist, model.palm_frame, model.object_frame),
        effort_to_msg(msgs, t, names, u_nom),
    ]
    return [deserialize_message(serialize_message(m), type(m)) for m in made]
"""


def kernels_loaded(before: str, during: str) -> list[str]:
    """Run ``before`` then ``during`` in a fresh interpreter; the kernels loaded during it."""
    code = '\n'.join(
        (textwrap.dedent(before), COUNT_KERNEL_LOADS, textwrap.dedent(during), 'print(loaded)')
    )
    result = subprocess.run(
        [sys.executable, '-c', code], cwd=REPO, capture_output=True, text=True, check=False
    )
    assert result.returncode == 0, result.stderr
    return ast.literal_eval(result.stdout.strip().splitlines()[-1])


def test_the_simulator_node_loads_its_kernels_before_the_first_step():
    """Under load, numba loading kernels at the first step would stall the lockstep loop."""
    before = f"""
        import numpy as np
        import rclpy
        from rclpy.parameter import Parameter

        from grasp_safety_filter.io.messages import effort_to_msg
        from hand_sim_node.node import HandSimNode

        rclpy.init()
        node = HandSimNode(
            cli_args=['--ros-args', '--params-file', {str(CONFIG)!r}],
            parameter_overrides=[Parameter('use_sim_time', value=True)],
        )
        """
    first_step = """
        sim = node.endpoint
        sim.start()
        joints = list(sim.model.joint_names)
        sim.on_command(effort_to_msg(sim.msgs, sim.t, joints, np.zeros(len(joints))))
        assert sim.plant.step_index == 1
        """
    assert kernels_loaded(before, first_step) == []


#: The controller nodes: module, class, the inputs of a tick and more arguments.
CONTROLLER_NODES = {
    'nominal controller': (
        'grasp_safety_filter.nodes.nominal_controller_node',
        'NominalControllerNode',
        ('on_joint_states', 'on_odom'),
        (),
    ),
    'safety filter': (
        'grasp_safety_filter.nodes.safety_filter_node',
        'SafetyFilterNode',
        ('on_joint_states', 'on_odom', 'on_effort_nominal'),
        (),
    ),
    'safety filter switched off': (
        'grasp_safety_filter.nodes.safety_filter_node',
        'SafetyFilterNode',
        ('on_joint_states', 'on_odom', 'on_effort_nominal'),
        ('-p', 'enabled:=false'),
    ),
    # On a hand's streams the object's state is the estimator's: the tracker's sample first.
    "nominal controller on a hand's streams": (
        'grasp_safety_filter.nodes.nominal_controller_node',
        'NominalControllerNode',
        ('on_joint_states', 'on_odom'),
        ('-p', 'input.sync:=latest'),
    ),
    "safety filter on a hand's streams": (
        'grasp_safety_filter.nodes.safety_filter_node',
        'SafetyFilterNode',
        ('on_joint_states', 'on_odom', 'on_effort_nominal'),
        ('-p', 'input.sync:=latest'),
    ),
}


@pytest.mark.parametrize(
    'module, name, handlers, arguments', CONTROLLER_NODES.values(), ids=CONTROLLER_NODES
)
def test_a_controller_node_loads_its_kernels_before_its_first_tick(
    module, name, handlers, arguments
):
    """Under load, numba loading kernels at the first tick would stall the lockstep loop.

    The first tick is the paper's initial grasp, its messages as DDS delivers them
    (serialized and deserialized by rclpy).
    """
    before = DELIVER_TICK + textwrap.dedent(f"""
        import numpy as np
        import rclpy

        from grasp_safety_filter.io.schemas import load_node_parameters
        from grasp_safety_filter.model.quaternion import rotation_matrix
        from {module} import {name}

        rclpy.init()
        node = {name}(
            cli_args=['--ros-args', '--params-file', {str(CONFIG)!r}, *{arguments!r}]
        )
        initial = load_node_parameters({str(CONFIG)!r}, 'hand_sim_node')
        q = np.array(initial['initial.joint_positions'])
        R = rotation_matrix(np.array(initial['initial.object_orientation']))
        p = np.array(initial['initial.object_position'])
        zeros = np.zeros_like(q)
        messages = delivered(node.endpoint, 0.001, q, zeros, p, R, np.zeros(6), zeros)
        """)
    first_tick = f"""
        answers = []
        inputs = dict(zip({handlers!r}, messages))
        if 'on_odom' in inputs:  # the object's pose first: the estimator needs a sample
            answers += node.endpoint.on_odom(inputs.pop('on_odom'))
        for handler, msg in inputs.items():
            answers += getattr(node.endpoint, handler)(msg)
        assert any(a.topic != '/diagnostics' for a in answers), answers
        """
    assert kernels_loaded(before, first_tick) == []


def test_the_safety_filter_node_loads_the_kernels_of_its_rarer_ticks_before_its_first(
    tmp_path,
):
    """The first tick that changes the active set, or is relaxed, loads nothing either.

    The paper's filtered run to its first relaxed tick (2.26 s) is recorded here, in another
    process, and fed to a fresh node as DDS delivers messages: its active-set ticks (the
    first at 3 ms) and relaxed ticks took up to 23 ms when their steps loaded then.
    """
    from grasp_tools.bench.recorded_run import record_filtered_run, Scenario

    ticks, *_ = record_filtered_run(Scenario.load(CONFIG), 2.265)
    recorded = tmp_path / 'ticks.npz'
    fields = ('t', 'q', 'dq', 'p_object_in_palm', 'R_object_to_palm', 'twist_object', 'u_nom')
    np.savez(recorded, **{f: np.array([getattr(tick, f) for tick in ticks]) for f in fields})
    before = DELIVER_TICK + textwrap.dedent(f"""
        import numpy as np
        import rclpy

        from grasp_safety_filter.nodes.safety_filter_node import SafetyFilterNode

        rclpy.init()
        node = SafetyFilterNode(
            cli_args=['--ros-args', '--params-file', {str(CONFIG)!r}, '-p', 'use_sim_time:=true']
        )
        ticks = np.load({str(recorded)!r})
        every_tick_messages = [
            delivered(node.endpoint, *(ticks[f][k] for f in {fields!r}))
            for k in range(ticks['t'].size)
        ]
        statuses = set()
        """)
    every_tick = """
        endpoint = node.endpoint
        for joints, odometry, effort in every_tick_messages:
            endpoint.last_result = None
            endpoint.on_joint_states(joints)
            endpoint.on_odom(odometry)
            endpoint.on_effort_nominal(effort)
            statuses.add(endpoint.last_result.status.value)
        assert {'solved', 'relaxed'} <= statuses, statuses
        """
    assert kernels_loaded(before, every_tick) == []


def test_the_simulator_node_runs_the_mujoco_plant(ros_context):
    """plant:=mujoco: the node steps MuJoCo (with its -p mujoco.* options) in the same loop."""
    from rclpy.executors import SingleThreadedExecutor

    from hand_sim_node.mujoco_plant import MuJoCoPlant

    sim, nominal, safety_filter = make_nodes(
        ros_context,
        duration=0.005,
        sim_parameters=(('plant', 'mujoco'), ('mujoco.cone', 'elliptic')),
    )
    executor = SingleThreadedExecutor(context=ros_context)
    for node in (sim, nominal, safety_filter):
        executor.add_node(node)
    try:
        assert isinstance(sim.endpoint.plant, MuJoCoPlant)
        assert sim.endpoint.plant.options.cone == 'elliptic'
        assert 'cone="elliptic"' in sim.endpoint.plant.mjcf
        deadline = time.monotonic() + 60.0
        while not sim.endpoint.finished and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.1)
        assert sim.endpoint.stop_reason == 'duration'
        assert sim.endpoint.plant.step_index == 5
        assert safety_filter.endpoint.hold.rejected_ticks == 0
    finally:
        executor.shutdown()
        for node in (sim, nominal, safety_filter):
            node.destroy_node()


def test_live_parameters_apply_and_read_only_ones_are_refused(ros_context):
    from rclpy.parameter import Parameter

    sim, nominal, safety_filter = make_nodes(ros_context, duration=0.005)
    try:
        assert sim.set_parameters([Parameter('command_timeout', value=2.5)])[0].successful
        assert sim.endpoint.command_timeout == 2.5
        assert not sim.set_parameters([Parameter('time_step', value=0.002)])[0].successful
        assert not sim.set_parameters([Parameter('command_timeout', value=-1.0)])[0].successful
        assert nominal.set_parameters([Parameter('gains.kf', value=20.0)])[0].successful
        assert nominal.endpoint.config.kf == 20.0
        assert safety_filter.set_parameters([Parameter('enabled', value=False)])[0].successful
        assert not safety_filter.endpoint.enabled
        assert safety_filter.set_parameters([Parameter('input.hold_timeout', value=0.3)])[
            0
        ].successful
        assert safety_filter.endpoint.hold.hold_timeout == 0.3
    finally:
        for node in (sim, nominal, safety_filter):
            node.destroy_node()


#: How an extension module initialising itself may treat an exception raised inside it.
IMPORT_HANDLING = {
    'propagated': '    os.kill(os.getpid(), signal.SIGINT)\n    time.sleep(0.5)\n',
    'dropped': (
        'try:\n    os.kill(os.getpid(), signal.SIGINT)\n    time.sleep(0.5)\n'
        'except BaseException:\n    pass\n'
    ),
    # numpy's C core, interrupted while it imports datetime, reports an ImportError
    'converted': (
        'try:\n    os.kill(os.getpid(), signal.SIGINT)\n    time.sleep(0.5)\n'
        'except BaseException as error:\n    raise ImportError("C-extensions failed") from error\n'
    ),
}


@pytest.mark.parametrize('handling', list(IMPORT_HANDLING))
def test_a_signal_while_the_node_module_imports_ends_the_node_quietly(
    tmp_path, monkeypatch, handling
):
    """A signal during the import ends the process with 0 once it is done, never runs main."""
    import signal

    from grasp_safety_filter.nodes import entry_points

    name = f'interrupted_{handling}_node'
    body = IMPORT_HANDLING[handling]
    if handling == 'propagated':
        body = 'if True:\n' + body
    (tmp_path / f'{name}.py').write_text(
        f'import os, signal, time\n{body}STARTED = []\ndef main(args):\n    STARTED.append(args)\n'
    )
    monkeypatch.syspath_prepend(str(tmp_path))
    monkeypatch.setitem(entry_points.NODE_MODULES, name, name)
    previous = {s: signal.getsignal(s) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        with pytest.raises(SystemExit) as stop:
            entry_points.run_node(name, [name])
    finally:
        for s, handler in previous.items():
            signal.signal(s, handler)
    assert stop.value.code == 0
    assert sys.modules[name].STARTED == []
