"""The grasp in space: scenes of the hand, the object and the contacts, and their pictures."""
