"""The results table of a sweep, ``DIR/results.parquet``: one row per finished run, the SPEC's
description in its metadata (columns: docs/usage.md). It is rewritten whole into a temporary
file renamed over it, so it is always complete and readable, also after a crash.
"""

from __future__ import annotations

import json
import os
import pathlib
from typing import Any

import pyarrow as pa
import pyarrow.parquet as pq

from iceskate_sim.run.metrics import metric_ratio
from iceskate_sim.shutdown import StopRequest
from iceskate_study.errors import StudyRefused
from iceskate_study.spec import RUN_COLUMNS, Point, Points, Spec, polled

RESULTS = 'results.parquet'
#: Rows of a table read (and checked) between two looks at the stop request.
READ_BATCH = 4096
METADATA_KEY = b'iceskate_study'
#: Columns that measure time, which differ between two sweeps of the same SPEC.
TIMING_COLUMNS = ('worker_time_s', 'wall_time_s', 'real_time_factor')


def read_table(path: pathlib.Path) -> tuple[pa.Table, dict[str, Any]]:
    """A results table and the SPEC description in its metadata."""
    try:
        table = pq.read_table(path)
    except (OSError, pa.ArrowException) as exc:
        raise StudyRefused(f'cannot read the results table {path}: {exc}') from None
    meta = (table.schema.metadata or {}).get(METADATA_KEY)
    if meta is None:
        raise StudyRefused(f'{path} is not the results table of a sweep (no '
                           f'{METADATA_KEY.decode()} metadata)')
    return table, json.loads(meta)


class ResultTable:
    """The rows of a sweep of ``spec`` over ``points``, kept in ``DIR/results.parquet``.

    Rows already in the file are kept (a resumed sweep); a row whose key is not the key of the
    run at its point and repeat means the folder holds another sweep, which is refused.

    :param stop: its signal ends the reading of the rows (``RunInterrupted``).
    """

    def __init__(self, out: pathlib.Path, spec: Spec, points: Points,
                 stop: StopRequest | None = None) -> None:
        self.path = out / RESULTS
        self.spec = spec
        self.rows: dict[str, dict[str, Any]] = {}
        #: (point, repeat) of every row
        self.done: set[tuple[int, int]] = set()
        table = read_table(self.path)[0] if self.path.exists() else None
        missing = [] if table is None else [
            name for name in RUN_COLUMNS[:4] if name not in table.column_names]
        if missing:  # e.g. edited by hand: its rows cannot say which runs are done
            raise StudyRefused(f"{self.path} lacks the column {missing[0]!r} of a sweep's results "
                               'table (edited?); restore it or choose a new --out')
        batches = table.to_batches(READ_BATCH) if table is not None else []
        for batch in polled(batches, stop):
            for row in batch.to_pylist():
                at = (row.get('point'), row.get('repeat'))
                if not (all(isinstance(i, int) and i >= 0 for i in at) and at[0] < points.count
                        and at[1] < spec.repeats
                        and points[at[0] * spec.repeats + at[1]].key == row.get('key')):
                    raise StudyRefused(f'{self.path} holds runs this SPEC does not make (another '
                                       'SPEC, or the base scene changed); choose a new --out')
                self.rows[row['key']] = {k: v for k, v in row.items() if v is not None}
                self.done.add(at)
        #: the table's metadata, the SPEC's description (made once: an axis may have a
        #: million values)
        self._metadata = {METADATA_KEY: json.dumps(spec.description_for_table(), default=str)}
        self.dirty = False

    def add(self, point: Point, row: dict[str, Any]) -> None:
        """Record the row of ``point``'s finished run."""
        row = {k: v for k, v in row.items() if v is not None}
        if 'run_dir' in row:  # relative to the sweep's folder
            row['run_dir'] = os.path.relpath(row['run_dir'], self.path.parent)
        self.rows[row['key']] = {'key': point.key, 'point': point.index,
                                 'repeat': point.repeat, **point.values, **row}
        self.done.add((point.index, point.repeat))
        self.dirty = True

    def _ratios(self, rows: list[dict[str, Any]]) -> None:
        """Fill in each ratio's column: ``metric_ratio`` of the run over the run at the baseline
        (the same rule as ``run_scene --arm-swing-ratio``: null where either fell or failed,
        lacks a value, or the baseline's is 0)."""
        for ratio in self.spec.ratios:
            others = [k for k in self.spec.axis_keys if k != ratio.baseline_key]
            wheres = [json.dumps([r['repeat'], *(r.get(k) for k in others)], default=str)
                      for r in rows]  # the run's place but for the ratio's axis
            base = {where: r for where, r in zip(wheres, rows, strict=True)
                    if r.get(ratio.baseline_key) == ratio.baseline_value}
            for row, where in zip(rows, wheres, strict=True):
                row.pop(ratio.name, None)
                bottom = base.get(where)
                value = metric_ratio(ratio.metrics, row, bottom) if bottom is not None else None
                if value is not None:
                    row[ratio.name] = value

    def write(self) -> None:
        """Write every row into the table file (atomically)."""
        rows = sorted(self.rows.values(), key=lambda row: (row['point'], row['repeat']))
        self._ratios(rows)
        first = [*RUN_COLUMNS[:3], *self.spec.axis_keys, *RUN_COLUMNS[3:]]
        later = dict.fromkeys(k for row in rows for k in row if k not in first)
        columns = {name: [row.get(name) for row in rows] for name in [*first, *later]}
        table = pa.table(columns).replace_schema_metadata(self._metadata)
        partial = self.path.with_name(f'.{self.path.name}.partial')
        pq.write_table(table, partial)
        os.replace(partial, self.path)
        self.dirty = False
