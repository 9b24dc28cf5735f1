"""The compiled kernels' disk cache: where numba writes it, and that a new process loads it."""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys
import tempfile

import numba
import pytest

from grasp_safety_filter.model import compiled

REPO = Path(__file__).resolve().parent.parent
#: A process computing one paper state and printing its kernels' cache hits and compilations.
ONE_STATE = """
from grasp_states import paper_model, Q_PAPER, P_OBJECT_PAPER
import numpy as np
from grasp_safety_filter.model import packed_terms
for overrides in ({}, {'model.object.shape': 'sphere', 'model.object.size': 0.3}):
    model = paper_model(**overrides)
    model.state(0.0, Q_PAPER, np.zeros(9), P_OBJECT_PAPER, np.eye(3), np.zeros(6))
# The terms in one pass on the cube and on a sphere (the kernels they call are compiled
# into them).
import numba
kernels = (packed_terms.sphere_on_plane_terms, packed_terms.sphere_on_sphere_terms)
print(sum(sum(k.stats.cache_hits.values()) for k in kernels),
      sum(sum(k.stats.cache_misses.values()) for k in kernels), numba.config.CACHE_DIR)
"""


@pytest.mark.parametrize(
    ('explicit', 'user_writable', 'expected'),
    [
        ('/some/dir', False, None),  # NUMBA_CACHE_DIR given: numba's own choice
        ('', True, 'user'),  # the user's cache directory
        ('', False, 'temporary'),  # not writable: a directory under the temporary one
    ],
)
def test_the_cache_is_the_users_or_a_temporary_directory_named_after_the_sources(
    monkeypatch, explicit, user_writable, expected
):
    monkeypatch.setattr(numba.config, 'CACHE_DIR', explicit)
    monkeypatch.setenv('XDG_CACHE_HOME', '/user-cache')
    monkeypatch.setattr(compiled, '_writable', lambda directory: user_writable)
    found = compiled.cache_directory()
    if expected is None:
        assert found is None
        return
    name = f'numba-{compiled.source_key()}'
    if expected == 'user':
        assert Path(found) == Path('/user-cache/grasp_safety_filter') / name
    else:
        assert Path(found).name == name
        assert Path(found).parent.parent == Path(tempfile.gettempdir())
        assert str(os.getuid()) in Path(found).parent.name


def test_any_change_to_the_sources_names_a_new_cache(tmp_path):
    """A helper a kernel inlines counts too: numba checks a kernel against its own file only."""
    package = tmp_path / 'grasp_safety_filter'
    (package / 'model').mkdir(parents=True)
    kernel, helper = package / 'model' / 'terms.py', package / 'model' / 'inlined.py'
    kernel.write_text('def terms(x):\n    return helper(x)\n')
    helper.write_text('def helper(x):\n    return x + 1.0\n')
    first = compiled.source_key((package,))
    assert compiled.source_key((package,)) == first
    helper.write_text('def helper(x):\n    return x + 2.0\n')
    assert compiled.source_key((package,)) != first
    assert len(first) == 16
    assert {p.name for p in compiled.SOURCES} == {'grasp_safety_filter', 'hand_sim_node'}


def test_a_second_process_loads_the_kernels_from_the_cache_instead_of_compiling():
    """The sources' own cache: whatever the first process finds there, the second compiles nothing.

    The first process compiles what is not cached yet (nothing when earlier tests did) and
    writes it where :func:`compiled.cache_directory` says (the user's cache here); the second
    loads both kernels.
    """
    env = {
        key: value for key, value in os.environ.items() if key != 'NUMBA_CACHE_DIR'
    } | {'PYTHONPATH': os.pathsep.join([str(REPO / 'test'), str(REPO)])}
    runs = [
        subprocess.run(
            [sys.executable, '-c', ONE_STATE], env=env, capture_output=True, text=True, check=True
        ).stdout.split()
        for _ in range(2)
    ]
    (first_hits, first_compiled, directory), (second_hits, second_compiled, _) = runs
    assert int(first_hits) + int(first_compiled) == 2
    assert (int(second_hits), int(second_compiled)) == (2, 0)
    assert Path(directory).name == f'numba-{compiled.source_key()}'
    assert any(Path(directory).rglob('*.nbi')) and any(Path(directory).rglob('*.nbc'))
