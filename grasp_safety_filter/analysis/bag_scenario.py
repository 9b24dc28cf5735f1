"""A bag's scenario file: what it expects of the run, and its hand's fingers.

A bag records its scenario (``/grasp/scenario``: names, limits, friction, workspace, time
step...), not the scenario file it came from, nor the URDF. ``grasp-analyze`` takes a
scenario file (``--config``, default the paper's) and uses it for a bag that records it:

- its ``expected_outcome`` applies when the bag's scenario document is the file's, up to
  the run options a run may change (:data:`RUN_OPTION_KEYS`: duration, time step,
  integrator, lockstep);
- its hand groups the figures' joints by finger when the bag records the same joint and
  contact names (the URDF is not in the bag: its names are all of the hand it records).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io.schemas import NO_OUTCOME
from grasp_safety_filter.model.fingers import Finger, fingers_from_parameters

#: Scenario-document keys a run may set without changing the scenario (``grasp-demo
#: --duration --dt --integrator``; a ROS graph run's lockstep), and ``n_steps`` with them.
RUN_OPTION_KEYS = ('duration', 'n_steps', 'time_step', 'integrator', 'lockstep')


class ScenarioMismatchError(ConfigError):
    """The scenario file given for a bag describes another hand than the one it records."""


@dataclass(frozen=True)
class ScenarioFile:
    """What the analysis takes from a scenario file.

    Attributes:
        path: The file.
        expected_outcome: Its ``expected_outcome`` (``"none"``: none).
        fingers: Its hand's joints by finger.
        document: The ``/grasp/scenario`` document its simulator publishes.
        model: Its ``GraspModel`` (the grasp drawn in space).

    """

    path: Path
    expected_outcome: str
    fingers: list[Finger]
    document: dict[str, Any]
    model: Any = None


def load_scenario_file(path: Path, overrides: Mapping[str, Any] | None = None) -> ScenarioFile:
    """Read a scenario file as ``hand_sim_node`` does (model built, grasp not checked).

    ``overrides``: ``{key: value}`` of any node; those that apply to ``hand_sim_node``
    (:func:`~grasp_safety_filter.io.schemas.node_overrides`) do.

    Raises:
        ConfigError: The file, its URDF or a parameter is wrong.

    """
    from grasp_safety_filter.io.schemas import HAND_SIM_NODE, load_node_parameters, node_overrides
    from grasp_safety_filter.model.grasp_model import GraspModel
    from grasp_safety_filter.nodes.scenario import scenario_document
    from hand_sim_node.config import SimConfig

    own = node_overrides(overrides or {}, HAND_SIM_NODE)
    params = load_node_parameters(path, HAND_SIM_NODE, overrides=own)
    model = GraspModel.from_parameters(params)
    document = scenario_document(model, SimConfig.from_parameters(params))
    return ScenarioFile(
        Path(path),
        str(params['expected_outcome']),
        fingers_from_parameters(params),
        document,
        model,
    )


def scenario_differences(recorded: Mapping[str, Any], scenario: Mapping[str, Any]) -> list[str]:
    """Keys of the two scenario documents that differ, run options aside (sorted)."""
    keys = (set(recorded) | set(scenario)) - set(RUN_OPTION_KEYS)
    return sorted(key for key in keys if recorded.get(key) != scenario.get(key))


@dataclass(frozen=True)
class BagScenario:
    """What a scenario file says of a bag.

    Attributes:
        expected_outcome: The outcome the bag's run is judged against (``"none"``: none).
        fingers: Its joints by finger for the figures, or None (another hand).
        note: One line on why the file's expected outcome does not apply to a bag of its
            hand, or None.
        model: The hand's ``GraspModel`` for the figures, or None (another hand).

    """

    expected_outcome: str
    fingers: Sequence[Finger] | None
    note: str | None = None
    model: Any = None


def bag_scenario(recorded: Mapping[str, Any], scenario: ScenarioFile, given: bool) -> BagScenario:
    """Apply a scenario file to a bag's recorded scenario (module docstring).

    Args:
        recorded: The bag's ``/grasp/scenario`` document.
        scenario: The scenario file.
        given: The user named the file (else it is the default one, for bags of its hand).

    Raises:
        ScenarioMismatchError: ``given`` and the file's hand has other joint or contact
            names than the bag's.

    """
    names = ('joint_names', 'contact_names')
    same_hand = all(recorded[key] == scenario.document[key] for key in names)
    if not same_hand:
        if given:
            raise ScenarioMismatchError(
                f'--config {scenario.path}: expected the scenario file of the recorded run; '
                f'its hand has joints {scenario.document["joint_names"]} and contacts '
                f'{scenario.document["contact_names"]}, the bag records joints '
                f'{recorded["joint_names"]} and contacts {recorded["contact_names"]}'
            )
        return BagScenario(NO_OUTCOME, None)
    differences = scenario_differences(recorded, scenario.document)
    if not differences:
        return BagScenario(scenario.expected_outcome, scenario.fingers, model=scenario.model)
    note = None
    if scenario.expected_outcome != NO_OUTCOME:
        note = (
            f'expected outcome {scenario.expected_outcome!r} of {scenario.path} not checked: '
            f'the bag records another scenario (differing in {", ".join(differences)})'
        )
    return BagScenario(NO_OUTCOME, scenario.fingers, note, scenario.model)
