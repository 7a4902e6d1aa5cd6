"""Rows of the analysis' per-sample records (``BagData``, ``JointDecomposition``): frozen
dataclasses whose arrays, and dicts of arrays, have one row per sample along their first axis;
every other field is a property of the whole record.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
import dataclasses
from typing import Any, TypeVar

import numpy as np

__all__ = ['collect_rows', 'join_rows', 'sample_count', 'take_rows']

Record = TypeVar('Record')


def sample_count(record: Any) -> int:
    """The number of samples of ``record``: the length of its first array field."""
    for f in dataclasses.fields(record):
        value = getattr(record, f.name)
        if isinstance(value, np.ndarray):
            return int(value.shape[0])
    raise TypeError(f'{type(record).__name__} has no array field')


def _per_sample(value: Any, n: int) -> bool:
    return isinstance(value, np.ndarray) and value.ndim >= 1 and value.shape[0] == n


def take_rows(record: Record, index: np.ndarray | slice) -> Record:
    """``record`` with the samples of ``index`` (indices, a mask or a slice)."""
    n = sample_count(record)
    changes = {}
    for f in dataclasses.fields(record):
        value = getattr(record, f.name)
        if _per_sample(value, n):
            changes[f.name] = value[index]
        elif isinstance(value, dict) and all(_per_sample(v, n) for v in value.values()):
            changes[f.name] = {key: v[index] for key, v in value.items()}
    return dataclasses.replace(record, **changes)


def join_rows(records: Sequence[Record],
              missing: Callable[[Any, str, int], np.ndarray] | None = None) -> Record:
    """The samples of ``records`` one after the other, as one record (its other fields those of
    the last). A dict of arrays has every key of any record, in the order they first come; a
    record without one holds ``missing(record, key, its sample count)`` there (default: zeros).

    :raises ValueError: for no record.
    """
    if not records:
        raise ValueError('no record to join')
    last = records[-1]
    if len(records) == 1:
        return last
    counts = [sample_count(r) for r in records]
    changes = {}
    for f in dataclasses.fields(last):
        values = [getattr(r, f.name) for r in records]
        if all(_per_sample(v, n) for v, n in zip(values, counts, strict=True)):
            changes[f.name] = np.concatenate(values)
        elif all(isinstance(v, dict) and all(_per_sample(x, n) for x in v.values())
                 for v, n in zip(values, counts, strict=True)):
            keys = list(dict.fromkeys(key for v in values for key in v))
            shapes = {key: next(v[key] for v in values if key in v) for key in keys}
            changes[f.name] = {
                key: np.concatenate([
                    v[key] if key in v else
                    missing(r, key, n) if missing is not None else
                    np.zeros((n, *shapes[key].shape[1:]), shapes[key].dtype)
                    for r, v, n in zip(records, values, counts, strict=True)])
                for key in keys}
    return dataclasses.replace(last, **changes)


def collect_rows(records: Iterable[Record], capacity: int) -> Record:
    """``join_rows`` of ``records`` as they come, each copied into arrays of ``capacity`` rows
    made once (doubled when more come), so that only one record is held beside them; a key of
    a dict of arrays that a record lacks holds zeros there.

    :raises ValueError: for no record.
    """
    last, size = None, 0
    arrays: dict[str, Any] = {}
    for record in records:
        n = sample_count(record)
        while size + n > capacity:
            capacity = max(2 * capacity, size + n)
            arrays = {name: _resized(value, capacity) for name, value in arrays.items()}
        for f in dataclasses.fields(record):
            value = getattr(record, f.name)
            if _per_sample(value, n):
                if f.name not in arrays:
                    arrays[f.name] = _empty(value, capacity)
                arrays[f.name][size:size + n] = value
            elif isinstance(value, dict) and all(_per_sample(v, n) for v in value.values()):
                group = arrays.setdefault(f.name, {})
                for key, v in value.items():
                    if key not in group:
                        group[key] = _empty(v, capacity)
                    group[key][size:size + n] = v
        last, size = record, size + n
    if last is None:
        raise ValueError('no record to join')
    return dataclasses.replace(last, **{
        name: ({key: v[:size] for key, v in value.items()} if isinstance(value, dict)
               else value[:size]) for name, value in arrays.items()})


def _empty(like: np.ndarray, rows: int) -> np.ndarray:
    return np.zeros((rows, *like.shape[1:]), like.dtype)


def _resized(value: Any, rows: int) -> Any:
    if isinstance(value, dict):
        return {key: _resized(v, rows) for key, v in value.items()}
    out = _empty(value, rows)
    out[:min(rows, value.shape[0])] = value[:rows]
    return out
