"""The hand–object plant: rolling-contact simulator, integrators and grasp constraint events.

Plain Python + numpy (no ROS): :class:`~hand_sim_node.simulator.Simulator` integrates the
grasp model of :mod:`grasp_safety_filter.model` under a joint torque held over each step and
records the grasp constraint events the paper reports (fingertip workspace exit, joint
limits, slip, separation). The rclpy node is a thin shell around it.
"""
