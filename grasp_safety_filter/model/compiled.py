"""How the model's per-tick kernels are compiled: by numba, on first use, cached on disk.

A tick's model terms are a few hundred float operations on arrays of 3 to 60 elements; as
numpy calls, nearly all of their cost is the calls' own overhead. The kernels are plain
loops compiled by numba with ``cache=True``: the machine code is written next to the module
(``__pycache__``) the first time a process compiles it (seconds), and later processes load
it (a fraction of a second) instead of compiling again.

Where the package directory cannot be written (an installed, read-only package), numba
writes its cache to the user's cache directory; where neither can be written, to a
directory under the system's temporary directory (numba's ``config.CACHE_DIR``, set here
before any kernel is decorated; an explicit ``NUMBA_CACHE_DIR`` is left as it is).
"""

from __future__ import annotations

import os
from pathlib import Path
import tempfile

import numba


def _writable(directory: Path) -> bool:
    """Whether a file can be created in ``directory`` (created if missing), as numba checks."""
    try:
        directory.mkdir(parents=True, exist_ok=True)
        tempfile.TemporaryFile(dir=directory).close()
    except OSError:
        return False
    return True


def fallback_cache_directory() -> str | None:
    """Return a temporary cache directory if numba's own choices are read-only, else None.

    numba caches in ``config.CACHE_DIR`` (``NUMBA_CACHE_DIR``) when set, else next to the
    source (``__pycache__``), else in the user's cache directory (``$XDG_CACHE_HOME`` or
    ``~/.cache``); with none writable it refuses to decorate a cached function.
    """
    if numba.config.CACHE_DIR:
        return None
    if _writable(Path(__file__).resolve().parent / '__pycache__'):
        return None
    user_cache = Path(os.environ.get('XDG_CACHE_HOME') or Path.home() / '.cache') / 'numba'
    if _writable(user_cache):
        return None
    return str(Path(tempfile.gettempdir()) / f'grasp_safety_filter-numba-{os.getuid()}')


numba.config.CACHE_DIR = fallback_cache_directory() or numba.config.CACHE_DIR

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
