"""Verdicts on a run's ``summary.json``: the generic one of any scenario, and an expected one.

Every run gets the generic verdict (:func:`run_verdict`): whether the grasp held for the
duration (the run reached its requested duration and no constraint family was violated),
why and when it stopped, and per constraint family of the summary (whatever families it
lists) when it was first violated and by which contact or joint. A slipping nominal run is
an outcome, not an error.

A scenario that declares an expected outcome (``expected_outcome`` in its
``hand_sim_node`` section, :data:`~grasp_safety_filter.io.schemas.EXPECTED_OUTCOMES`) is
also judged against it (:func:`expected_verdict`): the paper's scenario, ``"paper"``,
against the outcome Shaw-Cortez et al. (CDC 2018) publish in Section IV
(:func:`paper_verdict`). ``grasp-demo`` and ``grasp-analyze`` exit 1 only when such an
outcome is not met. An interrupted run (a recording without the simulator's end of run: a
signal, a killed process) is not judged against it: it did not run as the scenario asks.

On a plant with real contacts (``"plant": "mujoco"`` in the summary) the grasp is judged by
what the plant measured: it held when the run reached its duration with no contact lost, the
object not dropped and no joint limit passed; the other families (slip as beta > mu from
MuJoCo's forces, the fingertip workspace of our model's contact coordinates) are reported,
not judged, and the slip distance per contact is reported. An expected outcome is not
judged there: the paper's is about our rigid plant (its slip is beta > mu, its stop a
workspace exit), not about a plant whose contacts really slip and separate.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any

from grasp_safety_filter.io.plant_schema import RIGID_PLANT
from grasp_safety_filter.io.schemas import EXPECTED_OUTCOMES, NO_OUTCOME, PAPER_OUTCOME

#: The family that still decides ``held`` on a plant with real contact events.
JOINT_LIMITS = 'joint_limits'

#: ``stop_reason`` of a run whose recording has no end-of-run status from the simulator.
INTERRUPTED = 'interrupted'


@dataclass(frozen=True)
class FamilyVerdict:
    """One constraint family over a run.

    Attributes:
        family: The family's name in the summary (``slip``, ``joint_limits``, ...).
        steps: Steps at which it was violated.
        first_t: Time of its first violation, s, or None (never violated).
        first_by: The contact or joint violated first, or None (not known or never).
        side: Which bound of it (``"upper"``, ``"a_max"``, ...; ``""`` for one-sided ones).

    """

    family: str
    steps: int
    first_t: float | None
    first_by: str | None = None
    side: str = ''

    @property
    def violated(self) -> bool:
        """Whether the family was violated at any step."""
        return self.steps > 0

    def first_text(self) -> str:
        """Say when and by what it was first violated, e.g. ``"... at 1.107 s by j2, upper"``."""
        if self.first_t is None:
            return 'never violated'
        by = '' if self.first_by is None else f' by {self.first_by}'
        side = f', {self.side}' if self.first_by is not None and self.side else ''
        return f'first violated at {self.first_t:.3f} s{by}{side}'


@dataclass(frozen=True)
class RunVerdict:
    """The generic verdict of a run (module docstring).

    Attributes:
        held: Ran its requested duration with no constraint family violated (on a plant
            with real contacts: no contact lost, no drop, no joint limit passed).
        completed: Ran its requested duration.
        stop_reason: Why it stopped early (``"fingertip_workspace"``, ``"interrupted"``, ...),
            or None when it ran to the end.
        t_end: Time reached, s.
        duration: Time requested, s.
        families: Per constraint family of the summary, in its order.
        plant: ``"rigid"`` or the plant that measured ``contact_events``.
        contact_events: The summary's ``contact_events`` (None on the rigid plant).

    """

    held: bool
    completed: bool
    stop_reason: str | None
    t_end: float
    duration: float
    families: tuple[FamilyVerdict, ...]
    plant: str = RIGID_PLANT
    contact_events: Mapping[str, Any] | None = None

    def text(self) -> str:
        """One line: ``held for the duration: yes`` or ``no``, with the reasons."""
        violated = [f.family for f in self.families if f.violated]
        if self.contact_events is not None:
            return self._plant_text(violated)
        if self.completed:
            ran = f'ran {self.duration:g} s'
        else:
            ran = (
                f'stopped at {self.t_end:.3f} s of {self.duration:g} s: '
                f'{self.stop_reason or INTERRUPTED}'
            )
        broken = f'violated: {", ".join(violated)}' if violated else 'no constraint violated'
        return f'held for the duration: {"yes" if self.held else "no"} ({ran}; {broken})'

    def _plant_text(self, violated: list[str]) -> str:
        """Return the line of a run on a plant with real contacts (module docstring)."""
        events = self.contact_events or {}
        lost = {k: t for k, t in events['contact_lost'].items() if t is not None}
        ran = (
            f'ran {self.duration:g} s on {self.plant}'
            if self.completed
            else f'stopped at {self.t_end:.3f} s of {self.duration:g} s on {self.plant}: '
            f'{self.stop_reason or INTERRUPTED}'
        )
        parts = [
            'contacts lost: '
            + (', '.join(f'{k} at {t:.3f} s' for k, t in lost.items()) if lost else 'none'),
            'object dropped'
            + (f' at {events["object_dropped"]:.3f} s' if events['object_dropped'] is not None
               else ': no'),
            f'joint limits passed: {"yes" if JOINT_LIMITS in violated else "no"}',
            'slip '
            + ', '.join(
                f'{k} {1e3 * d:.2f} mm' if d is not None else f'{k} n/a'
                for k, d in events['slip_distance'].items()
            ),
        ]
        reported = [f for f in violated if f != JOINT_LIMITS]
        if reported:
            parts.append(f'model families violated (reported): {", ".join(reported)}')
        return f'held for the duration: {"yes" if self.held else "no"} ({ran}; {"; ".join(parts)})'

    def to_json(self) -> dict[str, Any]:
        """Return the verdict as ``verdict.json`` writes it."""
        document: dict[str, Any] = {
            'held': self.held,
            'stop_reason': self.stop_reason,
            't_end': self.t_end,
            'duration_requested': self.duration,
            'first_violations': {
                f.family: {'t': f.first_t, 'name': f.first_by, 'side': f.side}
                for f in self.families
                if f.violated
            },
        }
        if self.contact_events is not None:
            document['plant'] = self.plant
            document['contact_events'] = dict(self.contact_events)
        return document


def run_verdict(summary: Mapping[str, Any]) -> RunVerdict:
    """Judge a run from its summary (every family ``summary["violations"]`` lists)."""
    first_by = summary.get('first_violated_by') or {}
    families = tuple(
        FamilyVerdict(
            family,
            int(record['count']),
            record['first_t'],
            first_by.get(family, {}).get('name'),
            first_by.get(family, {}).get('side', ''),
        )
        for family, record in summary['violations'].items()
    )
    completed = bool(summary['completed'])
    events = summary.get('contact_events')
    if events is None:
        held = completed and not any(f.violated for f in families)
    else:
        held = (
            completed
            and not any(t is not None for t in events['contact_lost'].values())
            and events['object_dropped'] is None
            and not any(f.violated for f in families if f.family == JOINT_LIMITS)
        )
    return RunVerdict(
        held=held,
        completed=completed,
        stop_reason=None if completed else summary['stop_reason'],
        t_end=float(summary['t_end']),
        duration=float(summary['duration_requested']),
        families=families,
        plant=str(summary.get('plant', RIGID_PLANT)),
        contact_events=events,
    )


def paper_verdict(mode: str, summary: Mapping[str, Any]) -> tuple[bool, str]:
    """Tell whether a run shows the paper's outcome for its mode, and why (one line)."""
    violations = summary['violations']
    if mode == 'nominal':
        joint = violations['joint_limits']['first_t']
        checks = {
            'stopped early on a contact leaving the fingertip workspace': (
                not summary['completed'] and summary['stop_reason'] == 'fingertip_workspace'
            ),
            'a joint limit passed before that': joint is not None and joint < summary['t_end'],
            'required friction above mu': violations['slip']['count'] > 0,
        }
    else:
        checks = {
            'ran the full duration': summary['completed'],
            'no constraint violated': all(v['count'] == 0 for v in violations.values()),
        }
    failed = [name for name, ok in checks.items() if not ok]
    if failed:
        return False, 'NOT reproduced: ' + '; '.join(f'not {name}' for name in failed)
    return True, 'reproduced: ' + '; '.join(checks)


