"""From a recorded bag to the paper's figures and a verdict: ``grasp-analyze BAG``."""
