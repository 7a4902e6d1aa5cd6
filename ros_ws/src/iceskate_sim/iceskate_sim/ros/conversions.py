"""Checked conversions of message fields to the ROS-free core types (no rclpy import):
``command_from_message`` (an ``EffortCommand`` -> ``CommandValues``), ``finite_vector``,
``PIVOT_OF_CODE``. See docs/architecture.md, 'The control laws in C++'.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import EMPTY, CommandValues, all_finite
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES

PIVOT_OF_CODE = {0: 'toe', 1: 'toe', 2: 'heel'}  # GaitState.pivot -> Observation.pivot
_INDEX = {name: i for i, name in enumerate(COORDINATE_NAMES)}
_IMPEDANCE = ('stiffness', 'damping', 'position_reference')


def finite_vector(values: Any, names: Sequence[str], what: str, length: str) -> np.ndarray:
    """``values`` as a new float array of one entry per name, all finite.

    :param what: the field, as the error messages name it.
    :param length: what a wrong length is told against (appended to 'has N entries').
    """
    x = np.array(values, dtype=float)  # a copy: never a view of the message
    if x.shape != (len(names),):
        raise SimulationError(f'{what} has {x.size} entries{length}')
    if not all_finite(x):
        bad = [str(names[i]) for i in np.flatnonzero(~np.isfinite(x))]
        raise SimulationError(f'{what} is not finite at {bad}')
    return x


# ---------------------------------------------------------------------------------- commands
def _indices(names: list[str], where: str) -> np.ndarray:
    unknown = [n for n in names if n not in _INDEX]
    if unknown:
        raise SimulationError(f'{where}: unknown joint names {unknown}; expected names among '
                              f'{list(COORDINATE_NAMES)}')
    if len(set(names)) != len(names):
        repeated = sorted({n for n in names if names.count(n) > 1})
        raise SimulationError(f'{where}: repeated joint names {repeated}')
    return np.array([_INDEX[n] for n in names], dtype=np.intp)


def command_from_message(msg: Any) -> CommandValues:
    """The CommandValues of an EffortCommand message (18-vectors; unnamed coordinates 0).

    An empty breakdown gives empty ``source_efforts`` (a controller with one source named like
    itself: the simulator evaluates its effort).

    :raises SimulationError: on unknown or repeated joint names, wrong lengths, non-finite or
        negative gains, a partial impedance, or a breakdown of the wrong length, repeated
        source names or non-finite values; the message names the source and the field.
    """
    where = f'effort command of source {msg.source!r}'
    names = list(msg.joint_names)
    index = None if names == list(COORDINATE_NAMES) else _indices(names, where)

    def coordinates(x: np.ndarray) -> np.ndarray:
        if index is None:
            return x
        out = np.zeros(N_COORDINATES)
        out[index] = x
        return out

    def field(name: str) -> np.ndarray:
        return coordinates(finite_vector(getattr(msg, name), names, f'{where}: {name}',
                                         f' for {len(names)} joint names'))

    effort = field('effort')
    given = [len(getattr(msg, f)) > 0 for f in _IMPEDANCE]
    if any(given) and not all(given):
        raise SimulationError(f'{where}: stiffness, damping and position_reference must be '
                              'all empty or all given')
    impedance = [field(f) for f in _IMPEDANCE] if all(given) else [EMPTY] * 3
    if all(given) and min(min(impedance[0].tolist()), min(impedance[1].tolist())) < 0.0:
        raise SimulationError(f'{where}: stiffness and damping must be >= 0')
    sources = [str(n) for n in msg.source_names]
    if len(set(sources)) != len(sources):
        raise SimulationError(f'{where}: repeated source names in {sources}')
    parts = np.array(msg.source_efforts, dtype=float)
    if parts.shape != (len(sources) * len(names),):
        raise SimulationError(f'{where}: source_efforts has {parts.size} entries for '
                              f'{len(sources)} source names x {len(names)} joint names')
    if not all_finite(parts):
        raise SimulationError(f'{where}: source_efforts is not finite')
    rows = parts.reshape(len(sources), len(names))
    target = np.array(msg.head_target, dtype=float)
    if target.shape not in ((0,), (3,)) or not all_finite(target):
        raise SimulationError(f'{where}: head_target must be empty or 3 finite values '
                              f'(y, z, pitch), got {target.tolist()}')
    efforts = [coordinates(row.copy()) for row in rows]
    return CommandValues(effort, *impedance, np.concatenate(efforts) if efforts else EMPTY,
                         target, tuple(sources))
