"""The safety filter alone, for a user's own hand (or simulator) and nominal controller.

::

    ros2 launch grasp_safety_filter safety_filter.launch.py \
        config:=/path/to/my_hand.yaml \
        joint_states:=/my_hand/joint_states object_odom:=/tracker/object_odom \
        effort_nominal:=/my_planner/effort effort_command:=/my_hand/effort_command

Launch arguments:

- ``config``: parameter file with the ``/**`` model section and a ``safety_filter_node``
  section (default: the installed ``config/paper_scenario.yaml``).
- ``use_sim_time`` (``true``/``false``, default ``false``): input stamps are checked
  against the node's clock, so use the clock the hand's stamps are on.
- ``enabled`` (``true``/``false``, default ``true``): ``false`` passes u_nom through.
- Remappings, each defaulting to the package's topic name:
  ``joint_states`` (``sensor_msgs/JointState``: q, dq, effort, by joint name),
  ``object_odom`` (``nav_msgs/Odometry``: object pose in the palm frame ``palm``,
  child frame ``object``), ``effort_nominal`` (``sensor_msgs/JointState``: u_nom),
  ``effort_command`` (``sensor_msgs/JointState``: u*, to the hand's torque interface),
  ``margins`` and ``diagnostics``.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node
from launch_ros.parameter_descriptions import ParameterValue

from grasp_safety_filter.io import topics
from grasp_safety_filter.io.paths import config_path

PACKAGE = 'grasp_safety_filter'

#: Launch argument -> the topic it remaps.
REMAPPED_TOPICS = {
    'joint_states': topics.JOINT_STATES,
    'object_odom': topics.OBJECT_ODOM,
    'effort_nominal': topics.EFFORT_NOMINAL,
    'effort_command': topics.EFFORT_COMMAND,
    'margins': topics.MARGINS,
    'diagnostics': topics.DIAGNOSTICS,
}


def generate_launch_description():
    default_config = str(config_path())
    arguments = [
        DeclareLaunchArgument(
            'config', default_value=default_config, description='ROS 2 parameter file'
        ),
        DeclareLaunchArgument(
            'use_sim_time',
            default_value='false',
            choices=['true', 'false'],
            description='Use /clock (simulation time) for the input stamp checks',
        ),
        DeclareLaunchArgument(
            'enabled',
            default_value='true',
            choices=['true', 'false'],
            description='Filter u_nom (false: pass it through unchanged)',
        ),
    ]
    arguments += [
        DeclareLaunchArgument(name, default_value=topic, description=f'Topic used for {topic}')
        for name, topic in REMAPPED_TOPICS.items()
    ]
    safety_filter = Node(
        package=PACKAGE,
        executable='safety_filter_node',
        name='safety_filter_node',
        parameters=[
            LaunchConfiguration('config'),
            {
                'use_sim_time': ParameterValue(
                    LaunchConfiguration('use_sim_time'), value_type=bool
                ),
                'enabled': ParameterValue(LaunchConfiguration('enabled'), value_type=bool),
            },
        ],
        remappings=[(topic, LaunchConfiguration(name)) for name, topic in REMAPPED_TOPICS.items()],
        output='screen',
    )
    return LaunchDescription([*arguments, safety_filter])
