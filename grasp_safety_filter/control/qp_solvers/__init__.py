"""QP backends of the safety filter behind one interface.

Every backend is a class ``Backend(problem, slack_weights, settings)`` with:

- ``solve(problem) -> Solution``: the hard problem, or its relaxed version
  (``problem.with_slack(w)``) right after a hard solve that did not end optimal;
- ``warm_start(solution | None)``: a tick settled without the backend (u_nom feasible: its
  solution; no answer at all: None, and the next solve starts cold);
- ``reset()``: forget every warm start.

A backend is warm-started from its own previous tick; the problem's arrays may be rewritten
in place between calls. :data:`BACKENDS` maps the ``qp.solver`` parameter to the classes.
"""

from grasp_safety_filter.control.qp_solvers.daqp_backend import DAQPBackend
from grasp_safety_filter.control.qp_solvers.osqp_backend import OSQPBackend
from grasp_safety_filter.control.qp_solvers.problem import (
    FEASIBILITY_TOLERANCE,
    Problem,
    Solution,
    SolutionStatus,
)

#: Backend class per ``qp.solver`` value.
BACKENDS: dict[str, type[OSQPBackend] | type[DAQPBackend]] = {
    OSQPBackend.name: OSQPBackend,
    DAQPBackend.name: DAQPBackend,
}

__all__ = [
    'BACKENDS',
    'FEASIBILITY_TOLERANCE',
    'DAQPBackend',
    'OSQPBackend',
    'Problem',
    'Solution',
    'SolutionStatus',
]
