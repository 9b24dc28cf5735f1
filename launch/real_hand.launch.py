"""The safety filter and the nominal controller on a real hand's streams (or its stand-in).

::

    ros2 launch grasp_safety_filter real_hand.launch.py config:=/path/to/my_hand.yaml \
        joint_states:=/joint_states object_pose:=/tracker/object_pose object_message:=pose \
        command_message:=float64_multi_array effort_controller:=/hand_effort_controller/commands

    ros2 launch grasp_safety_filter real_hand.launch.py sim:=true   # the simulator as the hand

Both controllers tick on each joint state of the hand's driver (``input.sync: latest``), on
the wall clock, the object's state estimated at each stamp from the tracker's samples and the
hand's joint velocities (README, "On a real hand").

Launch arguments:

- ``config``: the parameter file: the hand's model (``/**``) and the controllers' sections
  (default: the installed ``config/paper_scenario.yaml``).
- ``sim`` (``true``/``false``, default ``false``): also start ``hand_sim_node`` in its
  hardware mode (a driver and a tracker on the wall clock) in place of the real hand.
- ``nominal`` (``true``/``false``, default ``true``): start the package's nominal controller;
  ``false`` when a controller of one's own publishes u_nom.
- ``filter`` (``true``/``false``, default ``true``): ``false`` passes u_nom through.
- ``viz`` (``true``/``false``, default ``false``): also start ``grasp_markers_node``, the grasp
  as markers on ``/grasp/markers`` (fixed frame: the palm frame) for RViz or Foxglove.
- ``object_message`` (``odometry``/``pose``): the tracker's ``nav_msgs/Odometry`` on
  ``object_odom`` or ``geometry_msgs/PoseStamped`` on ``object_pose`` (palm frame).
- ``command_message`` (``joint_state``/``float64_multi_array``): u* by joint name on
  ``effort_command``; ``float64_multi_array`` also sends it to a ros2_control
  ``JointGroupEffortController`` on ``effort_controller`` (order: ``command.joints``).
- Remappings, each defaulting to the package's topic: ``joint_states``, ``object_odom``,
  ``object_pose``, ``effort_nominal``, ``effort_command``, ``effort_controller``.

What is started, with which parameters, is decided in
:func:`grasp_safety_filter.io.launch_arguments.real_hand`.
"""

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, OpaqueFunction, Shutdown
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from grasp_safety_filter.io.launch_arguments import parse_bool, real_hand, REAL_HAND_TOPICS
from grasp_safety_filter.io.paths import config_path


def _actions(context):
    def value(name):
        return LaunchConfiguration(name).perform(context)

    nodes = real_hand(
        value('config'),
        simulate=parse_bool('sim', value('sim')),
        nominal=parse_bool('nominal', value('nominal')),
        enabled=parse_bool('filter', value('filter')),
        object_message=value('object_message'),
        command_message=value('command_message'),
        remaps={name: value(name) for name in REAL_HAND_TOPICS},
        viz=parse_bool('viz', value('viz')),
    )
    return [
        Node(
            **node.node_kwargs(),
            on_exit=Shutdown(reason=f'{node.name} exited') if node.ends_launch else None,
        )
        for node in nodes
    ]


def generate_launch_description():
    flags = {
        'sim': ('false', 'Start hand_sim_node in its hardware mode in place of the real hand'),
        'nominal': ('true', "Start the package's nominal controller (false: your own)"),
        'filter': ('true', 'Filter u_nom (false: pass it through unchanged)'),
        'viz': ('false', 'Start grasp_markers_node: the grasp on /grasp/markers (RViz, Foxglove)'),
    }
    arguments = [
        DeclareLaunchArgument(
            'config', default_value=str(config_path()), description='ROS 2 parameter file'
        ),
        *(
            DeclareLaunchArgument(
                name, default_value=default, choices=['true', 'false'], description=text
            )
            for name, (default, text) in flags.items()
        ),
        DeclareLaunchArgument(
            'object_message',
            default_value='odometry',
            choices=['odometry', 'pose'],
            description="The tracker's message: nav_msgs/Odometry or geometry_msgs/PoseStamped",
        ),
        DeclareLaunchArgument(
            'command_message',
            default_value='joint_state',
            choices=['joint_state', 'float64_multi_array'],
            description='u* by joint name, or also for a ros2_control effort controller',
        ),
    ]
    arguments += [
        DeclareLaunchArgument(name, default_value=topic, description=f'Topic used for {topic}')
        for name, topic in REAL_HAND_TOPICS.items()
    ]
    return LaunchDescription([*arguments, OpaqueFunction(function=_actions)])
