"""A campaign file: a base scenario and its variations, expanded into runs.

A campaign file (YAML) names a scenario and how its runs vary::

    scenario: ../paper_scenario.yaml  # relative to this file, or a file of the package's config/
    duration: 2.0                     # s, every run
    modes: [nominal, filtered]        # each variation is run in every mode (paired)
    samples: 100                      # random draws; each is run in every grid cell
    seed: 0
    set:                              # fixed for every run, as grasp-demo --set
      qp.solver: daqp
    grid:                             # every combination of these values
      plant: [rigid, mujoco]
    random:                           # drawn once per sample
      hand_sim_node/model.friction_coefficient: {scale: [0.8, 1.2]}
      hand_sim_node/command_delay: {choice: [0.0, 0.002]}
    reference:                        # a random smooth reference per sample: r0 + A (cos wt - 1)
      axes: [x, y, z, yaw]            # the axes that move (others: A = 0)
      position: [0.0, 0.05]           # |A| on a position axis, m (sign drawn too)
      orientation: [0.0, 0.5]         # |A| on a rotation axis, rad
      frequency: [0.5, 2.0]           # w, rad/s

Parameter names are those of ``--set``: a dotted name for every node that declares it, or
``NODE/NAME`` for one node only (the plant, ``hand_sim_node/...``, against the controllers'
model: model mismatch). Random values: ``{uniform: [lo, hi]}``, ``{log_uniform: [lo, hi]}``,
``{choice: [v, ...]}``, ``{scale: [lo, hi]}`` (the scenario's own value times a uniform factor).

Sample ``s`` draws from ``numpy.random.default_rng([seed, s])``: adding samples keeps the
earlier ones, and the modes and grid cells of one sample share its draw.

``scenario`` may also be a list of such files, e.g. ``[hand_000/scenario.yaml,
hand_001/scenario.yaml]``: the scenarios are then one more grid axis, the outermost (every
sample runs on every scenario, its modes paired), the table gets a ``scenario`` column, and
a ``scale`` multiplies each scenario's own value by the sample's one factor.
"""

from __future__ import annotations

from collections.abc import Mapping
import dataclasses
from dataclasses import dataclass, field
import hashlib
import itertools
import json
import math
from pathlib import Path
from typing import Any

import numpy as np
import yaml

from grasp_safety_filter.campaign.draws import AXES, DISTRIBUTIONS, draw_reference, draw_value
from grasp_safety_filter.io.parameters import ParameterError, suggestion
from grasp_safety_filter.io.paths import config_path
from grasp_safety_filter.io.schemas import load_node_parameters, NODE_SCHEMAS
from grasp_safety_filter.io.schemas.overrides import override_errors, split_override
from grasp_safety_filter.run_types import MODES, RunOptions

#: The table's column of the scenario, when a campaign has several.
SCENARIO_COLUMN = 'scenario'
_KEYS = {'scenario', 'duration', 'modes', 'samples', 'seed', 'set', 'grid', 'random', 'reference'}
_REFERENCE_KEYS = {'axes', 'position', 'orientation', 'frequency'}


class CampaignError(ParameterError):
    """A campaign file that cannot be run; the message names the file and the problem."""


@dataclass(frozen=True)
class RunSpec:
    """One run of a campaign: what a worker needs to run it, and its row's identity.

    Attributes:
        index: Position in the campaign (the table's order).
        key: Content hash of what is run (mode, scenario, duration, overrides): a finished
            run with the same key is never run again.
        mode: ``"nominal"`` or ``"filtered"``.
        sample: The random draw (0 when nothing is random).
        cell: The grid cell (0 without a grid), the scenario's index being its outermost
            axis.
        config: The scenario file, absolute.
        duration: Simulated duration, s.
        overrides: ``{name: value}``, as ``RunOptions.overrides``.
        varied: ``{column: number or text}``: what varies across the campaign, for the table.

    """

    index: int
    key: str
    mode: str
    sample: int
    cell: int
    config: str
    duration: float
    overrides: Mapping[str, Any] = field(default_factory=dict)
    varied: Mapping[str, Any] = field(default_factory=dict)

    def options(self, animate: bool = False) -> RunOptions:
        """Return the runner's options for this run."""
        return RunOptions(
            Path(self.config),
            mode=self.mode,
            duration=self.duration,
            overrides=dict(self.overrides),
            animate=animate,
        )


