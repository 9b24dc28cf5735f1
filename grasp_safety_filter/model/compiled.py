"""How the model's per-tick kernels are compiled: by numba, on first use, cached on disk.

A tick's model terms are a few hundred float operations on arrays of 3 to 60 elements; as
numpy calls, nearly all of their cost is the calls' own overhead. The kernels are plain
loops compiled by numba with ``cache=True``: the machine code is written to disk the first
time a process compiles it (seconds), and later processes load it (a fraction of a second)
instead of compiling again.

numba checks a cached kernel only against the file that defines it, not against the
modules whose functions it inlines or calls: after an update of one of those (a ``git
pull`` in an editable install), it would load stale machine code. So the cache lives in a
directory named after a hash of the package's sources (:func:`source_key`): any change to
them starts a new cache. The directory is under the user's cache directory
(``$XDG_CACHE_HOME`` or ``~/.cache``), or under the system's temporary directory where that
cannot be written (numba's ``config.CACHE_DIR``, set here before any kernel is decorated;
an explicit ``NUMBA_CACHE_DIR`` is left as it is).
"""

from __future__ import annotations

import hashlib
import importlib.util
import os
from pathlib import Path
import tempfile

import numba

#: The packages whose sources key the cache: this one and the simulator's, which compiles
#: with :data:`kernel` too.
SOURCES = tuple(
    Path(location)
    for name in ('grasp_safety_filter', 'hand_sim_node')
    if (spec := importlib.util.find_spec(name)) is not None
    for location in spec.submodule_search_locations or ()
)


def _writable(directory: Path) -> bool:
    """Whether a file can be created in ``directory`` (created if missing), as numba checks."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()
    except OSError:
        return False
    return True


def source_key(packages: tuple[Path, ...] = SOURCES) -> str:
    """Return a short hash of every Python source under ``packages`` (names and contents)."""
    digest = hashlib.sha1()
    for package in packages:
        for path in sorted(package.rglob('*.py')):
            digest.update(str(path.relative_to(package.parent)).encode())
            digest.update(path.read_bytes())
    return digest.hexdigest()[:16]


def cache_directory() -> str | None:
    """Return the kernels' cache directory for these sources; None if ``NUMBA_CACHE_DIR`` is set.

    ``<user cache>/grasp_safety_filter/numba-<source key>`` when it can be written, else the
    same name under the system's temporary directory (with the user's id).
    """
    if numba.config.CACHE_DIR:
        return None
    name = f'numba-{source_key()}'
    user_cache = Path(os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache')
    directory = user_cache / 'grasp_safety_filter' / name
    if _writable(directory):
        return str(directory)
    return str(Path(tempfile.gettempdir()) / f'grasp_safety_filter-{os.getuid()}' / name)


numba.config.CACHE_DIR = cache_directory() or numba.config.CACHE_DIR

#: The kernels' decorator: no Python objects, cached machine code, numpy's float semantics
#: (division by zero gives inf or NaN, as in the numpy code, instead of raising).
kernel = numba.njit(cache=True, error_model='numpy', nogil=True)
#: The same, its body inlined into each compiled caller by numba (a helper whose call would
#: pass many arrays: inlined, their reference counts go too).
inline_kernel = numba.njit(cache=True, error_model='numpy', nogil=True, inline='always')


@kernel
def _first_kernel(x: float) -> float:
    """Return x + 1: a kernel loaded only to set up the runtime (:func:`load_compiled_runtime`)."""
    return x + 1.0


def load_compiled_runtime() -> None:
    """Set up numba's compiler and runtime in this process now, not at its first tick.

    The first cached kernel a process loads sets up LLVM and numba's runtime: about 0.25 s
    of CPU, against some 10 ms for each kernel after it. A node calls this before it
    subscribes, so its first tick costs only its own kernels' loading. Idempotent.
    """
    _first_kernel(0.0)
