"""``MARKER_PARAMETERS``: the grasp as markers (``nodes.grasp_markers.MarkerConfig``)."""

from __future__ import annotations

from grasp_safety_filter.io.parameters import ParameterSpec
from grasp_safety_filter.io.schemas.common import DOUBLE

# fmt: off
MARKER_PARAMETERS: tuple[ParameterSpec, ...] = (
    ParameterSpec(
        'markers.rate', DOUBLE, 30.0,
        'MarkerArray publications per second of steady time, at most (none before a joint '
        'state and an object pose) [Hz]',
        min_value=0.0, exclusive_min=True, max_value=100.0,
    ),
    ParameterSpec(
        'markers.force_scale', DOUBLE, 0.005,
        'Length of the contact-force arrows per newton [m/N]',
        min_value=0.0, exclusive_min=True,
    ),
)
# fmt: on
