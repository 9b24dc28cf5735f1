"""``grasp-bench --soak SECONDS``: memory and bag growth of a long recorded run, and its analysis.

1. **Run.** The paper's filtered scenario runs in the ROS-free lockstep runner for SECONDS
   simulated seconds, recorded to a bag as ``grasp-demo`` records it. The process's resident
   memory (RSS) is sampled every ``--soak-interval`` simulated seconds; its growth per tick
   is the least-squares slope over the samples after the first tenth of the run (start-up:
   imports, OSQP set-up, the first bag chunk).
2. **Bag.** Its size per simulated second, and each topic's bytes per message (serialised
   CDR, the size a subscriber receives).
3. **Analysis.** ``grasp-analyze`` on the bag in a process of its own: its peak RSS and wall
   time, and the same on the first quarter of the run (a bag of its own), so that the
   analysis's memory growth with the run's length can be read off.

Nothing here asserts a figure: they are for reading.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
import os
from pathlib import Path
import resource
import subprocess
import sys
import tempfile
import time
from typing import Any

import numpy as np
from rosbags.highlevel import AnyReader

from grasp_safety_filter.run_types import RunOptions
from grasp_safety_filter.runner import record_run

#: Fraction of the run left out of the growth fit (start-up allocations).
WARMUP_FRACTION = 0.1


def rss_bytes() -> int:
    """Return this process's resident set size, bytes (Linux ``/proc``; else the peak)."""
    try:
        resident_pages = int(Path('/proc/self/statm').read_text().split()[1])
        return resident_pages * os.sysconf('SC_PAGE_SIZE')
    except (OSError, ValueError, IndexError):
        return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss * 1024


@dataclass(frozen=True)
class RssSample:
    """Resident memory at one moment of the run.

    Attributes:
        t_sim: Simulated time, s.
        wall: Wall-clock time since the run started, s.
        rss: Resident set size, bytes.

    """

    t_sim: float
    wall: float
    rss: int


def growth_per_tick(samples: list[RssSample], time_step: float) -> float | None:
    """Least-squares slope of RSS over ticks after the warm-up, bytes per tick (None: too few)."""
    if not samples:
        return None
    start = samples[-1].t_sim * WARMUP_FRACTION
    kept = [s for s in samples if s.t_sim >= start]
    if len(kept) < 3:
        return None
    ticks = np.array([s.t_sim / time_step for s in kept])
    rss = np.array([s.rss for s in kept], dtype=float)
    slope, _ = np.polyfit(ticks, rss, 1)
    return float(slope)


def bag_bytes(bag: Path) -> int:
    """Return the bytes of a bag directory's files."""
    return sum(path.stat().st_size for path in Path(bag).iterdir() if path.is_file())


def topic_bytes(bag: Path) -> dict[str, dict[str, float]]:
    """Return each topic's message count and mean CDR bytes per message (one streaming pass)."""
    sizes: Counter[str] = Counter()
    counts: Counter[str] = Counter()
    with AnyReader([Path(bag)]) as reader:
        for connection, _, rawdata in reader.messages():
            sizes[connection.topic] += len(rawdata)
            counts[connection.topic] += 1
    return {
        topic: {'messages': counts[topic], 'bytes_per_message': sizes[topic] / counts[topic]}
        for topic in sorted(counts, key=lambda name: -sizes[name])
    }


def analysis_cost(bag: Path, out_dir: Path) -> dict[str, float]:
    """Run ``grasp-analyze BAG --out OUT`` in a process of its own: peak RSS (MB), wall (s).

    Raises:
        RuntimeError: The analysis failed (its stderr in the message).

    """
    code = 'import sys; from grasp_safety_filter.cli import analyze_main; sys.exit(analyze_main())'
    command = [sys.executable, '-c', code, str(bag), '--out', str(out_dir), '--force']
    with tempfile.TemporaryFile('w+') as stderr:
        start = time.perf_counter()
        process = subprocess.Popen(command, stdout=subprocess.DEVNULL, stderr=stderr)
        # wait4 gives this child's own peak RSS (RUSAGE_CHILDREN would be the max of all).
        _, status, usage = os.wait4(process.pid, 0)
        wall = time.perf_counter() - start
        process.returncode = os.waitstatus_to_exitcode(status)
        if process.returncode != 0:
            stderr.seek(0)
            raise RuntimeError(
                f'grasp-analyze {bag} failed ({process.returncode}): {stderr.read().strip()}'
            )
    return {'peak_rss_mb': usage.ru_maxrss / 1024.0, 'wall_s': wall}