@dataclass(frozen=True)
class Campaign:
    """A loaded campaign file (module docstring) and its runs.

    Attributes:
        scenarios: ``{name as the file gives it: absolute path}``, in the file's order.
    """

    path: Path
    scenarios: Mapping[str, Path]
    duration: float
    modes: tuple[str, ...]
    samples: int
    seed: int
    fixed: Mapping[str, Any]
    grid: Mapping[str, tuple[Any, ...]]
    random: Mapping[str, tuple[str, tuple[Any, ...]]]
    reference: Mapping[str, Any] | None

    @property
    def scenario(self) -> Path:
        """The first (or only) scenario file."""
        return next(iter(self.scenarios.values()))

    @property
    def varied_columns(self) -> list[str]:
        """The table's columns for what varies, in order."""
        columns = [SCENARIO_COLUMN] if len(self.scenarios) > 1 else []
        columns += [*self.grid, *self.random]
        if self.reference is not None:
            columns += ['reference.frequency', 'reference.position', 'reference.orientation']
        return columns

    def runs(self) -> list[RunSpec]:
        """Every run: scenarios, grid cells, then samples, then modes (a draw's modes adjacent)."""
        cells = list(itertools.product(*self.grid.values())) or [()]
        scenarios = list(self.scenarios.items())
        bases = [_scenario_values(path, self.random) for _, path in scenarios]
        runs: list[RunSpec] = []
        for sample in range(self.samples):
            factors, columns = self._draw(sample)
            for cell, (((name, path), base), values) in enumerate(
                itertools.product(zip(scenarios, bases, strict=True), cells)
            ):
                drawn = _scaled(factors, base, self.random)
                grid = dict(zip(self.grid, values, strict=True))
                varied = {
                    **({SCENARIO_COLUMN: name} if len(scenarios) > 1 else {}),
                    **grid,
                    **{key: drawn.get(key, value) for key, value in columns.items()},
                }
                overrides = {**self.fixed, **grid, **drawn}
                runs += [
                    RunSpec(
                        index=0,
                        key=run_key(mode, path, self.duration, overrides),
                        mode=mode,
                        sample=sample,
                        cell=cell,
                        config=str(path),
                        duration=self.duration,
                        overrides=overrides,
                        varied={k: _column_value(v) for k, v in varied.items()},
                    )
                    for mode in self.modes
                ]
        runs.sort(key=lambda run: (run.cell, run.sample, MODES.index(run.mode)))
        return [dataclasses.replace(run, index=index) for index, run in enumerate(runs)]

    def _draw(self, sample: int) -> tuple[dict[str, Any], dict[str, Any]]:
        """Return sample ``sample``'s overrides (a ``scale``'s factor) and its table columns."""
        rng = np.random.default_rng([self.seed, sample])
        overrides: dict[str, Any] = {}
        for name, (kind, arguments) in self.random.items():
            value = draw_value(rng, kind, arguments)
            overrides[name] = value if kind == 'scale' else _typed(name, value)
        columns = dict(overrides)
        if self.reference is not None:
            amplitude, frequency = draw_reference(rng, self.reference)
            overrides['reference.source'] = 'paper'
            overrides['reference.amplitude'] = amplitude
            overrides['reference.frequency'] = frequency
            columns['reference.frequency'] = frequency
            columns['reference.position'] = float(np.linalg.norm(amplitude[:3]))
            columns['reference.orientation'] = float(np.linalg.norm(amplitude[3:]))
        return overrides, columns


def run_key(mode: str, scenario: Path, duration: float, overrides: Mapping[str, Any]) -> str:
    """Return a run's content hash (12 hex digits): same inputs, same key, on any machine."""
    text = json.dumps(
        [mode, str(scenario), duration, sorted(overrides.items())], default=str, sort_keys=True
    )
    return hashlib.sha1(text.encode()).hexdigest()[:12]


