"""``GaitState`` CDR bytes -> the observation a native control law takes, without message
objects (the controller nodes' hot path: rosbags' deserialisation and the conversion of its
message cost 30 us per instant, this reading 10 us).

``read_observation`` walks the message field by field (``cdr.CdrReader``), skipping what a law
does not read (frame id, multipliers, forces, ZMP, the last transition), and checks what it
reads as ``ros_conversions.observation_from_gait_state`` does, with the same words.
"""

from __future__ import annotations

import struct

import numpy as np

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, PIVOTS
from iceskate_sim.model.stamps import NS_PER_S
from iceskate_sim.ros.cdr import STAMP, CdrReader
from iceskate_sim.ros.conversions import PIVOT_OF_CODE, finite_vector

_CODES = struct.Struct('<3B')         # mode, support_side, pivot
_STEP = struct.Struct('<I2B')         # step_index, y0_active, q1_active
_FORCES = struct.Struct('<5d')        # support normal and friction force, zmp x, y, z
_FLAG = struct.Struct('<B')           # a bool
_DOUBLE = struct.Struct('<d')


def _seconds(sec: int, nanosec: int) -> float:
    return (sec * NS_PER_S + nanosec) / 1e9


def read_observation(data: bytes) -> tuple[int, iceskate_native.Observation]:
    """The stamp [ns] and the observation of one GaitState's CDR bytes, as the native laws take
    it (``native_control.native_observation`` of ``observation_from_gait_state``'s).

    :raises SimulationError: for bytes that are not a GaitState ('undecodable gait_state ...')
        or a malformed field (naming it, as ``observation_from_gait_state``).
    """
    try:
        reader = CdrReader(data)
        sec, nanosec = reader.unpack(STAMP, 4)
        reader.skip_string()  # frame_id
        mode, side, pivot = reader.unpack(_CODES, 1)
        step_index, _, _ = reader.unpack(_STEP, 4)
        for _ in range(reader.count()):  # multiplier_names
            reader.skip_string()
        reader.doubles()  # multipliers
        reader.unpack(_FORCES, 8)
        reader.unpack(_FLAG, 1)  # zmp_inside_support
        reader.skip_string()  # last_transition_cause
        reader.unpack(STAMP, 4)  # last_transition_stamp
        exchange = reader.unpack(STAMP, 4)
        (touched_down,) = reader.unpack(_FLAG, 1)
        touchdown = reader.unpack(STAMP, 4)
        (heel_anchor_y,) = reader.unpack(_DOUBLE, 8)
        position, velocity = reader.doubles(), reader.doubles()
    except (ValueError, struct.error) as exc:
        raise SimulationError(f'undecodable gait_state ({len(data)} bytes): {exc}') from None
    if side not in (0, 1):
        raise SimulationError(f'gait_state support_side must be 0 or 1, got {side}')
    pivot_name = PIVOT_OF_CODE.get(pivot)
    if pivot_name is None:
        raise SimulationError(f'gait_state pivot must be 0, 1 or 2, got {pivot}')
    q, v = (finite_vector(np.frombuffer(data, '<f8', count, offset), COORDINATE_NAMES,
                          f'gait_state {field}', f'; it needs {N_COORDINATES} (y0, q1..q17)')
            for field, (offset, count) in (('position', position), ('velocity', velocity)))
    try:
        obs = iceskate_native.Observation(
            _seconds(sec, nanosec), q, v, mode, side, PIVOTS.index(pivot_name), step_index,
            _seconds(*exchange), heel_anchor_y,
            _seconds(*touchdown) if touched_down else float('nan'))
    except ValueError as exc:
        raise SimulationError(f'gait_state: {exc}') from None
    return sec * NS_PER_S + nanosec, obs
