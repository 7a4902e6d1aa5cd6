"""``GaitState`` CDR bytes -> the observation a native control law takes, without message
objects (the controller nodes' hot path: rosbags' deserialisation and the conversion of its
message cost 30 us per instant).

``GaitStateReader.read`` reads the fields a law needs at their places in the message's
``cdr.Layout`` and checks them as ``ros_conversions.observation_from_gait_state`` does, with
the same words.
"""

from __future__ import annotations

from rosbags.typesys.store import Typestore

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, PIVOTS
from iceskate_sim.model.stamps import NS_PER_S
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.cdr import LayoutCache, LayoutError
from iceskate_sim.ros.conversions import PIVOT_OF_CODE, finite_vector

_TYPE = 'iceskate_interfaces/msg/GaitState'


class GaitStateReader:
    """Reads GaitState messages into native observations (``typestore``: the types, default
    ``make_typestore()``)."""

    def __init__(self, typestore: Typestore | None = None) -> None:
        self._layouts = LayoutCache(typestore or make_typestore(), _TYPE)

    def read(self, data: bytes) -> tuple[int, iceskate_native.Observation]:
        """The stamp [ns] and the observation of one GaitState's CDR bytes, as the native laws
        take it (``native_control.native_observation`` of ``observation_from_gait_state``'s).

        :raises SimulationError: for bytes that are not a GaitState ('undecodable gait_state
            ...') or a malformed field (naming it, as ``observation_from_gait_state``).
        """
        try:
            layout = self._layouts.layout(data)
        except LayoutError as exc:
            raise SimulationError(f'undecodable gait_state ({len(data)} bytes): {exc}') \
                from None

        def integer(path: str) -> int:
            return int(layout.read(data, path)[0])

        def stamp_ns(path: str) -> int:
            return integer(f'{path}.sec') * NS_PER_S + integer(f'{path}.nanosec')

        side, pivot = integer('support_side'), integer('pivot')
        if side not in (0, 1):
            raise SimulationError(f'gait_state support_side must be 0 or 1, got {side}')
        pivot_name = PIVOT_OF_CODE.get(pivot)
        if pivot_name is None:
            raise SimulationError(f'gait_state pivot must be 0, 1 or 2, got {pivot}')
        q, v = (finite_vector(layout.read(data, field), COORDINATE_NAMES, f'gait_state {field}',
                              f'; it needs {N_COORDINATES} (y0, q1..q17)')
                for field in ('position', 'velocity'))
        stamp = stamp_ns('header.stamp')
        try:
            obs = iceskate_native.Observation(
                stamp / 1e9, q, v, integer('mode'), side, PIVOTS.index(pivot_name),
                integer('step_index'), stamp_ns('support_exchange_stamp') / 1e9,
                float(layout.read(data, 'heel_anchor_y')[0]),
                stamp_ns('touchdown_stamp') / 1e9 if integer('touched_down') else float('nan'))
        except ValueError as exc:
            raise SimulationError(f'gait_state: {exc}') from None
        return stamp, obs
