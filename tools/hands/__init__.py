"""Random hands and grasps not designed with the filter, and a campaign to run them.

``python -m grasp_tools.hands --count N --seed S --out DIR`` (:mod:`.__main__`) writes N
hands, each a URDF and a scenario parameter file that passes the nodes' start-up check:

- :mod:`.objects`: the object (a box or sphere of 3–10 cm above the palm) and the contacts
  on it, the thumb's opposing the other fingers';
- :mod:`.kinematics`: a random finger per contact (3 or 4 revolute joints, random link
  lengths, its base on the palm) and the hand's URDF text;
- :mod:`.ik`: the joint angles that put the fingertips on the contacts, solved on the
  package's own hand model, and the fingertip frames turned after it;
- :mod:`.scenario`: the scenario file, from config/four_finger_box.yaml;
- :mod:`.grasp`: one hand from its seed, every step and the checks, redrawn until it passes;
- :mod:`.campaign`: ``hands.csv`` and ``campaign.yaml``.
"""
