"""Output directories: the names this package writes into one, and the check before a run.

A run writes only into a directory that is empty, new, or a previous
output of this package, i.e. one holding nothing but :data:`OUTPUT_NAMES` (``bag`` with
only bag files in it, ``summary.json``, ``verdict.json``, the figures, and ``nominal``,
``filtered`` and ``analysis`` directories of the same kind). Anything else, or a symbolic
link in the place of one of them, raises :class:`OutputError` unless ``force`` is given.
The files themselves are written by :func:`grasp_safety_filter.io.files.write_file`
(a temporary file renamed into place: a planted symbolic link is replaced, never followed).
"""

from __future__ import annotations

from pathlib import Path

from grasp_safety_filter.analysis.figures import ANIMATION, FIGURE_FILES
from grasp_safety_filter.io.files import OutputError
from grasp_safety_filter.run_types import MODES

BAG_DIRECTORY = 'bag'
SUMMARY_FILE = 'summary.json'
VERDICT_FILE = 'verdict.json'
ANALYSIS_DIRECTORY = 'analysis'
#: Directories of an output directory that are outputs of their own (``--mode both``,
#: ``grasp-analyze`` next to a run that has a summary).
OUTPUT_SUBDIRECTORIES = (*MODES, ANALYSIS_DIRECTORY)
#: Every name this package writes into an output directory.
OUTPUT_NAMES = (
    BAG_DIRECTORY, SUMMARY_FILE, VERDICT_FILE, *FIGURE_FILES, ANIMATION, *OUTPUT_SUBDIRECTORIES
)
#: Files of a bag directory written by this package's recorder (rosbags) or ``ros2 bag``.
BAG_FILE_SUFFIXES = ('.mcap', '.db3', '.db3-journal', '.db3-wal', '.db3-shm')


def _foreign_entries(directory: Path, inputs: frozenset[Path]) -> list[str]:
    """Entries of ``directory`` that are not outputs of this package (see the module doc)."""
    foreign = []
    for entry in sorted(directory.iterdir()):
        if entry.resolve() in inputs and not entry.is_symlink():
            continue
        if entry.is_symlink():
            foreign.append(f'{entry} (a symbolic link)')
        elif entry.name not in OUTPUT_NAMES:
            foreign.append(str(entry))
        elif entry.name == BAG_DIRECTORY:
            if not entry.is_dir():
                foreign.append(f'{entry} (not a bag directory)')
            else:
                foreign.extend(
                    f'{f} (in a bag)'
                    for f in sorted(entry.iterdir())
                    if f.is_symlink()
                    or not f.is_file()
                    or (f.name != 'metadata.yaml' and not f.name.endswith(BAG_FILE_SUFFIXES))
                )
        elif entry.name in OUTPUT_SUBDIRECTORIES:
            if not entry.is_dir():
                foreign.append(str(entry))
            else:
                foreign.extend(_foreign_entries(entry, inputs))
        elif not entry.is_file():
            foreign.append(str(entry))
    return foreign


def check_output_dir(out_dir: Path, force: bool = False, inputs: tuple[Path, ...] = ()) -> None:
    """Refuse ``out_dir`` unless it is new, empty or a previous output (module doc).

    Args:
        out_dir: The output directory.
        force: Write into it anyway (symbolic links are still replaced, never followed).
        inputs: Paths inside it that are read, not written (the bag ``grasp-analyze`` reads).

    Raises:
        OutputError: Not ours, without ``force``; or it is not a directory.

    """
    out_dir = Path(out_dir)
    if not out_dir.exists():
        if out_dir.is_symlink():
            raise OutputError(f'{out_dir}: a dangling symbolic link, not an output directory')
        return
    if not out_dir.is_dir():
        raise OutputError(f'{out_dir}: exists and is not a directory')
    if force:
        return
    foreign = _foreign_entries(out_dir, frozenset(Path(p).resolve() for p in inputs))
    if foreign:
        shown = ', '.join(foreign[:3]) + (
            f' and {len(foreign) - 3} more' if len(foreign) > 3 else ''
        )
        raise OutputError(
            f'{out_dir}: not an output directory of this package (has {shown}); '
            'choose another or pass --force to write into it'
        )
