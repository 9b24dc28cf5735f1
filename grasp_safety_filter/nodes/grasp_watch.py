"""Is the state a node receives a grasp? The start-up check and the run-time contact check.

The simulator refuses an invalid initial grasp of its own configuration; on a real hand the
first state comes from the hand's drivers and the object tracker, and the controllers must
check it themselves. :class:`GraspWatch` does so for the safety filter and the nominal
controller, over :class:`~grasp_safety_filter.model.grasp_state.GraspState` s:

1. **Start-up** (until a state passes): every finding of
   :func:`grasp_safety_filter.model.grasp_check.grasp_findings` (gap or penetration per
   contact within ``grasp_check.gap_tolerance``, the contact point on its finite face, the
   fingertip coordinates inside the fingertip workspace, the joints strictly inside their
   limits, M_h positive definite, rank J_h = 3n, rank G = 6).
2. **Run time** (once a state has passed): per contact, the signed normal interpenetration
   ``state.penetration`` within ``grasp_check.gap_tolerance`` either way. A real fingertip
   that leaves the object shows as a gap; the simulator's own contact stays within 1e-9 m
   (Baumgarte stabilisation), far below the default 1 mm. The other start-up findings are
   the safety filter's own constraints at run time (joint limits, fingertip workspace),
   whose margins it reports.

:meth:`GraspWatch.check` returns the findings of a state (empty: a grasp) and records a
:class:`LogLine` only when the answer changes (invalid, valid again), so a node logs each
change once rather than every tick; :meth:`GraspWatch.take_log` hands them over.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Mapping
from dataclasses import dataclass
import math
from typing import Any, NamedTuple

import numpy as np

from grasp_safety_filter.errors import ConfigError
from grasp_safety_filter.io.diagnostic_keys import Key
from grasp_safety_filter.io.messages import bounded_text, DiagnosticLevel, NAMES_SHOWN
from grasp_safety_filter.model.grasp_check import GAP_TOLERANCE, grasp_findings, GraspFinding
from grasp_safety_filter.model.grasp_state import GraspState

#: Parameter of the largest gap or penetration per contact, m (both nodes).
GAP_TOLERANCE_PARAMETER = 'grasp_check.gap_tolerance'

#: Log lines kept until a node takes them (a ROS-free runner never does: the oldest go).
MAX_LOG_LINES = 16


class LogLine(NamedTuple):
    """A line for the node's log.

    Attributes:
        level: ``DiagnosticLevel.ERROR`` (the grasp became invalid) or ``OK`` (INFO: valid).
        text: What happened, bounded.

    """

    level: DiagnosticLevel
    text: str


@dataclass(frozen=True)
class GraspCheckConfig:
    """The ``grasp_check.*`` parameters.

    Attributes:
        gap_tolerance: Largest gap or penetration per contact, m (finite, > 0).

    """

    gap_tolerance: float = GAP_TOLERANCE

    def __post_init__(self) -> None:
        value = self.gap_tolerance
        if (
            isinstance(value, bool)
            or not isinstance(value, int | float)
            or not (value > 0.0 and math.isfinite(value))
        ):
            raise ConfigError(
                f"parameter '{GAP_TOLERANCE_PARAMETER}': expected a finite number > 0 m, "
                f'got {value!r}'
            )
        object.__setattr__(self, 'gap_tolerance', float(value))

    @classmethod
    def from_parameters(cls, values: Mapping[str, Any]) -> GraspCheckConfig:
        """Read ``grasp_check.gap_tolerance`` (default :data:`GAP_TOLERANCE` if absent)."""
        return cls(values.get(GAP_TOLERANCE_PARAMETER, GAP_TOLERANCE))


def contact_subject(name: str) -> str:
    """Return the subject of a contact's finding (as in ``model.grasp_check``)."""
    return f'contact {name!r}'


