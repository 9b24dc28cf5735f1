"""A generated hand's scenario parameter file, from config/four_finger_box.yaml.

The template's ``/**`` model section is replaced by the generated hand's and object's, and
``hand_sim_node``'s ``initial`` by the generated grasp; the filter's class-K functions,
barrier margins, object-workspace switch and QP metric, which the template pins to the
paper's, are left out, so a generated hand runs the filter's defaults (:data:`DEFAULTED`);
everything else (the rigid plant, its time step, ``stop_on_workspace_exit``, the controllers'
gains and the filter's other settings) is the template's. The file is written with PyYAML
as a ROS 2 parameter file: every double is a Python float, which PyYAML writes with a
decimal point or an exponent, as ROS 2 requires of a double (the package's own loader
accepts an integer for a double, ROS 2 does not).
"""

from __future__ import annotations

import copy
from functools import cache
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from grasp_safety_filter.io.paths import config_path
from grasp_tools.hands.kinematics import FingerDesign
from grasp_tools.hands.objects import ObjectDesign

TEMPLATE = 'four_finger_box.yaml'
URDF_NAME = 'hand.urdf'
SCENARIO_NAME = 'scenario.yaml'
#: The filter's parameters a generated scenario leaves to their defaults, as nested keys.
DEFAULTED = (
    ('joint_limits', 'margin'),
    ('fingertip_workspace', 'margin'),
    ('object_workspace', 'enabled'),
    ('barrier',),
    ('qp', 'metric'),
)
#: The fingertip workspace of every generated hand: the template's (0.15 rad off a = ±π/2,
#: the hemisphere z > 0 of each fingertip frame).
WORKSPACE = {
    'a_min': -math.pi / 2 + 0.15,
    'a_max': math.pi / 2 - 0.15,
    'b_min': -math.pi,
    'b_max': 0.0,
}


@cache
def _template() -> dict[str, Any]:
    return yaml.safe_load(config_path(TEMPLATE).read_text())


def model_section(fingers: list[FingerDesign], obj: ObjectDesign, faces: tuple[str, ...]) -> dict:
    """Return the ``/**`` ``model`` section of a generated hand, nested as the template's."""
    shape: dict[str, Any] = {'shape': obj.shape, 'mass': float(obj.mass)}
    if obj.shape == 'box':
        shape['edge_lengths'] = [float(x) for x in obj.edge_lengths]
    else:
        shape['size'] = float(obj.edge_lengths[0])
    model: dict[str, Any] = {
        'urdf_file': URDF_NAME,
        'joint_names': [name for finger in fingers for name in finger.joint_names],
        'fingertip_frames': [finger.tip_frame for finger in fingers],
        'contact_names': [finger.name for finger in fingers],
        'object': shape,
    }
    if obj.shape == 'box':
        model['contact_faces'] = list(faces)
    model.update(
        {
            'friction_coefficient': float(obj.friction_coefficient),
            'torsional_friction': 0.0,
            'torsional_compliance': 0.1,
            'gravity': [0.0, 0.0, -9.81],
            'palm_frame': '',
            'object_frame': 'object',
            'fingertip_workspace': {name: float(v) for name, v in WORKSPACE.items()},
        }
    )
    return model


def scenario_document(
    fingers: list[FingerDesign],
    obj: ObjectDesign,
    faces: tuple[str, ...],
    q0: np.ndarray,
) -> dict[str, Any]:
    """Return the template with the generated model and initial grasp."""
    document = copy.deepcopy(_template())
    document['/**']['ros__parameters']['model'] = model_section(fingers, obj, faces)
    document['hand_sim_node']['ros__parameters']['initial'] = {
        'joint_positions': [float(x) for x in q0],
        'object_position': [float(x) for x in obj.p_object_in_palm],
        'object_orientation': [float(x) for x in obj.quaternion_xyzw],
    }
    safety_filter = document['safety_filter_node']['ros__parameters']
    for *section, name in DEFAULTED:
        parent = safety_filter
        for key in section:
            parent = parent[key]
        del parent[name]
    return document


class _Quoted(str):
    """A string value, written in double quotes (ROS 2 reads an unquoted ``off`` as a bool)."""


class _Dumper(yaml.SafeDumper):
    """PyYAML's safe dumper, with :class:`_Quoted` strings in double quotes."""


_Dumper.add_representer(
    _Quoted, lambda dumper, text: dumper.represent_scalar('tag:yaml.org,2002:str', text, '"')
)


def _quote_values(value: Any) -> Any:
    """``value`` with every string value (not key) quoted."""
    if isinstance(value, dict):
        return {key: _quote_values(item) for key, item in value.items()}
    if isinstance(value, list):
        return [_quote_values(item) for item in value]
    return _Quoted(value) if isinstance(value, str) else value


def write_scenario(path: Path, document: dict[str, Any], header: str) -> None:
    """Write ``document`` to ``path`` with ``header`` as its first comment lines."""
    comment = ''.join(f'# {line}\n' if line else '#\n' for line in header.splitlines())
    body = yaml.dump(
        _quote_values(document), Dumper=_Dumper, sort_keys=False, default_flow_style=None,
        width=96,
    )  # fmt: skip
    path.write_text(comment + body)
