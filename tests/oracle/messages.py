"""The ROS messages as objects (rclpy or rosbags): the formulation the byte codecs
(``iceskate_sim.ros.gait_state_cdr``, ``effort_cdr``) are checked against. Duck-typed on the
message fields.
"""

from __future__ import annotations

from array import array
from typing import Any

import numpy as np

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, SIDES
from iceskate_sim.model.stamps import NS_PER_S
from iceskate_sim.ros.conversions import PIVOT_OF_CODE, finite_vector
from oracle.commands import ControllerCommand


def stamp_to_ns(stamp: Any) -> int:
    """Integer nanoseconds of a builtin_interfaces/Time (fields sec, nanosec)."""
    return int(stamp.sec) * NS_PER_S + int(stamp.nanosec)


def stamp_to_seconds(stamp: Any) -> float:
    """Seconds [s] of a builtin_interfaces/Time."""
    return stamp_to_ns(stamp) / 1e9


def _state_vector(gait_state: Any, field: str) -> np.ndarray:
    return finite_vector(getattr(gait_state, field), COORDINATE_NAMES, f'gait_state {field}',
                          f'; it needs {N_COORDINATES} (y0, q1..q17)')


def observation_from_gait_state(gait_state: Any) -> Observation:
    """The Observation of one instant from its GaitState message (the whole hybrid state).

    :raises SimulationError: when a field is malformed (naming it).
    """
    if int(gait_state.mode) not in MODES:
        raise SimulationError(f'gait_state mode {gait_state.mode} is not a mode of the table '
                              f'(1-{len(MODES)})')
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