def load_campaign(path: str | Path) -> Campaign:
    """Read and check a campaign file; every name and value is checked here, not in a run.

    Raises:
        CampaignError: The file is unreadable or names or values are invalid.

    """
    path = Path(path)
    try:
        document = yaml.safe_load(path.read_text())
    except (OSError, yaml.YAMLError) as error:
        raise CampaignError(f"campaign '{path}': cannot read it: {error}") from None
    where = f"campaign '{path}'"
    if not isinstance(document, dict):
        raise CampaignError(f'{where}: expected a mapping of {sorted(_KEYS)}')
    unknown = sorted(set(document) - _KEYS)
    if unknown:
        hint = suggestion(unknown[0], sorted(_KEYS))
        raise CampaignError(f'{where}: unknown key {unknown[0]!r}{hint}')
    if 'scenario' not in document:
        raise CampaignError(f"{where}: 'scenario' is required (a scenario parameter file)")
    names = document['scenario']
    names = names if isinstance(names, list) and names else [names]
    scenarios = {str(name): _scenario_path(path, name, where) for name in names}
    if len(scenarios) != len(names):
        raise CampaignError(f"{where}: 'scenario' names a file twice")
    duration = document.get('duration', 2.0)
    if isinstance(duration, bool) or not isinstance(duration, int | float) or duration <= 0:
        raise CampaignError(
            f"{where}: 'duration' must be a number of seconds > 0, got {duration!r}"
        )
    modes = tuple(document.get('modes', MODES))
    if not modes or any(mode not in MODES for mode in modes) or len(set(modes)) != len(modes):
        raise CampaignError(f"{where}: 'modes' must be distinct of {list(MODES)}, got {modes!r}")
    samples, seed = document.get('samples', 1), document.get('seed', 0)
    for name, value, least in (('samples', samples, 1), ('seed', seed, 0)):
        if isinstance(value, bool) or not isinstance(value, int) or value < least:
            raise CampaignError(f"{where}: '{name}' must be an integer >= {least}, got {value!r}")
    fixed = {name: _typed(name, value, where) for name, value in _mapping(document, 'set', where)}
    grid = {}
    for name, values in _mapping(document, 'grid', where):
        if not isinstance(values, list) or not values:
            raise CampaignError(f"{where}: grid '{name}' must be a non-empty list of values")
        grid[name] = tuple(_typed(name, value, where) for value in values)
    random = {
        name: _distribution(name, value, where)
        for name, value in _mapping(document, 'random', where)
    }
    reference = _reference_section(document.get('reference'), where)
    campaign = Campaign(
        path, scenarios, float(duration), modes, samples, seed, fixed, grid, random, reference
    )
    try:
        campaign.runs()[0].options()  # every name declared by a node, the scenario readable
    except (ParameterError, ValueError, OSError) as error:
        raise CampaignError(f'{where}: {error}') from None
    return campaign


def _scenario_path(path: Path, value: Any, where: str) -> Path:
    if not isinstance(value, str) or not value:
        raise CampaignError(
            f"{where}: 'scenario' must be a file name or a list of them, got {value!r}"
        )
    for candidate in (path.parent / value, config_path(value)):
        if candidate.is_file():
            return candidate.resolve()
    raise CampaignError(
        f"{where}: scenario '{value}' is neither beside the campaign file nor in "
        f"the package's config/ ({config_path(value).parent})"
    )


def _mapping(document: Mapping[str, Any], key: str, where: str) -> list[tuple[str, Any]]:
    section = document.get(key) or {}
    if not isinstance(section, dict):
        raise CampaignError(f"{where}: '{key}' must be a mapping of parameter names")
    return [(str(name), value) for name, value in section.items()]


def _typed(name: str, value: Any, where: str = 'campaign') -> Any:
    """``value`` checked and converted as the nodes ``name`` addresses read it."""
    errors = override_errors([name])
    if errors:
        raise CampaignError(f'{where}: {errors[0]}')
    node, parameter = split_override(name)
    schemas = [NODE_SCHEMAS[node]] if node else list(NODE_SCHEMAS.values())
    spec = next(spec for schema in schemas if (spec := schema.get(parameter)) is not None)
    try:
        return spec.validate(value)
    except ParameterError as error:
        raise CampaignError(f'{where}: {error}') from None


