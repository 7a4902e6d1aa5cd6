"""Conversions between our ROS messages and the ROS-free core types (no rclpy import).

Every function is duck-typed on message *fields*, so it accepts rclpy messages (live topics) and
rosbags message objects (bags) alike:

* ``observation_from_gait_state``: the ``Observation`` a control law sees, rebuilt from the
  ``gait_state`` (GaitState) of one instant, which holds the whole hybrid state;
* ``command_from_message`` / ``command_fields``: an ``EffortCommand`` <-> a
  ``ControllerCommand`` (the summed command and its per-source breakdown),
  refusing NaN, wrong lengths, repeated or unknown joint names with a ``SimulationError`` that
  names the problem and the source (arrays go out as ``array('d')``, which rclpy messages take
  without a per-element check; all 18 names in order, as the controllers send, skip the
  reordering).

Known loss: GaitState carries ``pivot = PIVOT_NONE`` while the support sole is flat, so the
observation then says 'toe'. The support models of either pivot give the same kinematics while
q1 = 0, which is all a flat-sole law evaluates.
"""

from __future__ import annotations

from array import array
from collections.abc import Sequence
from typing import Any

import numpy as np

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import ControllerCommand, JointCommand, all_finite
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, SIDES
from iceskate_sim.model.stamps import stamp_to_seconds

PIVOT_OF_CODE = {0: 'toe', 1: 'toe', 2: 'heel'}  # GaitState.pivot -> Observation.pivot
_NAMES = list(COORDINATE_NAMES)
_INDEX = {name: i for i, name in enumerate(COORDINATE_NAMES)}
_IMPEDANCE = ('stiffness', 'damping', 'position_reference')


# ------------------------------------------------------------------------------ observation
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


def _state_vector(gait_state: Any, field: str) -> np.ndarray:
    return finite_vector(getattr(gait_state, field), COORDINATE_NAMES, f'gait_state {field}',
                          f'; it needs {N_COORDINATES} (y0, q1..q17)')


def observation_from_gait_state(gait_state: Any) -> Observation:
    """The Observation of one instant from its GaitState message (the whole hybrid state).

    :raises SimulationError: when a field is malformed (naming it).
    """
    side = int(gait_state.support_side)
    if side not in (0, 1):
        raise SimulationError(f'gait_state support_side must be 0 or 1, got {side}')
    pivot = PIVOT_OF_CODE.get(int(gait_state.pivot))
    if pivot is None:
        raise SimulationError(f'gait_state pivot must be 0, 1 or 2, got {gait_state.pivot}')
    touchdown = (stamp_to_seconds(gait_state.touchdown_stamp) if gait_state.touched_down
                 else float('nan'))
    return Observation(stamp_to_seconds(gait_state.header.stamp),
                       _state_vector(gait_state, 'position'),
                       _state_vector(gait_state, 'velocity'), int(gait_state.mode),
                       SIDES[side], pivot, int(gait_state.step_index),
                       stamp_to_seconds(gait_state.support_exchange_stamp),
                       float(gait_state.heel_anchor_y), touchdown)


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


def _array(msg: Any, field: str, names: list[str], where: str) -> np.ndarray:
    return finite_vector(getattr(msg, field), names, f'{where}: {field}',
                          f' for {len(names)} joint names')


def command_from_message(msg: Any) -> ControllerCommand:
    """The ControllerCommand of an EffortCommand message (18-vectors; unnamed coordinates 0).

    An empty breakdown gives empty ``source_efforts`` (a controller with one source named like
    itself: the simulator evaluates its effort).

    :raises SimulationError: on unknown or repeated joint names, wrong lengths, non-finite or
        negative gains, a partial impedance, or a breakdown of the wrong length, repeated
        source names or non-finite values; the message names the source and the field.
    """
    where = f'effort command of source {msg.source!r}'
    names = list(msg.joint_names)
    index = None if names == _NAMES else _indices(names, where)

    def coordinates(x: np.ndarray) -> np.ndarray:
        if index is None:
            return x
        out = np.zeros(N_COORDINATES)
        out[index] = x
        return out

    def field(name: str) -> np.ndarray:
        return coordinates(_array(msg, name, names, where))

    effort = field('effort')
    given = [len(getattr(msg, f)) > 0 for f in _IMPEDANCE]
    if not any(given):
        command = JointCommand(effort)
    elif not all(given):
        raise SimulationError(f'{where}: stiffness, damping and position_reference must be '
                              'all empty or all given')
    else:
        try:
            command = JointCommand(effort, *(field(f) for f in _IMPEDANCE))
        except SimulationError as exc:
            raise SimulationError(f'{where}: {exc}') from None
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
    return ControllerCommand(command, {name: coordinates(row.copy())
                                       for name, row in zip(sources, rows, strict=True)},
                             target if target.size else None)


def command_fields(answer: ControllerCommand) -> dict[str, Any]:
    """EffortCommand fields (joint_names, effort, impedance arrays, breakdown, head target) of a
    command."""
    command = answer.command
    fields = {'joint_names': list(COORDINATE_NAMES), 'effort': _doubles(command.effort),
              'stiffness': array('d'), 'damping': array('d'), 'position_reference': array('d'),
              'source_names': list(answer.source_efforts),
              'source_efforts': _doubles(np.concatenate(list(answer.source_efforts.values()))
                                         if answer.source_efforts else np.zeros(0)),
              'head_target': _doubles(answer.head_target if answer.head_target is not None
                                      else np.zeros(0))}
    if command.has_impedance:
        fields.update(stiffness=_doubles(command.stiffness), damping=_doubles(command.damping),
                      position_reference=_doubles(command.reference))
    return fields


def _doubles(x: np.ndarray) -> array:
    return array('d', np.ascontiguousarray(x, dtype=np.float64).tobytes())