def contact_gap_findings(
    contact_names: list[str], penetration: np.ndarray, gap_tolerance: float
) -> list[GraspFinding]:
    """One finding per contact whose gap or penetration is above ``gap_tolerance``, m.

    Args:
        contact_names: The model's contact names.
        penetration: Signed normal interpenetration per contact, m (> 0 inside the object,
            < 0 a gap; non-finite counts as lost).
        gap_tolerance: Largest admissible magnitude either way, m.

    """
    findings = []
    # Python floats: one conversion, not a numpy scalar per contact.
    depths = np.asarray(penetration, dtype=float).tolist()
    for name, depth in zip(contact_names, depths, strict=True):
        if not math.isfinite(depth):
            problem = f'penetration is {depth} (expected a finite distance)'
        elif depth < -gap_tolerance:
            problem = (
                f'gap {-depth * 1e3:.1f} mm > {gap_tolerance * 1e3:.1f} mm tolerance: the '
                'fingertip left the object'
            )
        elif depth > gap_tolerance:
            problem = f'penetration {depth * 1e3:.1f} mm > {gap_tolerance * 1e3:.1f} mm tolerance'
        else:
            continue
        findings.append(GraspFinding(contact_subject(name), problem))
    return findings


def findings_text(findings: list[GraspFinding]) -> str:
    """Return the findings, ``; ``-separated, bounded (a hand of many contacts stays one line)."""
    return bounded_text('; '.join(map(str, findings)))


def findings_subjects(findings: list[GraspFinding]) -> str:
    """Return the distinct subjects of the findings, comma-separated, the first few named."""
    subjects = list(dict.fromkeys(finding.subject for finding in findings))
    shown = ','.join(subjects[:NAMES_SHOWN])
    if len(subjects) > NAMES_SHOWN:
        shown += f',... ({len(subjects)} in all)'
    return bounded_text(shown, 200)


class GraspWatch:
    """The start-up and run-time grasp checks of one node (module docstring).

    Args:
        model: The ``GraspModel`` (contact names, ``grasp_findings``).
        config: The ``grasp_check.*`` parameters.

    Attributes:
        started: A state has passed the start-up check (the run-time check applies).
        findings: The last checked state's findings (empty: a grasp).

    """

    def __init__(self, model: Any, config: GraspCheckConfig | None = None) -> None:
        self.model = model
        self.config = config or GraspCheckConfig()
        self.started = False
        self.findings: list[GraspFinding] = []
        self._log: deque[LogLine] = deque(maxlen=MAX_LOG_LINES)
        self._contact_names = list(model.contact_names)

    @property
    def gap_tolerance(self) -> float:
        """Largest gap or penetration per contact, m."""
        return self.config.gap_tolerance

    def check(self, state: GraspState) -> list[GraspFinding]:
        """Return the findings of ``state`` (empty: a grasp); log a change of the answer.

        Before a state has passed: the start-up check
        (:func:`~grasp_safety_filter.model.grasp_check.grasp_findings`); after: the run-time
        contact check (:func:`contact_gap_findings`).
        """
        if self.started:
            findings = contact_gap_findings(
                self._contact_names, state.penetration, self.gap_tolerance
            )
        else:
            findings = grasp_findings(
                self.model,
                state.q,
                state.p_object_in_palm,
                state.R_object_to_palm,
                self.gap_tolerance,
            )
        if findings and not self.findings:
            what = 'a contact is lost' if self.started else 'not a valid grasp'
            text = f'state at t = {state.t:.6f} s: {what}: {findings_text(findings)}'
            self._log.append(LogLine(DiagnosticLevel.ERROR, bounded_text(text)))
        elif not findings and (self.findings or not self.started):
            what = 'contacts back' if self.started else 'valid grasp'
            verb = 'resumes' if self.started else 'starts'
            self._log.append(
                LogLine(DiagnosticLevel.OK, f'{what} at t = {state.t:.6f} s: control {verb}')
            )
        if not findings:
            self.started = True
        self.findings = findings
        return findings

    def take_log(self) -> list[LogLine]:
        """Return and forget the log lines recorded since the last call."""
        lines = list(self._log)
        self._log.clear()
        return lines

    def diagnostic_values(self) -> dict[str, Any]:
        """Return the ``grasp.*`` values of a status on a state that is not a grasp."""
        return {
            Key.GRASP_VALID: not self.findings,
            Key.GRASP_CONTACTS: findings_subjects(self.findings),
            Key.GRASP_FINDINGS: findings_text(self.findings),
            Key.GRASP_GAP_TOLERANCE: self.gap_tolerance,
        }
