"""Grasp-constraint safety filter for torque-controlled multi-fingered hands.

Implements the control-barrier-function safety filter of Shaw-Cortez, Oetomo, Manzie and
Choong, "Grasp Constraint Satisfaction for Object Manipulation using Robotic Hands"
(IEEE CDC 2018): every tick, the joint torque closest to a nominal command that keeps the
contact forces inside the friction cones, the joints inside their limits and the rolling
contact points on the fingertip surface, within actuator limits.

Layout: ``model/`` (hand, object, surfaces, rolling contacts, the per-tick grasp state),
``control/`` (nominal controller, constraint families, QP, safety filter), ``io/``
(configuration, parameters, messages, bags), ``nodes/`` (rclpy shells).
"""

__version__ = '0.1.0'
