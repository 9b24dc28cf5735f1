"""Hand–object–contact model: kinematics, dynamics, rolling contacts, per-tick grasp state."""
