"""``grasp-analyze`` on bad input: one line on stderr naming the problem, exit status 2."""

from __future__ import annotations

from collections.abc import Callable
import json
from pathlib import Path
import shutil

import pytest
from rosbags.rosbag2 import Reader, StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores

from grasp_safety_filter.cli import analyze_main
from grasp_safety_filter.io import topics
from grasp_safety_filter.runner import run, RunOptions

REPO = Path(__file__).resolve().parent.parent
CONFIG = REPO / 'config' / 'paper_scenario.yaml'
TYPESTORE = get_typestore(Stores.ROS2_JAZZY)
String = TYPESTORE.types['std_msgs/msg/String']

# (topic, msgtype, cdr) -> the record to write instead, or None to leave it out.
Edit = Callable[[str, str, bytes], 'tuple[str, str, bytes] | None']


@pytest.fixture(scope='module')
def bags(tmp_path_factory) -> dict[str, Path]:
    """Short runner bags, mcap and sqlite3."""
    return {
        storage: run(
            RunOptions(CONFIG, 'filtered', duration=0.02, storage=storage),
            tmp_path_factory.mktemp(storage),
        ).bag
        for storage in ('mcap', 'sqlite3')
    }


def copy_bag(source: Path, target: Path, edit: Edit) -> None:
    """Copy a bag to mcap, each record through ``edit``."""
    with Reader(source) as reader:
        records = [(c.topic, c.msgtype, bytes(d)) for c, _, d in reader.messages()]
        stamps = [t for _, t, _ in reader.messages()]
    with Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {}
        for (topic, msgtype, data), stamp in zip(records, stamps, strict=True):
            edited = edit(topic, msgtype, data)
            if edited is None:
                continue
            key = edited[:2]
            if key not in connections:
                connections[key] = writer.add_connection(*key, typestore=TYPESTORE)
            writer.write(connections[key], stamp, edited[2])


def scenario_edit(change: Callable[[dict], str]) -> Edit:
    """Replace the scenario document by ``change(document)`` (the new JSON text)."""

    def edit(topic: str, msgtype: str, data: bytes) -> tuple[str, str, bytes]:
        if topic != topics.SCENARIO:
            return topic, msgtype, data
        document = json.loads(TYPESTORE.deserialize_cdr(data, msgtype).data)
        text = change(document)
        return topic, msgtype, bytes(TYPESTORE.serialize_cdr(String(data=text), msgtype))

    return edit


def with_values(**values) -> Edit:
    return scenario_edit(lambda document: json.dumps({**document, **values}))


def with_derived(derive: Callable[[dict], dict]) -> Edit:
    """Replace keys by values computed from the original document."""
    return scenario_edit(lambda document: json.dumps({**document, **derive(document)}))


def empty_workspace(document: dict) -> dict:
    box = document['fingertip_workspace']
    return {'fingertip_workspace': {**box, 'a_max': box['a_min']}}


def nan_duration(document: dict) -> str:
    return json.dumps(document).replace('"duration": 0.02', '"duration": NaN')


