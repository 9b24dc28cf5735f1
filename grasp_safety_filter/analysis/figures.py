"""The paper's figures (Fig. 3 nominal, Fig. 4 filtered) drawn from a run's recorded series.

Contact coordinates and required friction have one line per contact; joint angles and
torques one panel per joint, a row of panels per finger (the hand's joints grouped by
finger, :mod:`grasp_safety_filter.model.fingers`), whatever each finger's joint count.

A long run's lines are thinned to their envelope before drawing
(:func:`~grasp_safety_filter.analysis.panels.envelope`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
import io
from pathlib import Path
from typing import Any

from matplotlib.axes import Axes
from matplotlib.figure import Figure
import numpy as np

from grasp_safety_filter.analysis.forked import ForkedCall
from grasp_safety_filter.analysis.grasp_figures import (
    animation,
    configuration_picture,
    setup_picture,
)
from grasp_safety_filter.analysis.object_figure import object_figure
from grasp_safety_filter.analysis.panels import envelope, stop_marker
from grasp_safety_filter.analysis.run_data import RunData
from grasp_safety_filter.io.files import write_file
from grasp_safety_filter.model.fingers import all_joints, Finger
from grasp_safety_filter.view.scene import SceneBuilder

#: The figures of a run, in :func:`plot_run`'s order (torques only with commands; the object
#: and the grasp in space only with ``/object/odom``, the latter two with the hand's model).
FIGURE_FILES = (
    'contacts.png',
    'joints.png',
    'friction.png',
    'torques.png',
    'object.png',
    'setup.png',
    'configuration.png',
)
INFEASIBLE = {'color': '0.85', 'zorder': 0}
# Symmetric grasps give identical curves; line styles keep each one visible.
LINE_STYLES = ('-', '--', ':', '-.')
#: The figures :func:`plot_run` draws in a forked child while it draws the others
#: (:mod:`~grasp_safety_filter.analysis.forked`): about half of the drawing time.
FORKED_FIGURES = ('joints.png', 'object.png', 'setup.png')
#: The run's animation (:func:`plot_run` with ``animate``).
ANIMATION = 'animation.gif'
#: Most joint panels in a row of the joint and torque figures (a longer finger wraps).
MAX_COLUMNS = 4


def _shade_outside(axes: Axes, low: float, high: float, values: np.ndarray) -> None:
    """Grey out everything below ``low`` and above ``high`` (the paper's infeasible regions)."""
    finite = values[np.isfinite(values)]
    span = max(high - low, 1e-9)
    bottom = min(low - 0.15 * span, finite.min() if finite.size else low)
    top = max(high + 0.15 * span, finite.max() if finite.size else high)
    axes.axhspan(bottom, low, **INFEASIBLE)
    axes.axhspan(high, top, **INFEASIBLE)
    axes.set_ylim(bottom, top)


def plot_contacts(run: RunData, path: Path) -> Path:
    """Plot contact coordinates a and b on each fingertip, the fingertip workspace unshaded."""
    a_min, a_max, b_min, b_max = run.fingertip_workspace
    figure = Figure(figsize=(7, 6))
    (axes_a, axes_b) = figure.subplots(2, 1, sharex=True)
    for i, name in enumerate(run.contact_names):
        style = LINE_STYLES[i % len(LINE_STYLES)]
        axes_a.plot(*envelope(run.t, run.xi_cf[:, i, 0]), style, label=name)
        axes_b.plot(*envelope(run.t, run.xi_cf[:, i, 1]), style, label=name)
    _shade_outside(axes_a, a_min, a_max, run.xi_cf[:, :, 0])
    _shade_outside(axes_b, b_min, b_max, run.xi_cf[:, :, 1])
    axes_a.set_ylabel('$a_{cf,i}$ [rad]')
    axes_b.set_ylabel('$b_{cf,i}$ [rad]')
    axes_b.set_xlabel('t [s]')
    axes_a.legend(loc='best')
    for axes in (axes_a, axes_b):
        stop_marker(axes, run)
    axes_a.set_title(f'{run.mode}: contact coordinates (grey: outside the fingertip workspace)')
    return _save(figure, path)


def _finger_rows(fingers: Sequence[Finger]) -> list[tuple[str, tuple[int, ...]]]:
    """Lay out a row of panels per finger: label and joints, at most :data:`MAX_COLUMNS` a row.

    A finger with more joints continues on the next rows, labelled ``"<finger> (cont.)"``; a
    finger that touches nothing is labelled ``"<branch> (free)"``.
    """
    rows = []
    for finger in fingers:
        name = f'{finger.label} (free)' if finger.free else finger.label
        for start in range(0, len(finger.joints), MAX_COLUMNS):
            label = name if start == 0 else f'{name} (cont.)'
            rows.append((label, finger.joints[start : start + MAX_COLUMNS]))
    return rows


def _finger_grid(
    fingers: Sequence[Finger], ylabel: str
) -> tuple[Figure, list[list[tuple[Axes, int]]]]:
    """Make a figure of one row of panels per finger (:func:`_finger_rows`), one per joint.

    Returns:
        The figure and, per row, each panel with its joint's index; unused cells hidden.
        Each row's first panel is labelled with the finger and ``ylabel``.

    """
    rows = _finger_rows(fingers)
    columns = max(len(joints) for _, joints in rows)
    figure = Figure(figsize=(2.2 + 2.6 * columns, 0.6 + 2.0 * len(rows)))
    grid = np.atleast_2d(figure.subplots(len(rows), columns, sharex=True, squeeze=False))
    panels = []
    for (label, joints), axes_row in zip(rows, grid, strict=True):
        for axes in axes_row[len(joints) :]:
            axes.set_visible(False)
        axes_row[0].set_ylabel(f'{label}\n{ylabel}')
        panels.append(list(zip(axes_row, joints, strict=False)))
    for column in range(columns):
        # Time ticks under the lowest panel of each column (a short finger leaves gaps).
        lowest = max(row for row, (_, joints) in enumerate(rows) if column < len(joints))
        grid[lowest][column].xaxis.set_tick_params(labelbottom=True)
    for axes_row in grid:
        for axes in axes_row:
            axes.tick_params(labelsize='small')
    figure.supxlabel('t [s]')
    return figure, panels


def _joint_title(axes: Axes, name: str) -> None:
    # On the right: the y axis's scale factor (1e-5) takes the top left corner.
    axes.set_title(name, fontsize='small', loc='right')


def plot_joints(run: RunData, path: Path, fingers: Sequence[Finger] | None = None) -> Path:
    """Plot :func:`joints_figure` to ``path``."""
    return _save(joints_figure(run, fingers), path)


def joints_figure(run: RunData, fingers: Sequence[Finger] | None = None) -> Figure:
    """Draw each joint's angle in its finger's row, with its limits (grey beyond)."""
    by = 'by finger' if fingers is not None else 'in command order (fingers not known)'
    fingers = all_joints(run.joint_names) if fingers is None else fingers
    figure, panels = _finger_grid(fingers, 'q [rad]')
    for row in panels:
        for axes, j in row:
            axes.plot(*envelope(run.t, run.q[:, j]), color='C0')
            low, high = run.joint_lower_limits[j], run.joint_upper_limits[j]
            _shade_outside(axes, float(low), float(high), run.q[:, j])
            _joint_title(axes, run.joint_names[j])
            stop_marker(axes, run)
    figure.suptitle(f'{run.mode}: joint angles {by} (grey: beyond the joint limits)')
    return figure


def plot_friction(run: RunData, path: Path) -> Path:
    """Plot the required friction beta_i against mu_i (grey: slip).

    With one mu for every contact, the grey band above it is slip for all of them. With a
    mu_i per contact, each contact's own mu_i is drawn dashed in its colour, and the band
    starts at the largest mu_i: above it every contact slips. Soft fingers' torsions are
    drawn as wide pale lines in their contact's colour, in the same units: ``mu_i |tau_i| / (mu_t,i
    f_n,i)``, above mu_i exactly when ``|tau_i| > mu_t,i f_n,i`` (the event monitor's slip).
    """
    figure = Figure(figsize=(7, 3.5))
    axes = figure.subplots()
    beta = np.where(np.isfinite(run.required_friction), run.required_friction, np.nan)
    mu = run.mu_per_contact
    shared = bool(np.all(mu == mu[0]))
    spin = torsion_in_friction_units(run)
    for i, name in enumerate(run.contact_names):
        (line,) = axes.plot(
            *envelope(run.t, beta[:, i]), LINE_STYLES[i % len(LINE_STYLES)], label=name
        )
        if spin is not None:
            axes.plot(
                *envelope(run.t, spin[:, i]),
                color=line.get_color(),
                linewidth=3.0,
                alpha=0.4,
                label=f'{name} torsion',
            )
        if not shared:
            axes.axhline(
                mu[i],
                color=line.get_color(),
                linestyle='--',
                linewidth=1.0,
                label=f'$\\mu$ of {name} = {mu[i]:g}',
            )
    highest = float(mu.max())
    drawn = beta if spin is None else np.concatenate((beta, spin), axis=1)
    top = max(1.5 * highest, float(np.nanmax(drawn)) * 1.05 if np.isfinite(drawn).any() else 0.0)
    axes.axhspan(highest, top, **INFEASIBLE)
    if shared:
        axes.axhline(highest, color='k', linewidth=1.0, label=f'$\\mu$ = {highest:g}')
    axes.set_ylim(0.0, top)
    axes.set_xlabel('t [s]')
    torsion_label = '$\\beta_i$; torsion: $\\mu_i |\\tau_i| / (\\mu_{t,i} f_{n,i})$'
    axes.set_ylabel('$\\beta_i$' if spin is None else torsion_label)
    axes.legend(loc='best')
    stop_marker(axes, run)
    title = 'grey: slip' if shared else "dashed: each contact's mu; grey: above every mu"
    axes.set_title(f'{run.mode}: required friction ({title})')
    return _save(figure, path)


def torsion_in_friction_units(run: RunData) -> np.ndarray | None:
    """``mu_i |tau_i| / (mu_t,i f_n,i)`` per sample and contact, (K, n); None: point contacts.

    NaN where the contact separates (``f_n <= 0``), as its beta is drawn.
    """
    mu_t = run.torsional_friction_per_contact
    if run.torsion is None or mu_t is None:
        return None
    normal = run.force[:, :, 2]
    positive = normal > 0.0
    ratio = np.abs(run.torsion) / (mu_t * np.where(positive, normal, 1.0))
    return np.where(positive, run.mu_per_contact * ratio, np.nan)


def plot_torques(run: RunData, path: Path, fingers: Sequence[Finger] | None = None) -> Path:
    """Plot :func:`torques_figure` to ``path``."""
    return _save(torques_figure(run, fingers), path)


def torques_figure(run: RunData, fingers: Sequence[Finger] | None = None) -> Figure:
    """Draw the commanded torque u* and the nominal u_nom, per joint in its finger's row."""
    by = 'by finger' if fingers is not None else 'in command order (fingers not known)'
    fingers = all_joints(run.joint_names) if fingers is None else fingers
    figure, panels = _finger_grid(fingers, 'torque [N m]')
    t = run.t_command
    for row in panels:
        for axes, j in row:
            axes.plot(*envelope(t, run.u_nominal[:, j]), color='0.5')
            axes.plot(*envelope(t, run.u_command[:, j]), color='C3', linewidth=1.0)
            _joint_title(axes, run.joint_names[j])
            stop_marker(axes, run)
    figure.suptitle(
        f'{run.mode}: joint torques {by}\n(grey: nominal $u_{{nom}}$, red: commanded $u^*$)'
    )
    return figure


def plot_run(
    run: RunData,
    out_dir: Path,
    fingers: Sequence[Finger] | None = None,
    model: Any | None = None,
    animate: bool = False,
) -> list[Path]:
    """Draw every figure of a run into ``out_dir``; return their paths.

    Args:
        run: The run.
        out_dir: Where the figures go.
        fingers: The hand's joints by finger (:mod:`grasp_safety_filter.model.fingers`), one
            row of joint panels each; None: one group of every joint, in rows of
            :data:`MAX_COLUMNS` (a bag analysed without its hand model).
        model: The run's :class:`~grasp_safety_filter.model.grasp_model.GraspModel`, for the
            grasp in space (:mod:`~grasp_safety_filter.analysis.grasp_figures`); None: not
            drawn.
        animate: With the model, also ``animation.gif`` (after the figures, on both cores).

    """
    out_dir.mkdir(parents=True, exist_ok=True)
    drawings: dict[str, Callable[[], Path | None]] = {
        'contacts.png': lambda: plot_contacts(run, out_dir / 'contacts.png'),
        'joints.png': lambda: plot_joints(run, out_dir / 'joints.png', fingers),
        'friction.png': lambda: plot_friction(run, out_dir / 'friction.png'),
    }
    if run.t_command.size:
        drawings['torques.png'] = lambda: plot_torques(run, out_dir / 'torques.png', fingers)
    if run.tracking is not None:
        drawings['object.png'] = lambda: _save(object_figure(run), out_dir / 'object.png')
        if model is not None:
            builder = SceneBuilder(model)
            drawings['setup.png'] = lambda: _save(
                setup_picture(run, builder), out_dir / 'setup.png', tight=False
            )
            drawings['configuration.png'] = lambda: _save(
                configuration_picture(run, builder), out_dir / 'configuration.png', tight=False
            )
    # Two halves of about the same drawing time, one in a forked child (FORKED_FIGURES).
    forked = [name for name in drawings if name in FORKED_FIGURES]
    paths: dict[str, Path | None] = {}
    failed = False
    with ForkedCall(lambda: [drawings[name]() for name in forked]) as child:
        try:
            paths.update((name, draw()) for name, draw in drawings.items() if name not in forked)
            paths.update(zip(forked, child.result(), strict=True))
        except Exception:  # ForkedCallError, or a figure failed
            failed = True
    if failed:  # the child stopped: all again, in order (the same files or error)
        paths = {name: draw() for name, draw in drawings.items()}
    if animate and 'setup.png' in drawings:
        paths[ANIMATION] = animation(run, builder, out_dir / ANIMATION)
        drawings[ANIMATION] = lambda: None
    return [path for name in drawings if (path := paths[name]) is not None]


def _save(figure: Figure | None, path: Path, tight: bool = True) -> Path | None:
    # Figure without pyplot: no GUI backend, no global state, works headless. Written
    # through a temporary file: a symbolic link at ``path`` is replaced, not followed.
    # None: a figure that cannot be drawn of this run; a previous run's file goes.
    if figure is None:
        path.unlink(missing_ok=True)
        return None
    if tight:
        figure.tight_layout()
    png = io.BytesIO()
    figure.savefig(png, dpi=120, format='png')
    return write_file(path, png.getvalue())
