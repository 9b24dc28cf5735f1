"""``grasp-bench``: how fast the filter is, on the paper's own filtered run.

1. **Record.** The paper's scenario runs closed loop (simulator, nominal controller and
   safety filter called directly, no messages) for ``--duration`` simulated seconds; every
   tick's plant state and u_nom are kept. Its wall time gives the filtered loop's
   real-time factor.
2. **Replay.** First the machine's own spread: a fixed compiled loop timed as many times
   as there are ticks (the noise floor, :mod:`.machine`). Then the recorded ticks are
   replayed in order through fresh instances, so every timing sees the same inputs and the
   filter the same warm starts as in the run. Per tick,
   each piece is timed on its own: the model terms (``GraspModel.state``), the nominal
   controller (reference sample and computed torque), the QP assembly
   (``SafetyFilter.assemble``), OSQP alone on the assembled hard QP (a second solver with the
   filter's settings: ``update`` + ``solve``, warm-started from its previous tick), the
   whole filter step (``SafetyFilter.solve``: assembly, solve, exact active-set step,
   checks and margins) and the whole filter-node tick (model terms + filter step).
3. **Other solvers.** The same hard QPs (``hard_qp.dense()`` of evenly spaced ticks) go to
   cvxpy (a fresh ``cvxpy.Problem`` per tick, as CBF research code is usually written: the
   default solver and OSQP with their default settings, and Clarabel with tight
   tolerances as an accurate reference) and to the dense active-set solver daqp through
   qpsolvers, each only if installed (``pip install grasp_safety_filter[bench]``). Their
   times are compared with the filter step on the same ticks and their solutions with ours
   (``max |Δu|``, on ticks whose hard QP is feasible).
4. **Closed loops.** Real-time factors (simulated seconds per wall second) of the nominal
   loop (simulator + nominal controller) and of the ROS-free runner recording to a bag; in
   the runner's run, the safety filter endpoint's three callbacks per tick in thread CPU
   time (:mod:`.node_callbacks`).

Timings are wall-clock (``time.perf_counter``) with the garbage collector on, as in a
node. Nothing here asserts a time: the figures are for reading.

``grasp-bench --soak SECONDS`` runs the long-run benchmark instead (memory growth of the
recording runner, bag size per simulated second, memory of the analysis):
:mod:`grasp_tools.soak`.

Modules: :mod:`.recorded_run` (1, 4), :mod:`.replay` (2), :mod:`.external_solvers` (3),
:mod:`.backends` (the QP backends on the same ticks), :mod:`.hands` (other hands in the
same run, ``--compare-config``), :mod:`.machine` (machine facts and noise floor),
:mod:`.node_callbacks` (4),
:mod:`.report` (the document and its table), :mod:`.command_line`.

``grasp-bench-realtime`` (:mod:`.real_time`) measures the filter node in real time over
DDS instead, on a driver's and a tracker's streams; its modules (``real_time_*``) are not
imported here.
"""

from __future__ import annotations

from grasp_tools.bench.backends import (  # noqa: F401
    backend_table,
    BackendReplay,
    replay_backends,
)
from grasp_tools.bench.command_line import (  # noqa: F401
    bench_main,
)
from grasp_tools.bench.external_solvers import (  # noqa: F401
    CLARABEL_TIGHT,
    EXTERNAL_SOLVERS,
    external_solvers,
    ExternalAnswer,
    ExternalSolver,
    general_form,
    run_external,
    SolverInput,
)
from grasp_tools.bench.hands import (  # noqa: F401
    format_hands,
    hand_table,
    HandTicks,
    replay_hands,
)
from grasp_tools.bench.machine import (  # noqa: F401
    fixed_work,
    machine_info,
    noise_floor,
    VERSIONED_PACKAGES,
)
from grasp_tools.bench.node_callbacks import FilterCallbackTimes  # noqa: F401
from grasp_tools.bench.recorded_run import (  # noqa: F401
    LoopRate,
    nominal_loop_rate,
    record_filtered_run,
    runner_loop_rate,
    Scenario,
    Tick,
)
from grasp_tools.bench.replay import (  # noqa: F401
    CERTIFIED,
    COMPONENTS,
    CPU_COMPONENTS,
    DenseQP,
    Replay,
    replay,
    statistics,
)
from grasp_tools.bench.report import (  # noqa: F401
    benchmark,
    CALLBACKS_LABEL,
    format_report,
)
