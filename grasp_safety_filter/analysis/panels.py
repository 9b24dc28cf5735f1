"""What every time-series panel of a run's figures shares: thinned lines and the stop mark.

A long run's lines are thinned to their envelope before drawing (:func:`envelope`: each
line's smallest and largest sample in each of ``MAX_POINTS / 2`` time bins), so that
drawing takes the same memory and time however long the run: at the figures' width of
under 1000 pixels nothing visible is lost, spikes (one relaxed tick) included.
"""

from __future__ import annotations

from matplotlib.axes import Axes
import numpy as np

from grasp_safety_filter.analysis.run_data import RunData

#: Most samples drawn per line (a 15 s run at 1 kHz has 15 001).
MAX_POINTS = 4000


def envelope(
    t: np.ndarray, values: np.ndarray, max_points: int | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """Thin a line to at most ``max_points`` samples: each bin's smallest and largest.

    Args:
        t: Sample times, shape (N,), s.
        values: Samples, shape (N,); NaN (no value) is kept only where a bin has nothing else.
        max_points: Most samples returned (>= 2; default :data:`MAX_POINTS`).

    Returns:
        The kept times and values, in time order (the input itself when it is short).

    """
    n = len(t)
    max_points = MAX_POINTS if max_points is None else max(int(max_points), 2)
    if n <= max_points:
        return t, values
    bins = max_points // 2
    width = -(-n // bins)  # ceil: the last bin is the only one with padding
    padded = np.full(bins * width, np.nan)
    padded[:n] = values
    rows = padded.reshape(bins, width)
    low = np.argmin(np.where(np.isnan(rows), np.inf, rows), axis=1)
    high = np.argmax(np.where(np.isnan(rows), -np.inf, rows), axis=1)
    start = np.arange(bins) * width
    kept = np.unique(np.minimum(np.concatenate((start + low, start + high)), n - 1))
    return t[kept], values[kept]


def stop_marker(axes: Axes, run: RunData) -> None:
    """Mark where a run stopped early (nothing for a run that reached its duration)."""
    if run.stop_reason not in (None, 'duration'):
        axes.axvline(run.t_end, color='k', linestyle=':', linewidth=1.0)
