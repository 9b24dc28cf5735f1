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
- ``record`` (``true``/``false``, default ``false``): record every topic to ``bag`` (mcap).
  The simulator then starts 3 s after the recorder, which needs that long to discover and
  subscribe to the topics; ``/grasp/scenario`` is latched, so it is recorded regardless.
- ``bag``: the bag directory to create (must not exist; default ``grasp_demo_bag``).

The simulator exits when the run ends, which shuts the whole launch down (the recorder
closes the bag on SIGINT).
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, ExecuteProcess, Shutdown, TimerAction
from launch.conditions import IfCondition
from launch.substitutions import LaunchConfiguration, PythonExpression
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.topics import TOPICS

PACKAGE = 'grasp_safety_filter'

#: Seconds between the recorder's start and the simulator's, when recording.
RECORDER_WARM_UP = 3.0


def generate_launch_description():
    default_config = str(config_path())
    filter_on = LaunchConfiguration('filter')
    config = LaunchConfiguration('config')
    record = LaunchConfiguration('record')
    bag = LaunchConfiguration('bag')
    sim_time = {'use_sim_time': True}

    hand_sim = Node(
        package=PACKAGE,
        executable='hand_sim_node',
        name='hand_sim_node',
        parameters=[config, sim_time],
        output='screen',
        on_exit=Shutdown(reason='the simulation ended'),
    )
    nominal_controller = Node(
        package=PACKAGE,
        executable='nominal_controller_node',
        name='nominal_controller_node',
        parameters=[config, sim_time],
        output='screen',
    )
    safety_filter = Node(
        package=PACKAGE,
        executable='safety_filter_node',
        name='safety_filter_node',
        parameters=[config, sim_time, {'enabled': ParameterValue(filter_on, value_type=bool)}],
        output='screen',
    )
    recorder = ExecuteProcess(
        cmd=['ros2', 'bag', 'record', '-s', 'mcap', '-o', bag, '--topics']
        + [spec.name for spec in TOPICS],
        condition=IfCondition(record),
        output='screen',
    )
    start_delay = PythonExpression(
        [f'{RECORDER_WARM_UP} if "', record, '".lower() == "true" else 0.0']
    )
    return LaunchDescription(
        [
            DeclareLaunchArgument(
                'filter',
                default_value='true',
                choices=['true', 'false'],
                description='Run the safety filter (false: u* = u_nom, the nominal run)',
            ),
            DeclareLaunchArgument(
                'config', default_value=default_config, description='ROS 2 parameter file'
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
            recorder,
            nominal_controller,
            safety_filter,
            TimerAction(period=start_delay, actions=[hand_sim]),
        ]
    )
