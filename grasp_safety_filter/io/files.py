"""Writing the package's output files: through a temporary file, never through a symlink."""

from __future__ import annotations

import os
from pathlib import Path
import tempfile


class OutputError(ValueError):
    """An output directory that is not this package's to write into (names the entry)."""


def write_file(path: Path, data: str | bytes) -> Path:
    """Write ``path`` through a temporary file renamed into place (a symlink is replaced).

    The rename is atomic: a reader sees the old file or the new one, never half of it, and a
    symbolic link planted at ``path`` is replaced, not followed.

    Raises:
        OutputError: ``path`` is a directory.
    """
    path = Path(path)
    if path.is_dir() and not path.is_symlink():
        raise OutputError(f'{path}: is a directory, expected a file')
    descriptor, temporary = tempfile.mkstemp(dir=path.parent, prefix=f'.{path.name}.')
    try:
        with os.fdopen(descriptor, 'wb') as file:
            file.write(data.encode() if isinstance(data, str) else data)
        os.chmod(temporary, 0o644)
        os.replace(temporary, path)
    except BaseException:
        Path(temporary).unlink(missing_ok=True)
        raise
    return path
