"""Rows of the analysis' per-sample records (``BagData``, ``JointDecomposition``): frozen
dataclasses whose arrays, and dicts of arrays, have one row per sample along their first axis;
every other field is a property of the whole record.
"""

from __future__ import annotations

from collections.abc import Sequence
import dataclasses
from typing import Any, TypeVar

import numpy as np

__all__ = ['join_rows', 'sample_count', 'take_rows']

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


def join_rows(records: Sequence[Record]) -> Record:
    """The samples of ``records`` one after the other, as one record (its other fields those of
    the last). A dict of arrays has every key of any record, in the order they first come; a
    record without one holds zeros there.

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
                key: np.concatenate([v[key] if key in v else
                                     np.zeros((n, *shapes[key].shape[1:]), shapes[key].dtype)
                                     for v, n in zip(values, counts, strict=True)])
                for key in keys}
    return dataclasses.replace(last, **changes)
