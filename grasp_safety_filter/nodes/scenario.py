"""The ``/grasp/scenario`` document: what a bag's analysis needs that no other topic carries.

``hand_sim_node`` publishes it once at start-up on ``/grasp/scenario``
(``std_msgs/msg/String``, reliable, transient local, depth 1, so a recorder that joins
later still gets it) as one JSON object::

    {
      "format": "grasp_safety_filter/scenario", "version": 1,
      "joint_names": [...], "joint_lower_limits": [...], "joint_upper_limits": [...],
      "effort_limits": [...],                  # rad, rad, N·m, one per joint, model order
      "contact_names": [...], "friction_coefficient": 0.9,
      "fingertip_workspace": {"a_min": ..., "a_max": ..., "b_min": ..., "b_max": ...},  # rad
      "time_step": 0.001, "duration": 15.0, "n_steps": 15000,   # s, s, -
      "integrator": "ode3", "lockstep": true,
      "stop_on_slip": false, "stop_on_workspace_exit": true
    }

Whether the safety filter is on is not the simulator's knowledge and is not in it (the
filter's ``/diagnostics`` say so). Numbers are JSON numbers written with ``repr``
precision, so every float round-trips exactly.
"""

from __future__ import annotations

from collections.abc import Mapping
import json
import math
from typing import Any

SCENARIO_FORMAT = 'grasp_safety_filter/scenario'
SCENARIO_VERSION = 1

#: Keys every scenario document has, with the JSON type of their value.
SCENARIO_KEYS: dict[str, type] = {
    'format': str,
    'version': int,
    'joint_names': list,
    'joint_lower_limits': list,
    'joint_upper_limits': list,
    'effort_limits': list,
    'contact_names': list,
    'friction_coefficient': float,
    'fingertip_workspace': dict,
    'time_step': float,
    'duration': float,
    'n_steps': int,
    'integrator': str,
    'lockstep': bool,
    'stop_on_slip': bool,
    'stop_on_workspace_exit': bool,
}


class ScenarioError(ValueError):
    """A ``/grasp/scenario`` document is not valid JSON or misses or mistypes a key."""


def _floats(values: Any) -> list[float]:
    return [float(v) for v in values]


def scenario_document(model: Any, sim_config: Any) -> dict[str, Any]:
    """Build the scenario document of a run.

    Args:
        model: A ``GraspModel`` (joint and contact names, joint and effort limits,
            friction coefficient, fingertip workspace).
        sim_config: The ``hand_sim_node.config.SimConfig`` of the run.

    """
    workspace = model.fingertip_workspace
    return {
        'format': SCENARIO_FORMAT,
        'version': SCENARIO_VERSION,
        'joint_names': [str(name) for name in model.joint_names],
        'joint_lower_limits': _floats(model.joint_lower_limits),
        'joint_upper_limits': _floats(model.joint_upper_limits),
        'effort_limits': _floats(model.effort_limits),
        'contact_names': [str(name) for name in model.contact_names],
        'friction_coefficient': float(model.friction_coefficient),
        'fingertip_workspace': {
            'a_min': float(workspace.a_min),
            'a_max': float(workspace.a_max),
            'b_min': float(workspace.b_min),
            'b_max': float(workspace.b_max),
        },
        'time_step': float(sim_config.time_step),
        'duration': float(sim_config.duration),
        'n_steps': int(sim_config.n_steps),
        'integrator': str(sim_config.integrator),
        'lockstep': bool(sim_config.lockstep),
        'stop_on_slip': bool(sim_config.stop_on_slip),
        'stop_on_workspace_exit': bool(sim_config.stop_on_workspace_exit),
    }


def scenario_to_text(document: Mapping[str, Any]) -> str:
    """Serialise a scenario document to JSON (non-finite numbers are refused)."""
    check_scenario(document)
    return json.dumps(dict(document), allow_nan=False)


def scenario_from_text(text: str) -> dict[str, Any]:
    """Parse and check a scenario document.

    Raises:
        ScenarioError: Not JSON, not an object, another format or version, or a key
            missing or of the wrong type (the message names it).

    """
    try:
        document = json.loads(text)
    except json.JSONDecodeError as error:
        raise ScenarioError(f'/grasp/scenario: invalid JSON: {error}') from None
    check_scenario(document)
    return document


def _has_type(value: Any, expected: type) -> bool:
    if expected is bool or isinstance(value, bool):
        return expected is bool and isinstance(value, bool)
    if expected is float:
        # JSON has one number type: an integral float may come back as an int.
        return isinstance(value, int | float)
    return isinstance(value, expected)


def check_scenario(document: Any) -> None:
    """Raise ScenarioError unless ``document`` has every key of :data:`SCENARIO_KEYS`."""
    if not isinstance(document, Mapping):
        raise ScenarioError(
            f'/grasp/scenario: expected a JSON object, got {type(document).__name__}'
        )
    if document.get('format') != SCENARIO_FORMAT or document.get('version') != SCENARIO_VERSION:
        raise ScenarioError(
            f'/grasp/scenario: expected format {SCENARIO_FORMAT!r} version {SCENARIO_VERSION}, '
            f'got {document.get("format")!r} version {document.get("version")!r}'
        )
    for key, expected in SCENARIO_KEYS.items():
        value = document.get(key)
        if not _has_type(value, expected):
            raise ScenarioError(
                f"/grasp/scenario: key '{key}': expected a {expected.__name__}, got {value!r}"
            )
    joints = len(document['joint_names'])
    for key in ('joint_lower_limits', 'joint_upper_limits', 'effort_limits'):
        values = document[key]
        if len(values) != joints or not all(
            isinstance(v, int | float) and math.isfinite(v) for v in values
        ):
            raise ScenarioError(
                f"/grasp/scenario: key '{key}': expected {joints} finite numbers (one per "
                f'joint), got {values!r}'
            )
    workspace = document['fingertip_workspace']
    if set(workspace) != {'a_min', 'a_max', 'b_min', 'b_max'}:
        raise ScenarioError(
            "/grasp/scenario: key 'fingertip_workspace': expected a_min, a_max, b_min, b_max, "
            f'got {sorted(workspace)}'
        )


def scenario_from_msg(msg: Any) -> dict[str, Any]:
    """Parse a ``/grasp/scenario`` message (see :func:`scenario_from_text`)."""
    return scenario_from_text(str(msg.data))
