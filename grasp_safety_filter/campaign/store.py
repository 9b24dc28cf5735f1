"""A campaign's results on disk: one line per finished run, written as it finishes.

``DIR/results.jsonl`` is appended to and flushed to disk run by run, so a campaign stopped
in any way (Ctrl-C, a killed process, a dead scheduler) keeps every run that finished; a
line cut short by the stop is ignored and that run is run again. ``DIR/runs.csv`` is the
table of the campaign's runs, in campaign order, written from it.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping, Sequence
import csv
import json
import os
from pathlib import Path
from typing import Any

from grasp_safety_filter.campaign.run import COST_COLUMNS, identity, OUTCOME_COLUMNS
from grasp_safety_filter.campaign.spec import Campaign, RunSpec

RESULTS_FILE = 'results.jsonl'
TABLE_FILE = 'runs.csv'
CAMPAIGN_COPY = 'campaign.yaml'


class ResultStore:
    """The finished runs of a campaign directory, by run key."""

    def __init__(self, directory: Path) -> None:
        self.directory = Path(directory)
        self.path = self.directory / RESULTS_FILE
        self.finished: dict[str, dict[str, Any]] = {}
        if self.path.is_file():
            for line in self.path.read_text().splitlines():
                try:
                    row = json.loads(line)
                except json.JSONDecodeError:
                    continue  # cut short by a stop: that run is run again
                if isinstance(row, dict) and 'key' in row:
                    self.finished[row['key']] = row

    def append(self, row: Mapping[str, Any]) -> None:
        """Keep a finished run: on disk before this returns."""
        self.directory.mkdir(parents=True, exist_ok=True)
        text = json.dumps(dict(row), default=str)
        with self.path.open('a') as file:
            if file.tell() > 0 and not _ends_with_newline(self.path):
                file.write('\n')  # after a line cut short by a stop
            file.write(text + '\n')
            file.flush()
            os.fsync(file.fileno())
        self.finished[row['key']] = dict(row)

    def rows(self, runs: Sequence[RunSpec]) -> list[dict[str, Any]]:
        """Return the finished rows of ``runs``, in campaign order, with their identity now."""
        return [
            {**self.finished[run.key], **identity(run)} for run in runs if run.key in self.finished
        ]


def _ends_with_newline(path: Path) -> bool:
    with path.open('rb') as file:
        file.seek(-1, os.SEEK_END)
        return file.read(1) == b'\n'


def table_columns(campaign: Campaign) -> list[str]:
    """Return the table's columns: identity, what varied, outcome, cost."""
    return [
        'index', 'key', 'mode', 'sample', 'cell',
        *campaign.varied_columns, *OUTCOME_COLUMNS, *COST_COLUMNS,
    ]  # fmt: skip


def write_table(path: Path, columns: Sequence[str], rows: Iterable[Mapping[str, Any]]) -> None:
    """Write ``rows`` as CSV (empty cells for None)."""
    with Path(path).open('w', newline='') as file:
        writer = csv.DictWriter(file, fieldnames=list(columns), extrasaction='ignore')
        writer.writeheader()
        for row in rows:
            writer.writerow({k: '' if row.get(k) is None else row[k] for k in columns})


def read_table(path: Path) -> list[dict[str, str]]:
    """Read a ``runs.csv`` back (cells as text)."""
    with Path(path).open(newline='') as file:
        return list(csv.DictReader(file))
