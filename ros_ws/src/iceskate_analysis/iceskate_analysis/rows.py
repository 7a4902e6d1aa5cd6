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
    the last): ``collect_rows`` into arrays of their total length.

    :raises ValueError: for no record.
    """
    if len(records) == 1:
        return records[0]
    return collect_rows(records, sum(sample_count(r) for r in records), missing)


def collect_rows(records: Iterable[Record], capacity: int,
                 missing: Callable[[Any, str, int], np.ndarray] | None = None) -> Record:
    """The samples of ``records`` one after the other, as one record (its other fields those of
    the last), copied as they come into arrays of ``capacity`` rows made once (doubled when
    more come), so that only one record is held beside them. A dict of arrays has every key
    of any record, in the order they first come; the rows of a record without one hold
    ``missing(record, key, its sample count)`` there (default: zeros; for the records before
    the key came, ``record`` is a record of their rows).

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
                        if size and missing is not None:  # the records before it came
                            group[key][:size] = missing(_filled(last, arrays, size), key, size)
                    group[key][size:size + n] = v
                if missing is not None:
                    for key in group.keys() - value.keys():
                        group[key][size:size + n] = missing(record, key, n)
        last, size = record, size + n
    if last is None:
        raise ValueError('no record to join')
    return _filled(last, arrays, size)


def _filled(last: Record, arrays: dict[str, Any], size: int) -> Record:
    """``last`` with the first ``size`` rows of ``arrays`` as its per-sample fields."""
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