def _distribution(name: str, value: Any, where: str) -> tuple[str, tuple[Any, ...]]:
    errors = override_errors([name])
    if errors:
        raise CampaignError(f'{where}: {errors[0]}')
    if not (isinstance(value, dict) and len(value) == 1 and next(iter(value)) in DISTRIBUTIONS):
        raise CampaignError(
            f"{where}: random '{name}' must be one of "
            f'{{{": [...]}, {".join(DISTRIBUTIONS)}: [...]}}, got {value!r}'
        )
    kind, arguments = next(iter(value.items()))
    if not isinstance(arguments, list) or not arguments:
        raise CampaignError(f"{where}: random '{name}': {kind} needs a list, got {arguments!r}")
    if kind == 'choice':
        return kind, tuple(_typed(name, item, where) for item in arguments)
    if (
        len(arguments) != 2
        or not all(isinstance(a, int | float) and not isinstance(a, bool) for a in arguments)
        or not arguments[0] <= arguments[1]
        or (kind == 'log_uniform' and arguments[0] <= 0)
    ):
        positive = ' > 0' if kind == 'log_uniform' else ''
        raise CampaignError(
            f"{where}: random '{name}': {kind} needs [lo, hi] with lo <= hi{positive}, "
            f'got {arguments!r}'
        )
    if kind != 'scale':
        _typed(name, float(arguments[0]), where)
        _typed(name, float(arguments[1]), where)
    return kind, (float(arguments[0]), float(arguments[1]))


def _reference_section(section: Any, where: str) -> dict[str, Any] | None:
    if section is None:
        return None
    if not isinstance(section, dict) or set(section) - _REFERENCE_KEYS:
        raise CampaignError(f"{where}: 'reference' must be a mapping of {sorted(_REFERENCE_KEYS)}")
    axes = section.get('axes', list(AXES))
    if not isinstance(axes, list) or not axes or any(axis not in AXES for axis in axes):
        raise CampaignError(
            f"{where}: reference 'axes' must be some of {list(AXES)}, got {axes!r}"
        )
    checked: dict[str, Any] = {'axes': tuple(axes)}
    for key, default in (
        ('position', [0.0, 0.0]),
        ('orientation', [0.0, 0.0]),
        ('frequency', [1.0, 1.0]),
    ):
        bounds = section.get(key, default)
        if (
            not isinstance(bounds, list)
            or len(bounds) != 2
            or not all(isinstance(b, int | float) and not isinstance(b, bool) for b in bounds)
            or not 0 <= bounds[0] <= bounds[1]
            or not all(math.isfinite(b) for b in bounds)
        ):
            raise CampaignError(
                f"{where}: reference '{key}' must be [lo, hi] with 0 <= lo <= hi, got {bounds!r}"
            )
        checked[key] = (float(bounds[0]), float(bounds[1]))
    return checked


def _scenario_values(scenario: Path, random: Mapping[str, tuple[str, Any]]) -> dict[str, Any]:
    """Return the scenario's own values of the parameters a ``scale`` distribution multiplies."""
    values: dict[str, Any] = {}
    for name, (kind, _) in random.items():
        if kind != 'scale':
            continue
        node, parameter = split_override(name)
        node = node or next(n for n, schema in NODE_SCHEMAS.items() if schema.get(parameter))
        values[name] = load_node_parameters(scenario, node)[parameter]
    return values


def _scaled(
    drawn: Mapping[str, Any],
    scenario_values: Mapping[str, Any],
    random: Mapping[str, tuple[str, Any]],
) -> dict[str, Any]:
    """Return ``drawn`` with each ``scale`` factor applied to the scenario's own value."""
    overrides = dict(drawn)
    for name, (kind, _) in random.items():
        if kind == 'scale':
            base, factor = scenario_values[name], drawn[name]
            value = [float(v) * factor for v in base] if isinstance(base, list) else base * factor
            overrides[name] = _typed(name, value)
    return overrides


def _column_value(value: Any) -> Any:
    """Return a table cell: numbers and text as they are, a list as its JSON text."""
    if isinstance(value, list | tuple):
        return json.dumps(list(value))
    return value
