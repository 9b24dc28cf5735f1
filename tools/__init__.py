"""Benchmarks and studies of the package, apart from what the nodes import.

Installed as ``grasp_tools``; the runtime (``grasp_safety_filter``, ``hand_sim_node``) never
imports it. ``grasp-bench``, ``grasp-bench-ros`` and ``grasp-bench-realtime`` run
:mod:`.bench` and :mod:`.bench_ros`; the studies run as ``python -m grasp_tools.<module>``
(:mod:`.mujoco_run`, :mod:`.mujoco_compare`, :mod:`.mujoco_creep`,
:mod:`.object_estimate_study`), and :mod:`.hands` generates random hands and grasps with
a campaign to run them (``python -m grasp_tools.hands``).
"""
