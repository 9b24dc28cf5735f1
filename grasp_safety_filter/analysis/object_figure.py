"""``object.png``: the object's pose against the reference the nominal controller tracked.

Four panels over time, palm frame: position x, y, z (m) and yaw (rad, ZYX Euler, unwrapped
over time), the object in colour and the reference dashed black. The title gives the RMS
tracking errors (:mod:`~grasp_safety_filter.analysis.tracking`); a bag without
``/object/reference_sample`` draws the object alone and says "no reference recorded".
"""

from __future__ import annotations

from matplotlib.axes import Axes
from matplotlib.figure import Figure

from grasp_safety_filter.analysis.panels import envelope, stop_marker
from grasp_safety_filter.analysis.run_data import RunData
from grasp_safety_filter.analysis.tracking import NO_REFERENCE, unwrapped_euler

#: The panels, top to bottom: label and unit.
OBJECT_PANELS: tuple[tuple[str, str], ...] = (
    ('x', 'm'),
    ('y', 'm'),
    ('z', 'm'),
    ('yaw', 'rad'),
)
#: Smallest vertical span per unit: a coordinate that stays put (rounding noise of 1e-16 m)
#: is drawn flat instead of magnified to fill the panel.
MIN_SPAN = {'m': 1e-3, 'rad': 1e-2}


def object_figure(run: RunData) -> Figure:
    """Draw the object pose and its reference (module docstring).

    Raises:
        ValueError: The run has no object pose (no ``/object/odom`` in its bag).

    """
    tracking = run.tracking
    if tracking is None:
        raise ValueError('object figure: the run has no /object/odom samples')
    figure = Figure(figsize=(7, 8))
    panels = figure.subplots(len(OBJECT_PANELS), 1, sharex=True)
    object_series = [tracking.p_object_in_palm[:, k] for k in range(3)]
    object_series.append(unwrapped_euler(tracking.R_object_to_palm)[:, 2])
    reference_series = [tracking.p_reference_in_palm[:, k] for k in range(3)]
    reference_series.append(unwrapped_euler(tracking.R_reference_to_palm)[:, 2])
    for axes, (label, unit), values, reference in zip(
        panels, OBJECT_PANELS, object_series, reference_series, strict=True
    ):
        axes.plot(*envelope(tracking.t, values), color='C0', label='object')
        if tracking.has_reference:
            axes.plot(
                *envelope(tracking.t_reference, reference),
                color='k',
                linestyle='--',
                linewidth=1.0,
                label='reference',
            )
        axes.set_ylabel(f'{label} [{unit}]')
        _at_least(axes, MIN_SPAN[unit])
        stop_marker(axes, run)
    panels[0].legend(loc='best')
    panels[-1].set_xlabel('t [s]')
    summary = tracking.summary()
    if tracking.has_reference:
        detail = 'RMS error: position {:.3g} m, orientation {:.3g} rad'.format(
            summary['position_error_m']['rms'], summary['orientation_error_rad']['rms']
        )
    else:
        detail = NO_REFERENCE
    figure.suptitle(f'{run.mode}: object pose in the palm frame vs reference\n({detail})')
    return figure


def _at_least(axes: Axes, span: float) -> None:
    """Widen the panel's vertical range to ``span`` around its middle if it is narrower."""
    low, high = axes.get_ylim()
    if high - low < span:
        middle = 0.5 * (low + high)
        axes.set_ylim(middle - 0.5 * span, middle + 0.5 * span)