def truncated(storage: str, suffix: str) -> Callable[[dict[str, Path], Path], None]:
    def build(bags: dict[str, Path], target: Path) -> None:
        shutil.copytree(bags[storage], target)
        (data,) = target.glob(f'*.{suffix}')
        data.write_bytes(data.read_bytes()[: data.stat().st_size // 2])

    return build


def copied(edit: Edit) -> Callable[[dict[str, Path], Path], None]:
    return lambda bags, target: copy_bag(bags['mcap'], target, edit)


def random_bytes(bags: dict[str, Path], target: Path) -> None:
    target.mkdir()
    (target / 'metadata.yaml').write_bytes(bytes(range(256)) * 4)
    (target / 'bag_0.mcap').write_bytes(bytes(range(255, -1, -1)) * 64)


def unrelated(bags: dict[str, Path], target: Path) -> None:
    with Writer(target, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection('/chatter', String.__msgtype__, typestore=TYPESTORE)
        for i in range(3):
            data = TYPESTORE.serialize_cdr(String(data=f'hello {i}'), String.__msgtype__)
            writer.write(connection, i, bytes(data))


CASES = {
    'missing path': (lambda bags, target: None, 'does not exist'),
    'a file': (lambda bags, target: target.write_bytes(b'\x00' * 64), 'is not a directory'),
    'empty directory': (lambda bags, target: target.mkdir(), 'not a readable rosbag2 bag'),
    'random bytes': (random_bytes, 'not a readable rosbag2 bag'),
    'truncated mcap': (truncated('mcap', 'mcap'), 'not a readable rosbag2 bag'),
    'truncated sqlite': (truncated('sqlite3', 'db3'), 'not a readable rosbag2 bag'),
    'unrelated topics': (unrelated, f'no messages on {topics.SCENARIO}'),
    'no scenario': (
        copied(lambda t, m, d: None if t == topics.SCENARIO else (t, m, d)),
        f'no messages on {topics.SCENARIO}',
    ),
    'scenario of another type': (
        copied(
            lambda t, m, d: (
                (t, 'std_msgs/msg/Int32', b'\x00\x01\x00\x00\x05\x00\x00\x00')
                if t == topics.SCENARIO
                else (t, m, d)
            )
        ),
        f'{topics.SCENARIO} has type std_msgs/msg/Int32',
    ),
    'undecodable contacts': (
        copied(lambda t, m, d: (t, m, d[:6]) if t == topics.CONTACTS else (t, m, d)),
        'not a readable rosbag2 bag',
    ),
    'deeply nested scenario': (
        copied(scenario_edit(lambda document: '[' * 100_000 + ']' * 100_000)),
        'nested too deeply',
    ),
    'scenario not JSON': (copied(scenario_edit(lambda document: '{"a": ')), 'invalid JSON'),
    'NaN duration': (
        copied(scenario_edit(nan_duration)),
        'NaN is not a JSON number',
    ),
    'time step 0': (copied(with_values(time_step=0.0)), "'time_step': expected a finite"),
    'negative time step': (copied(with_values(time_step=-0.001)), "'time_step'"),
    'friction 1e308': (copied(with_values(friction_coefficient=1e308)), "'friction_coefficient'"),
    'friction 0': (copied(with_values(friction_coefficient=0.0)), "'friction_coefficient'"),
    'duration 1e308': (copied(with_values(duration=1e308)), "'duration': expected at most"),
    'reversed joint limits': (
        copied(with_derived(lambda d: {'joint_lower_limits': d['joint_upper_limits']})),
        "'joint_lower_limits': expected each below",
    ),
    'zero effort limit': (
        copied(with_derived(lambda d: {'effort_limits': [0.0] * len(d['effort_limits'])})),
        "'effort_limits'",
    ),
    'empty workspace': (
        copied(with_derived(empty_workspace)),
        "'fingertip_workspace': expected finite a_min < a_max",
    ),
    'n_steps off': (copied(with_values(n_steps=7)), "'n_steps'"),
    'unknown integrator': (copied(with_values(integrator='euler')), "'integrator'"),
    'duplicate contact names': (
        copied(with_derived(lambda d: {'contact_names': d['contact_names'][:1] * 2})),
        "'contact_names': expected distinct names",
    ),
}


@pytest.mark.parametrize('case', list(CASES))
def test_bad_input_gives_one_line_and_status_2(case, bags, tmp_path, capsys):
    build, message = CASES[case]
    bag = tmp_path / 'input'
    build(bags, bag)
    out = tmp_path / 'out'
    assert analyze_main([str(bag), '--out', str(out)]) == 2
    captured = capsys.readouterr()
    lines = captured.err.splitlines()
    assert len(lines) == 1, captured.err
    assert lines[0].startswith(f'grasp-analyze: {bag}'), lines[0]
    assert message in lines[0]
    assert not (out / 'summary.json').exists()


def test_the_unedited_copy_is_analysed(bags, tmp_path):
    """The copies above differ from a good bag only by their edit."""
    copy_bag(bags['mcap'], tmp_path / 'copy', lambda t, m, d: (t, m, d))
    assert analyze_main([str(tmp_path / 'copy'), '--out', str(tmp_path / 'out')]) == 0
    assert json.loads((tmp_path / 'out' / 'summary.json').read_text())['completed']
