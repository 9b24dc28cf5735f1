"""Output directories: nothing outside them is written, nothing foreign in them is lost."""

from __future__ import annotations

import json
from pathlib import Path
import shutil

import pytest

from grasp_safety_filter.cli import analyze_main, demo_main
from grasp_safety_filter.runner import run, RunOptions

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
DEMO = ['--mode', 'filtered', '--duration', '0.01']
OUTSIDE = b'not yours\n'


@pytest.fixture(scope='module')
def source(tmp_path_factory) -> Path:
    """Run a short run into an output directory (bag and summary)."""
    out = tmp_path_factory.mktemp('source')
    run(RunOptions(CONFIG, 'filtered', duration=0.01), out)
    return out


def analyze(source: Path, out: Path, *extra: str) -> int:
    return analyze_main([str(source / 'bag'), '--out', str(out), *extra])


def demo(source: Path, out: Path, *extra: str) -> int:
    return demo_main([*DEMO, '--out', str(out), *extra])


# name of the planted symbolic link in OUT, and the command that writes that name
SYMLINKS = [
    ('summary.json', analyze),
    ('contacts.png', analyze),
    ('torques.png', analyze),
    ('summary.json', demo),
    ('verdict.json', demo),
    ('bag', demo),
]


@pytest.mark.parametrize(('name', 'command'), SYMLINKS)
@pytest.mark.parametrize('force', [False, True])
def test_a_planted_symlink_is_never_followed(source, tmp_path, capsys, name, command, force):
    victim = tmp_path / 'victim'
    if name == 'bag':
        victim.mkdir()
        (victim / 'keep.txt').write_bytes(OUTSIDE)
    else:
        victim.write_bytes(OUTSIDE)
    out = tmp_path / 'out'
    out.mkdir()
    (out / name).symlink_to(victim)
    code = command(source, out, *(['--force'] if force else []))
    err = capsys.readouterr().err
    if force:
        assert code in (0, 1), err  # 1: too short a run to show the paper's outcome
        assert not (out / name).is_symlink()
        assert (out / name).exists()
    else:
        assert code == 2
        assert 'symbolic link' in err and len(err.splitlines()) == 1, err
    if name == 'bag':
        assert (victim / 'keep.txt').read_bytes() == OUTSIDE
        assert [p.name for p in victim.iterdir()] == ['keep.txt']
    else:
        assert victim.read_bytes() == OUTSIDE


FOREIGN = [
    ('notes.txt', analyze),
    ('notes.txt', demo),
    ('bag/notes.txt', demo),
    ('filtered/notes.txt', demo),
]


@pytest.mark.parametrize(('name', 'command'), FOREIGN)
def test_a_directory_with_foreign_files_is_refused_without_force(
    source, tmp_path, capsys, name, command
):
    out = tmp_path / 'out'
    (out / name).parent.mkdir(parents=True)
    (out / name).write_bytes(OUTSIDE)
    assert command(source, out) == 2
    err = capsys.readouterr().err
    assert len(err.splitlines()) == 1 and str(out / name) in err and '--force' in err, err
    assert (out / name).read_bytes() == OUTSIDE
    assert not (out / 'summary.json').exists()


def test_force_writes_beside_foreign_files(source, tmp_path):
    out = tmp_path / 'out'
    out.mkdir()
    (out / 'notes.txt').write_bytes(OUTSIDE)
    assert analyze(source, out, '--force') == 0
    assert (out / 'notes.txt').read_bytes() == OUTSIDE
    assert json.loads((out / 'summary.json').read_text())['mode'] == 'filtered'


def test_a_previous_output_is_replaced_without_force(source, tmp_path):
    out = tmp_path / 'out'
    assert demo(source, out) in (0, 1)
    assert analyze(out, out / 'analysis') == 0
    # Another run, a sqlite3 one, into the same directory: it is ours, analysis/ included.
    assert demo(source, out, '--storage', 'sqlite3') in (0, 1)
    assert list((out / 'bag').glob('*.db3')) and not list((out / 'bag').glob('*.mcap'))


def test_analyze_without_out_keeps_the_runs_summary(source, tmp_path, capsys):
    run_dir = tmp_path / 'run'
    shutil.copytree(source, run_dir)
    summary = json.loads((run_dir / 'summary.json').read_text())
    summary['interrupted'] = 'SIGINT'
    text = json.dumps(summary)
    (run_dir / 'summary.json').write_text(text)
    assert analyze_main([str(run_dir / 'bag')]) == 0
    assert (run_dir / 'summary.json').read_text() == text
    analysis = run_dir / 'analysis'
    assert 'interrupted' not in json.loads((analysis / 'summary.json').read_text())
    assert f'summary: {analysis / "summary.json"}' in capsys.readouterr().out
    # A bag with no summary beside it (as ros2 bag records) is analysed next to it.
    bare = tmp_path / 'bare'
    bare.mkdir()
    shutil.copytree(source / 'bag', bare / 'bag')
    assert analyze_main([str(bare / 'bag')]) == 0
    assert (bare / 'summary.json').is_file() and not (bare / 'analysis').exists()
