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
      "stop_on_slip": false, "stop_on_workspace_exit": true,
      "object_face_half_widths": [[h_u, h_v], ...],  # m, per contact; null: no edge
      "torsional_friction": 0.005,   # m; soft fingers only (absent: point contacts)
      "torsional_compliance": 0.1    # soft fingers' relative torsional compliance
    }

``friction_coefficient`` and each workspace bound are one number when every contact has the
same value (the paper's scenario), else a list of one per contact in ``contact_names`` order.

Whether the safety filter is on is not the simulator's knowledge and is not in it (the
filter's ``/diagnostics`` say so). Numbers are JSON numbers written with ``repr``
precision, so every float round-trips exactly.
"""

from __future__ import annotations

from collections.abc import Mapping
import json
import math
from typing import Any

import numpy as np

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.model.fingertip_workspace import BOUNDS as WORKSPACE_BOUNDS
from grasp_safety_filter.model.per_contact import compact

SCENARIO_FORMAT = 'grasp_safety_filter/scenario'
SCENARIO_VERSION = 1

#: Largest friction coefficient taken as physical (rubber on rubber is about 1-4).
MAX_FRICTION_COEFFICIENT = 100.0
#: Smallest time step, s: stamps are whole nanoseconds.
MIN_TIME_STEP = 1e-9
#: Most steps a run may have (a day at 1 us).
MAX_STEPS = 1e11
#: Integrators the simulator has.
INTEGRATORS = ('ode3', 'rk4')


class PerContactNumber:
    """JSON type of a per-contact value: a number, or a list of one number per contact."""


#: Keys every scenario document has, with the JSON type of their value.
SCENARIO_KEYS: dict[str, type] = {
    'format': str,
    'version': int,
    'joint_names': list,
    'joint_lower_limits': list,
    'joint_upper_limits': list,
    'effort_limits': list,
    'contact_names': list,
    'friction_coefficient': PerContactNumber,
    'fingertip_workspace': dict,
    'time_step': float,
    'duration': float,
    'n_steps': int,
    'integrator': str,
    'lockstep': bool,
    'stop_on_slip': bool,
    'stop_on_workspace_exit': bool,
}


class ScenarioError(ConfigError):
    """A ``/grasp/scenario`` document is not valid JSON or misses or mistypes a key."""


def _floats(values: Any) -> list[float]:
    return [float(v) for v in values]


#: Key of the ``/grasp/scenario`` document holding each contact's torsional friction mu_t, m,
#: present only with soft-finger contacts (``model.torsional_friction`` > 0).
TORSIONAL_FRICTION_KEY = 'torsional_friction'
#: Key of the soft fingers' relative torsional compliance rho (``model.torsional_compliance``),
#: present with :data:`TORSIONAL_FRICTION_KEY`.
TORSIONAL_COMPLIANCE_KEY = 'torsional_compliance'

#: Key of the ``/grasp/scenario`` document holding each contact's face half extents
#: ``[h_u, h_v]``, m (absent for a sphere object), for judging a bag's object-face margins.
OBJECT_FACES_KEY = 'object_face_half_widths'


def object_face_half_widths(model: Any) -> np.ndarray | None:
    """Half extents ``(h_u, h_v)`` of each contact's box face, (n, 2), m.

    ``inf`` for a contact not on a bounded face (a sphere object); None when the model has
    not chosen its contacts' surfaces yet.
    """
    if not getattr(model, 'contacts_bound', False):
        return None
    return np.array(
        [
            getattr(contact.object_surface, 'half_widths', (np.inf, np.inf))
            for contact in model.contacts
        ],
        dtype=float,
    )


def scenario_document(model: Any, sim_config: Any) -> dict[str, Any]:
    """Build the scenario document of a run.

    Args:
        model: A ``GraspModel`` (joint and contact names, joint and effort limits,
            friction coefficient, fingertip workspace).
        sim_config: The ``hand_sim_node.config.SimConfig`` of the run.

    """
    box = model.fingertip_workspace.per_contact(len(model.contact_names))
    document: dict[str, Any] = {
        'format': SCENARIO_FORMAT,
        'version': SCENARIO_VERSION,
        'joint_names': [str(name) for name in model.joint_names],
        'joint_lower_limits': _floats(model.joint_lower_limits),
        'joint_upper_limits': _floats(model.joint_upper_limits),
        'effort_limits': _floats(model.effort_limits),
        'contact_names': [str(name) for name in model.contact_names],
        'friction_coefficient': compact(model.friction_coefficient),
        'fingertip_workspace': {
            bound: compact(box[:, column]) for column, bound in enumerate(WORKSPACE_BOUNDS)
        },
        'time_step': float(sim_config.time_step),
        'duration': float(sim_config.duration),
        'n_steps': int(sim_config.n_steps),
        'integrator': str(sim_config.integrator),
        'lockstep': bool(sim_config.lockstep),
        'stop_on_slip': bool(sim_config.stop_on_slip),
        'stop_on_workspace_exit': bool(sim_config.stop_on_workspace_exit),
    }
    torsional = getattr(model, 'torsional_friction', None)
    if torsional is not None:
        document[TORSIONAL_FRICTION_KEY] = compact(torsional)
        document[TORSIONAL_COMPLIANCE_KEY] = float(model.torsional_compliance)
    half = object_face_half_widths(model)
    if half is not None:
        document[OBJECT_FACES_KEY] = [
            [float(h) if math.isfinite(h) else None for h in row] for row in half.tolist()
        ]
    return document


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
        document = json.loads(text, parse_constant=_refuse_constant)
    except json.JSONDecodeError as error:
        raise ScenarioError(f'/grasp/scenario: invalid JSON: {error}') from None
    except RecursionError:
        raise ScenarioError('/grasp/scenario: invalid JSON: nested too deeply') from None
    check_scenario(document)
    return document


def _refuse_constant(name: str) -> float:
    raise ScenarioError(f'/grasp/scenario: invalid JSON: {name} is not a JSON number')


def _has_type(value: Any, expected: type) -> bool:
    if expected is PerContactNumber:
        values = value if isinstance(value, list) else [value]
        return bool(values) and all(_has_type(v, float) for v in values)
    if expected is bool or isinstance(value, bool):
        return expected is bool and isinstance(value, bool)
    if expected is float:
        # JSON has one number type: an integral float may come back as an int.
        return isinstance(value, int | float)
    return isinstance(value, expected)


def check_scenario(document: Any) -> None:
    """Raise ScenarioError unless ``document`` is a physical scenario.

    It must have every key of :data:`SCENARIO_KEYS` with its type, finite numbers, limits
    with lower below upper, positive effort limits, a friction coefficient in
    (0, :data:`MAX_FRICTION_COEFFICIENT`], a time step of at least :data:`MIN_TIME_STEP`
    that divides the duration into ``n_steps`` steps, and a known integrator.
    """
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
            what = (
                'number or a list of one per contact'
                if expected is PerContactNumber
                else expected.__name__
            )
            raise ScenarioError(f"/grasp/scenario: key '{key}': expected a {what}, got {value!r}")
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
    if set(workspace) != set(WORKSPACE_BOUNDS) or not all(
        _has_type(v, PerContactNumber) for v in workspace.values()
    ):
        raise ScenarioError(
            "/grasp/scenario: key 'fingertip_workspace': expected a_min, a_max, b_min, b_max, "
            f'each a number or a list of one per contact, got {workspace!r}'
        )
    _check_physical(document)


def _bad(key: str, expected: str, value: Any) -> ScenarioError:
    return ScenarioError(f"/grasp/scenario: key '{key}': expected {expected}, got {value!r}")


def _finite(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _check_physical(document: Mapping[str, Any]) -> None:
    """Refuse values no run can have (the types are already checked)."""
    for key in ('joint_names', 'contact_names'):
        names = document[key]
        if not names or not all(isinstance(n, str) and n for n in names):
            raise _bad(key, 'a non-empty list of names', names)
        if len(set(names)) != len(names):
            raise _bad(key, 'distinct names', names)
    lower, upper = document['joint_lower_limits'], document['joint_upper_limits']
    if not all(lo < hi for lo, hi in zip(lower, upper, strict=True)):
        raise _bad('joint_lower_limits', 'each below its joint_upper_limits', lower)
    if not all(e > 0 for e in document['effort_limits']):
        raise _bad('effort_limits', 'numbers > 0', document['effort_limits'])
    contacts = len(document['contact_names'])
    mu = scenario_per_contact(document, 'friction_coefficient')
    if not all(_finite(v) and 0 < v <= MAX_FRICTION_COEFFICIENT for v in mu):
        raise _bad(
            'friction_coefficient',
            f'numbers in (0, {MAX_FRICTION_COEFFICIENT:g}], 1 or {contacts} (one per contact)',
            document['friction_coefficient'],
        )
    if TORSIONAL_FRICTION_KEY in document:
        mu_t = scenario_per_contact(document, TORSIONAL_FRICTION_KEY)
        if not all(_finite(v) and v > 0 for v in mu_t):
            raise _bad(
                TORSIONAL_FRICTION_KEY,
                f'numbers > 0 m, 1 or {contacts} (one per contact)',
                document[TORSIONAL_FRICTION_KEY],
            )
        compliance = document.get(TORSIONAL_COMPLIANCE_KEY, 0.0)
        if not (_finite(compliance) and compliance >= 0):
            raise _bad(TORSIONAL_COMPLIANCE_KEY, 'a finite number >= 0', compliance)
    box = scenario_workspace(document)
    for row in box:
        for low, high in ((0, 1), (2, 3)):
            if not (_finite(row[low]) and _finite(row[high]) and row[low] < row[high]):
                first, second = WORKSPACE_BOUNDS[low], WORKSPACE_BOUNDS[high]
                raise _bad(
                    'fingertip_workspace',
                    f'finite {first} < {second}',
                    dict(document['fingertip_workspace']),
                )
    step, duration = document['time_step'], document['duration']
    if not (_finite(step) and step >= MIN_TIME_STEP):
        raise _bad('time_step', f'a finite number >= {MIN_TIME_STEP:g} s', step)
    if not (_finite(duration) and duration > 0):
        raise _bad('duration', 'a finite number > 0 s', duration)
    if duration / step > MAX_STEPS:
        raise _bad('duration', f'at most {MAX_STEPS:g} time steps', duration)
    n_steps = max(1, round(duration / step))
    if document['n_steps'] != n_steps:
        raise _bad('n_steps', f'{n_steps} (duration / time_step)', document['n_steps'])
    if document['integrator'] not in INTEGRATORS:
        raise _bad('integrator', f'one of {list(INTEGRATORS)}', document['integrator'])


def _per_contact_list(value: Any, contacts: int, key: str) -> list[Any]:
    values = value if isinstance(value, list) else [value]
    if len(values) not in (1, contacts):
        raise _bad(key, f'1 or {contacts} values (one per contact)', value)
    return values * (contacts // len(values))


def scenario_per_contact(document: Mapping[str, Any], key: str) -> list[float]:
    """Each contact's value of a per-contact key (``friction_coefficient``), in contact order.

    Raises:
        ScenarioError: Neither 1 nor n values.
    """
    contacts = len(document['contact_names'])
    return _per_contact_list(document[key], contacts, key)


def scenario_workspace(document: Mapping[str, Any]) -> list[list[float]]:
    """Each contact's ``[a_min, a_max, b_min, b_max]``, rad, in contact order.

    Raises:
        ScenarioError: A bound has neither 1 nor n values.
    """
    contacts = len(document['contact_names'])
    workspace = document['fingertip_workspace']
    columns = [
        _per_contact_list(workspace[bound], contacts, 'fingertip_workspace')
        for bound in WORKSPACE_BOUNDS
    ]
    return [list(row) for row in zip(*columns, strict=True)]


def scenario_from_msg(msg: Any) -> dict[str, Any]:
    """Parse a ``/grasp/scenario`` message (see :func:`scenario_from_text`)."""
    return scenario_from_text(str(msg.data))
