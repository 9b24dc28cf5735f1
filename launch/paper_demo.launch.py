"""The paper's demo (Shaw-Cortez et al., CDC 2018, Section IV) as a ROS 2 graph.

Starts ``hand_sim_node``, ``nominal_controller_node`` and ``safety_filter_node`` with the
parameter file ``config`` and ``use_sim_time`` (the simulator publishes ``/clock``), and
optionally records every topic of the package's topic table with ``ros2 bag record``::

    ros2 launch grasp_safety_filter paper_demo.launch.py                 # filter on
    ros2 launch grasp_safety_filter paper_demo.launch.py filter:=false   # the nominal run
    ros2 launch grasp_safety_filter paper_demo.launch.py record:=true bag:=runs/filtered

Launch arguments:

- ``filter`` (``true``/``false``, default ``true``): with ``false`` the safety filter node
  passes u_nom through unchanged (parameter ``enabled``), so ``/hand/effort_command`` is
  the nominal command and the topics are the same in both runs.
- ``config``: the parameter file (default: the installed ``config/paper_scenario.yaml``).
- ``duration``: simulated time, s (default: the parameter file's).
- ``record`` (``true``/``false``, default ``false``): record every topic to ``bag`` (mcap)
  with ``ros2 bag record``, whose node ``rosbag2_recorder`` the simulator waits for
  (``start.wait_for_recorder``): the run starts once the recorder is subscribed to every
  topic, so the bag holds it from t = 0. Without a ``ros2`` executable the launch stops
  with a message instead of running without a bag.
- ``bag``: the bag directory to create (must not exist; default ``grasp_demo_bag``).
- ``viz`` (``true``/``false``, default ``false``): also start ``grasp_markers_node``, the
  grasp as markers on ``/grasp/markers`` (fixed frame: the palm frame), recorded with the rest.

The simulator exits when the run ends, which shuts the whole launch down (the recorder
closes the bag on SIGINT). What is started, with which parameters, is decided in
:mod:`grasp_safety_filter.io.launch_arguments`.
"""

from launch import LaunchDescription
from launch.actions import (
    DeclareLaunchArgument,
    ExecuteProcess,
    LogInfo,
    OpaqueFunction,
    Shutdown,
)
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from grasp_safety_filter.io.launch_arguments import (
    paper_demo,
    parse_bool,
    recorder_command,
    recorder_problem,
)
from grasp_safety_filter.io.paths import config_path


def _actions(context):
    def value(name):
        return LaunchConfiguration(name).perform(context)

    record = parse_bool('record', value('record'))
    problem = recorder_problem(record)
    if problem is not None:
        return [LogInfo(msg=problem), Shutdown(reason=problem)]
    duration = value('duration').strip()
    nodes = paper_demo(
        value('config'),
        filter_on=parse_bool('filter', value('filter')),
        record=record,
        duration=float(duration) if duration else None,
        viz=parse_bool('viz', value('viz')),
    )
    actions = []
    if record:
        actions.append(ExecuteProcess(cmd=recorder_command(value('bag')), output='screen'))
    for node in nodes:
        on_exit = Shutdown(reason=f'{node.name} exited') if node.ends_launch else None
        actions.append(Node(**node.node_kwargs(), on_exit=on_exit))
    return actions


def generate_launch_description():
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                'filter',
                default_value='true',
                choices=['true', 'false'],
                description='Run the safety filter (false: u* = u_nom, the nominal run)',
            ),
            DeclareLaunchArgument(
                'config', default_value=str(config_path()), description='ROS 2 parameter file'
            ),
            DeclareLaunchArgument(
                'duration',
                default_value='',
                description="Simulated time, s (empty: the parameter file's)",
            ),
            DeclareLaunchArgument(
                'record',
                default_value='false',
                choices=['true', 'false'],
                description='Record every topic with ros2 bag record (mcap)',
            ),
            DeclareLaunchArgument(
                'bag', default_value='grasp_demo_bag', description='Bag directory to create'
            ),
            DeclareLaunchArgument(
                'viz',
                default_value='false',
                choices=['true', 'false'],
                description='Start grasp_markers_node: the grasp on /grasp/markers (RViz)',
            ),
            OpaqueFunction(function=_actions),
        ]
    )
