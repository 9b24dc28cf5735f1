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

The node, its parameters and remappings come from
:func:`grasp_safety_filter.io.launch_arguments.safety_filter_alone`.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from grasp_safety_filter.io.launch_arguments import (
    parse_bool,
    REMAPPED_TOPICS,
    safety_filter_alone,
)
from grasp_safety_filter.io.paths import config_path


def _actions(context):
    def value(name):
        return LaunchConfiguration(name).perform(context)

    node = safety_filter_alone(
        value('config'),
        use_sim_time=parse_bool('use_sim_time', value('use_sim_time')),
        enabled=parse_bool('enabled', value('enabled')),
        remaps={name: value(name) for name in REMAPPED_TOPICS},
    )
    return [Node(**node.node_kwargs())]


def generate_launch_description():
    arguments = [
        DeclareLaunchArgument(
            'config', default_value=str(config_path()), description='ROS 2 parameter file'
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
    return LaunchDescription([*arguments, OpaqueFunction(function=_actions)])
