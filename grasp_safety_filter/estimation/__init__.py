"""Estimation: the grasped object's pose and twist at the hand's joint-state rate."""
