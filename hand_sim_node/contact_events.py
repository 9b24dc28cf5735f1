"""A plant's real contact events over a run: onsets of contact loss and object drop.

:class:`ContactEventTracker` follows a plant's :class:`~hand_sim_node.plant.ContactReport`
step by step and keeps the run's :class:`~grasp_safety_filter.io.sim_diagnostic_keys.
PlantEvents` (when each contact was first lost, when the object dropped, the slip distance
per contact); the simulator endpoint publishes it on ``/diagnostics`` at each onset and at
the end of the run.
"""

from __future__ import annotations

from collections.abc import Sequence

from grasp_safety_filter.io.sim_diagnostic_keys import PlantEvents
from hand_sim_node.plant import ContactReport


class ContactEventTracker:
    """The contact events of one run of a plant with real contacts.

    Args:
        plant: The plant's name (``"mujoco"``).
        contact_names: The contacts, in the order of the plant's reports.
    """

    def __init__(self, plant: str, contact_names: Sequence[str]) -> None:
        self.plant = plant
        self.contact_names = list(contact_names)
        self.reset()

    def reset(self) -> None:
        """Forget the run so far."""
        self._lost: dict[str, float] = {}
        self._dropped: float | None = None
        self._slip = dict.fromkeys(self.contact_names, 0.0)

    def update(self, report: ContactReport) -> list[str]:
        """Take the plant's report after a step; return the onsets it shows, as phrases.

        A contact lost again after being regained, or a drop after the first, is no new
        onset: the record keeps the first time of each.
        """
        onsets = []
        for name, present in zip(self.contact_names, report.present, strict=True):
            if not present and name not in self._lost:
                self._lost[name] = report.t
                onsets.append(f'contact {name} lost at {report.t:.3f} s')
        if report.object_dropped and self._dropped is None:
            self._dropped = report.t
            onsets.append(f'object dropped at {report.t:.3f} s')
        self._slip = {
            name: float(distance)
            for name, distance in zip(self.contact_names, report.slip_distance, strict=True)
        }
        return onsets

    def events(self) -> PlantEvents:
        """Return the record so far."""
        return PlantEvents(self.plant, dict(self._lost), self._dropped, dict(self._slip))
