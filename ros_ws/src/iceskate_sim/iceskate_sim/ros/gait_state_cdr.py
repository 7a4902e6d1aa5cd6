"""``GaitState`` CDR bytes -> the observation a native control law takes, without message
objects (the controller nodes' hot path): ``GaitStateReader``. See docs/architecture.md, 'One
run: many periods per native call'.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np
from rosbags.typesys.store import Typestore

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, PIVOTS
from iceskate_sim.model.stamps import NS_PER_S
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.cdr import Field, Layout, LayoutCache, LayoutError
from iceskate_sim.ros.conversions import PIVOT_OF_CODE, finite_vector

_TYPE = 'iceskate_interfaces/msg/GaitState'


#: the one-number fields a law's observation takes, in ``GaitStateReader.read``'s order
_SCALARS = ('header.stamp.sec', 'header.stamp.nanosec', 'mode', 'support_side', 'pivot',
            'step_index', 'support_exchange_stamp.sec', 'support_exchange_stamp.nanosec',
            'heel_anchor_y', 'touched_down', 'touchdown_stamp.sec', 'touchdown_stamp.nanosec')


def _readers(layout: Layout) -> tuple[Callable[[bytes], tuple], Field, Field]:
    """What ``GaitStateReader.read`` takes from a message of ``layout``: the reader of its
    one-number fields, the places of position and velocity."""
    return layout.unpacker(_SCALARS), layout.fields['position'], layout.fields['velocity']


class GaitStateReader:
    """Reads GaitState messages into native observations (``typestore``: the types, default
    ``make_typestore()``)."""

    def __init__(self, typestore: Typestore | None = None) -> None:
        self._layouts = LayoutCache(typestore or make_typestore(), _TYPE, prepare=_readers)

    def read(self, data: bytes) -> tuple[int, iceskate_native.Observation]:
        """The stamp [ns] and the observation of one GaitState's CDR bytes, as the native laws
        take it (``native_control.native_observation`` of ``observation_from_gait_state``'s).

        :raises SimulationError: for bytes that are not a GaitState ('undecodable gait_state
            ...') or a malformed field (naming it, as ``observation_from_gait_state``).
        """
        try:
            _, (scalars, position, velocity) = self._layouts.lookup(data)
        except LayoutError as exc:
            raise SimulationError(f'undecodable gait_state ({len(data)} bytes): {exc}') \
                from None
        (sec, nanosec, mode, side, pivot, step_index, exchange_sec, exchange_nanosec,
         heel_anchor_y, touched_down, touchdown_sec, touchdown_nanosec) = scalars(data)
        if mode not in MODES:
            raise SimulationError(f'gait_state mode {mode} is not a mode of the table '
                                  f'(1-{len(MODES)})')
        if side not in (0, 1):
            raise SimulationError(f'gait_state support_side must be 0 or 1, got {side}')
        pivot_name = PIVOT_OF_CODE.get(pivot)
        if pivot_name is None:
            raise SimulationError(f'gait_state pivot must be 0, 1 or 2, got {pivot}')
        q, v = (finite_vector(np.frombuffer(data, field.dtype, field.count, field.offset),
                              COORDINATE_NAMES, f'gait_state {name}',
                              f'; it needs {N_COORDINATES} (y0, q1..q17)')
                for name, field in (('position', position), ('velocity', velocity)))
        stamp = sec * NS_PER_S + nanosec
        try:
            obs = iceskate_native.Observation(
                stamp / 1e9, q, v, mode, side, PIVOTS.index(pivot_name), step_index,
                (exchange_sec * NS_PER_S + exchange_nanosec) / 1e9, heel_anchor_y,
                (touchdown_sec * NS_PER_S + touchdown_nanosec) / 1e9 if touched_down
                else float('nan'))
        except ValueError as exc:
            raise SimulationError(f'gait_state: {exc}') from None
        return stamp, obs