def record_with_samples(
    options: RunOptions, bag: Path, interval: float, log: Callable[[str], None]
) -> tuple[list[RssSample], float, float]:
    """Record a run, sampling RSS every ``interval`` simulated s; return samples, t_end, wall."""
    samples: list[RssSample] = []
    start = time.perf_counter()
    next_sample = [0.0]

    def progress(t: float, duration: float) -> None:
        if t + 1e-9 >= next_sample[0]:
            samples.append(RssSample(t, time.perf_counter() - start, rss_bytes()))
            next_sample[0] += interval
            if len(samples) % 10 == 1:
                log(f't = {t:.1f} / {duration:.1f} s, RSS {samples[-1].rss / 1e6:.1f} MB')

    recording = record_run(options, bag, progress)
    return samples, recording.t_end, time.perf_counter() - start


def soak(
    config: Path,
    seconds: float,
    out_dir: Path,
    interval: float = 1.0,
    storage: str = 'mcap',
    overrides: dict[str, Any] | None = None,
    log: Callable[[str], None] = lambda message: None,
) -> dict[str, Any]:
    """Record and analyse a long run into ``out_dir`` (bags replaced); return the figures.

    See the module docstring.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    options = RunOptions(
        config, 'filtered', duration=seconds, storage=storage, overrides=overrides or {}
    )
    bag = out_dir / 'bag'
    log(f'recording {seconds:g} s of the filtered run to {bag}')
    samples, t_end, wall = record_with_samples(options, bag, interval, log)
    time_step = 0.001 if options.time_step is None else options.time_step
    total = bag_bytes(bag)
    log('reading the bag back for its per-topic sizes')
    per_topic = topic_bytes(bag)
    log('analysing the bag, and a bag of the first quarter of the run')
    short_bag = out_dir / 'bag_quarter'
    short = RunOptions(
        config, 'filtered', duration=seconds / 4, storage=storage, overrides=overrides or {}
    )
    record_run(short, short_bag)
    analysis = analysis_cost(bag, out_dir / 'analysis')
    analysis_short = analysis_cost(short_bag, out_dir / 'analysis_quarter')
    rss = [s.rss for s in samples]
    return {
        'seconds': seconds,
        't_end': t_end,
        'ticks': round(t_end / time_step),
        'wall_s': wall,
        'real_time_factor': t_end / wall if wall > 0 else None,
        'rss_samples': [
            {'t_sim': s.t_sim, 'wall_s': s.wall, 'rss_mb': s.rss / 1e6} for s in samples
        ],
        'rss_start_mb': rss[0] / 1e6 if rss else None,
        'rss_end_mb': rss[-1] / 1e6 if rss else None,
        'rss_growth_bytes_per_tick': growth_per_tick(samples, time_step),
        'bag_mb': total / 1e6,
        'bag_mb_per_sim_second': total / 1e6 / t_end if t_end > 0 else None,
        'topics': per_topic,
        'analysis': analysis,
        'analysis_quarter': {**analysis_short, 'seconds': seconds / 4},
    }


def format_soak(document: dict[str, Any]) -> str:
    """Return the soak figures as a few lines of text."""
    growth = document['rss_growth_bytes_per_tick']
    lines = [
        f'soak: {document["t_end"]:.1f} s simulated ({document["ticks"]} ticks) in '
        f'{document["wall_s"]:.0f} s wall (real-time factor {document["real_time_factor"]:.2f})',
        '  RSS (MB) at t_sim (s): '
        + ', '.join(f'{s["t_sim"]:g}: {s["rss_mb"]:.1f}' for s in document['rss_samples']),
        f'  RSS growth after the first {WARMUP_FRACTION:.0%}: '
        + ('n/a' if growth is None else f'{growth:+.1f} B/tick'),
        f'  bag: {document["bag_mb"]:.1f} MB, {document["bag_mb_per_sim_second"]:.2f} MB per '
        'simulated second',
    ]
    for topic, figures in document['topics'].items():
        lines.append(
            f'    {topic:<24} {figures["messages"]:>8} msgs, '
            f'{figures["bytes_per_message"]:8.0f} B/msg'
        )
    quarter = document['analysis_quarter']
    analysis = document['analysis']
    lines.append(
        f'  grasp-analyze: peak RSS {analysis["peak_rss_mb"]:.0f} MB, {analysis["wall_s"]:.1f} s '
        f'wall; on the first {quarter["seconds"]:g} s: {quarter["peak_rss_mb"]:.0f} MB, '
        f'{quarter["wall_s"]:.1f} s'
    )
    return '\n'.join(lines)
