"""The recorded sample's columns, read from their one declaration (``sample_columns.hpp``,
exported by the kernel): ``SAMPLE_COLUMNS`` by name, ``SAVED_COLUMNS`` (trajectory.npz) and
``routed`` (where each goes in the recorded messages). See docs/architecture.md, 'One sample
form'.
"""

from __future__ import annotations

from typing import NamedTuple

import numpy as np

from ._kernel import SAMPLE_COLUMNS_TABLE, TF_POSE_WIDTH


class Route(NamedTuple):
    """Where a column's values go in a message: ``topic`` and the field ``path``; ``axes``
    names a Point's or Quaternion's fields that hold them in order (empty: ``path`` is one
    number, or an array of all of them)."""

    topic: str
    path: str
    axes: tuple[str, ...] = ()

    @classmethod
    def parse(cls, text: str) -> Route:
        """From ``topic:field`` (``topic:pose.position.x,y,z`` for a Point's fields)."""
        topic, path = text.split(':', 1)
        head, _, last = path.rpartition('.')
        if ',' in last:
            return cls(topic, head, tuple(last.split(',')))
        return cls(topic, path)


class SampleColumn(NamedTuple):
    """One recorded quantity: ``name``; ``dtype``; ``width`` values per sample (0:
    ``TF_POSE_WIDTH`` per /tf pair); ``unit``; ``saved`` in trajectory.npz; ``routes`` in the
    messages (the first is what a bag gives back); ``meaning``."""

    name: str
    dtype: np.dtype
    width: int
    unit: str
    saved: bool
    routes: tuple[Route, ...]
    meaning: str

    def shape(self, tf_pairs: int = 0) -> tuple[int, ...]:
        """The shape of one sample's values: () for one number."""
        width = self.width or TF_POSE_WIDTH * tf_pairs
        return () if width == 1 else (width,)


#: Every column of a sample, by name, in the declaration's order.
SAMPLE_COLUMNS = {
    name: SampleColumn(name, np.dtype(dtype), width, unit, saved,
                       tuple(Route.parse(text) for text in routes.split()), meaning)
    for name, dtype, width, unit, saved, routes, meaning in SAMPLE_COLUMNS_TABLE}
#: The columns trajectory.npz keeps of a sample (it adds psi and each source's efforts).
SAVED_COLUMNS = tuple(name for name, column in SAMPLE_COLUMNS.items() if column.saved)


def routed(topic: str, read_back: bool = False) -> list[tuple[SampleColumn, Route]]:
    """The columns whose values go into ``topic``'s messages, with their route there;
    ``read_back``: only those a bag gives back from ``topic`` (their first route)."""
    return [(column, route) for column in SAMPLE_COLUMNS.values()
            for route in (column.routes[:1] if read_back else column.routes)
            if route.topic == topic]