#: Per expected outcome: its name in the printed verdict and its judge.
OUTCOME_JUDGES: dict[str, tuple[str, Callable[[str, Mapping[str, Any]], tuple[bool, str]]]] = {
    PAPER_OUTCOME: ('paper outcome', paper_verdict),
}


@dataclass(frozen=True)
class ExpectedVerdict:
    """A run judged against its scenario's expected outcome.

    Attributes:
        outcome: The ``expected_outcome`` value (e.g. ``"paper"``).
        met: Whether the run shows it; None for an interrupted run (not judged).
        text: One line, e.g. ``"paper outcome reproduced: ran the full duration; ..."``.

    """

    outcome: str
    met: bool | None
    text: str


def expected_verdict(
    outcome: str, mode: str, summary: Mapping[str, Any]
) -> ExpectedVerdict | None:
    """Judge a run against ``outcome`` (None for ``"none"``: no outcome expected).

    Raises:
        ValueError: ``outcome`` is not one of
            :data:`~grasp_safety_filter.io.schemas.EXPECTED_OUTCOMES`.

    """
    if outcome not in EXPECTED_OUTCOMES:
        raise ValueError(f'expected_outcome: expected one of {EXPECTED_OUTCOMES}, got {outcome!r}')
    if outcome == NO_OUTCOME:
        return None
    label, judge = OUTCOME_JUDGES[outcome]
    plant = summary.get('plant', RIGID_PLANT)
    if plant != RIGID_PLANT:
        return ExpectedVerdict(
            outcome,
            None,
            f"{label} not judged: it is the {RIGID_PLANT} plant's; this run is on {plant} "
            '(see the verdict above)',
        )
    if summary['stop_reason'] == INTERRUPTED:
        return ExpectedVerdict(
            outcome,
            None,
            f'{label} not judged: the run was interrupted at {summary["t_end"]:.3f} s',
        )
    met, text = judge(mode, summary)
    return ExpectedVerdict(outcome, met, f'{label} {text}')
