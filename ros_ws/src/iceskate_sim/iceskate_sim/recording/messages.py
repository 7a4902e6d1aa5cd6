"""The messages of recorded samples: what each topic holds of a sample, as CDR bytes.

A sample is a row of the native control loop's block (``iceskate_native.ControlLoop.run``,
``take_block``, ``live``: columns t, q, v, qdd, passive, mode, side, pivot_code, step_index,
multipliers, support forces, cop_y, head_position, head_orientation, root_pose, last_event,
and the efforts of its sources). ``SampleMessages.encode`` turns a block into the bytes of
every topic's messages, one per row, through the topic's ``cdr.Layout`` (computed once per
shape: the strings and sequence lengths a message has, e.g. a gait mode's multiplier names):
a few numpy operations per topic and shape, whatever the number of rows. The bag
(``bag.BagRecorder``) and the simulator node's live topics send these bytes.

Topics (one message per sample, stamped with its simulation time):

* ``/clock`` (rosgraph_msgs/Clock)
* ``/joint_states`` (sensor_msgs/JointState): the 18 coordinates y0, q1..q17; position,
  velocity and the total input effort held over the period
* ``/head_pose`` (geometry_msgs/PoseStamped, frame ``world``): the head-top frame
* ``/gait_state`` (iceskate_interfaces/GaitState): the whole hybrid state, what the
  controllers read
* ``/joint_dynamics`` (iceskate_interfaces/JointDynamics): accelerations and the effort of
  every input source (plus ``passive``: damping and soft stops)
* ``/tf`` (tf2_msgs/TFMessage): every URDF link (``links.LinkTransforms``)

and ``/robot_description`` (std_msgs/String) once.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from rosbags.typesys.store import Typestore

from iceskate_sim.model.modes import MODES, MULTIPLIER_NAMES
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, SOLE_HEEL_Y, SOLE_TOE_Y
from iceskate_sim.recording.bag_types import PASSIVE
from iceskate_sim.recording.cdr import Layout, Packer, layout_for
from iceskate_sim.recording.links import LinkTransforms

TOPICS = {
    '/clock': 'rosgraph_msgs/msg/Clock',
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/head_pose': 'geometry_msgs/msg/PoseStamped',
    '/gait_state': 'iceskate_interfaces/msg/GaitState',
    '/joint_dynamics': 'iceskate_interfaces/msg/JointDynamics',
    '/robot_description': 'std_msgs/msg/String',
    '/tf': 'tf2_msgs/msg/TFMessage',
}
#: The topics written at every control instant, in this order.
RECORDED_TOPICS = ('/clock', '/joint_states', '/head_pose', '/gait_state', '/joint_dynamics',
                   '/tf')

_N = N_COORDINATES
_MODES = [None, *(MODES[k] for k in range(1, len(MODES) + 1))]  # by mode number
_Y0_ACTIVE = np.array([False] + [m.y0_active for m in _MODES[1:]])
_Q1_ACTIVE = np.array([False] + [m.q1_active for m in _MODES[1:]])
#: which coordinates are active, by mode number: (21, 18)
_ACTIVE = np.zeros((len(_MODES), _N), dtype=bool)
for _mode in _MODES[1:]:
    _ACTIVE[_mode.number, _mode.active] = True
#: the columns of a block's multipliers that a mode's GaitState holds, by mode number
_PICKED = [None, *([MULTIPLIER_NAMES.index(name) for name in m.multipliers] for m in _MODES[1:])]


def _groups(key: np.ndarray):
    """(value, rows) for each distinct value of ``key``; rows None when it is every row."""
    first = key[0]
    if (key == first).all():
        yield int(first), None
        return
    for value in np.unique(key).tolist():
        yield value, np.flatnonzero(key == value)


class Stamps(NamedTuple):
    """The builtin_interfaces/Time fields of a block's samples: (m, 4) sec and nanosec of its
    ``stamps_ns``: the sample time t, the last support exchange, the heel strike (0 before
    it) and the latest transition (0: none)."""

    sec: np.ndarray
    nanosec: np.ndarray

    @classmethod
    def of(cls, block: Mapping[str, Any]) -> Stamps:
        """The stamps of ``block``'s samples."""
        return cls(*np.divmod(block['stamps_ns'], 1_000_000_000))

    def fields(self, prefix: str, column: int = 0) -> dict[str, np.ndarray]:
        """The sec and nanosec fields of the Time field ``prefix`` from ``column``."""
        return {f'{prefix}.sec': self.sec[:, column],
                f'{prefix}.nanosec': self.nanosec[:, column]}


class Events(NamedTuple):
    """The cause of the latest transition at each sample: ``cause`` index into ``causes`` (''
    for none yet)."""

    cause: np.ndarray
    causes: tuple[str, ...]

    @classmethod
    def of(cls, last_event: np.ndarray, events: Sequence[Any]) -> Events:
        """From a block's ``last_event`` (index in ``events``, -1: none) and the event log
        (items with a ``cause``)."""
        first = int(last_event[0])
        if len(last_event) == 1 or (last_event == first).all():  # e.g. a live sample
            return cls(np.zeros(len(last_event), dtype=np.intp),
                       (events[first].cause if first >= 0 else '',))
        indices = np.unique(last_event).tolist()
        causes = tuple(events[i].cause if i >= 0 else '' for i in indices)
        return cls(np.searchsorted(indices, last_event), causes)


class SampleMessages:
    """Encodes blocks of samples into the CDR bytes of the recorded topics' messages.

    :param typestore: the types (``bag_types.make_typestore()``).
    :param links: the /tf transforms of the recorded robot.
    """

    def __init__(self, typestore: Typestore, links: LinkTransforms) -> None:
        self.typestore = typestore
        self.links = links
        self._packers: dict[tuple[str, Any], Packer] = {}

    def encode(self, block: Mapping[str, Any], events: Events,
               topics: Sequence[str] = RECORDED_TOPICS) -> dict[str, list[bytes]]:
        """Topic -> the bytes of its message at each row of ``block``."""
        rows = len(block['t'])
        stamps = Stamps.of(block)
        out: dict[str, list[bytes]] = {}
        for topic in topics:
            encoded: list[bytes | None] = [None] * rows
            for key, selected, shape, values in _ENCODERS[topic](self, block, events, stamps):
                packer = self._packer(topic, key, shape, values)
                if selected is None:
                    encoded = [row.tobytes() for row in packer.pack(values, rows)]
                    break
                for k, row in zip(selected.tolist(), packer.pack(values, len(selected)),
                                  strict=True):
                    encoded[k] = row.tobytes()
            out[topic] = encoded
        return out

    def description(self, urdf: str) -> bytes:
        """The /robot_description message holding ``urdf``."""
        layout = layout_for(self.typestore, TOPICS['/robot_description'], {'data': urdf})
        return layout.template

    def _packer(self, topic: str, key: Any, shape: Mapping[str, Any],
                values: Mapping[str, np.ndarray]) -> Packer:
        packer = self._packers.get((topic, key))
        if packer is None:
            layout: Layout = layout_for(self.typestore, TOPICS[topic], shape)
            packer = self._packers[(topic, key)] = layout.packer(list(values))
        return packer

    def _clock(self, block: Mapping[str, Any], events: Events, stamps: Stamps):
        yield None, None, {}, stamps.fields('clock')

    def _joint_states(self, block: Mapping[str, Any], events: Events, stamps: Stamps):
        total = np.zeros((len(block['t']), _N))
        for effort in block['efforts']:  # 0 where a source did not act
            total += effort
        yield None, None, {
            'name': COORDINATE_NAMES, 'position': _N, 'velocity': _N, 'effort': _N}, {
            **stamps.fields('header.stamp'), 'position': block['q'],
            'velocity': block['v'], 'effort': total}

    def _head_pose(self, block: Mapping[str, Any], events: Events, stamps: Stamps):
        p, o = block['head_position'], block['head_orientation']
        yield None, None, {'header.frame_id': 'world'}, {
            **stamps.fields('header.stamp'),
            **{f'pose.position.{axis}': p[:, i] for i, axis in enumerate('xyz')},
            **{f'pose.orientation.{axis}': o[:, i] for i, axis in enumerate('xyzw')}}

    def _gait_state(self, block: Mapping[str, Any], events: Events, stamps: Stamps):
        mode, cop, q = block['mode'], block['cop_y'], block['q']
        y0, q1_active = q[:, 0], _Q1_ACTIVE[mode]
        inside = ~q1_active & (y0 + SOLE_HEEL_Y <= cop) & (cop <= y0 + SOLE_TOE_Y)  # NaN: no
        values = {
            **stamps.fields('header.stamp'), **stamps.fields('support_exchange_stamp', 1),
            **stamps.fields('touchdown_stamp', 2), **stamps.fields('last_transition_stamp', 3),
            'mode': mode,
            'support_side': block['side'], 'pivot': block['pivot_code'],
            'step_index': block['step_index'], 'y0_active': _Y0_ACTIVE[mode],
            'q1_active': q1_active,
            'support_normal_force': block['support_normal'],
            'support_friction_force': block['support_tangential'],
            'zmp.y': cop,  # NaN: no support force
            'zmp_inside_support': inside,
            'touched_down': ~np.isnan(block['t_touchdown']),  # NaN: not yet
            'heel_anchor_y': block['heel_anchor_y'], 'position': q,
            'velocity': block['v']}
        causes = len(events.causes)
        for code, rows in _groups(mode * causes + events.cause if causes > 1 else mode):
            number, cause = divmod(code, causes)
            names = _MODES[number].multipliers
            selected = values if rows is None else {k: x[rows] for k, x in values.items()}
            multipliers = block['multipliers'] if rows is None else block['multipliers'][rows]
            yield (number, events.causes[cause]), rows, {
                'multiplier_names': names, 'multipliers': len(names),
                'last_transition_cause': events.causes[cause], 'position': _N, 'velocity': _N}, {
                **selected, 'multipliers': multipliers[:, _PICKED[number]]}

    def _joint_dynamics(self, block: Mapping[str, Any], events: Events, stamps: Stamps):
        efforts = block['efforts']
        values = {**stamps.fields('header.stamp'), 'active': _ACTIVE[block['mode']],
                  'acceleration': block['qdd']}
        for mask, rows in _groups(block['present']):
            acting = [i for i in range(len(efforts)) if mask >> i & 1]
            names = [*(block['sources'][i] for i in acting), PASSIVE]
            pick = slice(None) if rows is None else rows
            yield tuple(names), rows, {
                'name': COORDINATE_NAMES, 'active': _N, 'acceleration': _N,
                'source_names': names, 'source_efforts': _N * len(names)}, {
                **{k: x[pick] for k, x in values.items()},
                'source_efforts': np.hstack([*(efforts[i][pick] for i in acting),
                                             block['passive'][pick]])}

    def _tf(self, block: Mapping[str, Any], events: Events, stamps: Stamps):
        frames = self.links.frames
        poses = self.links.block_rows(block['q'], block['side'], block['root_pose'])
        values = {}
        for k in range(len(frames)):
            values.update(stamps.fields(f'transforms.{k}.header.stamp'))
            for i, name in enumerate(('translation.x', 'translation.y', 'translation.z',
                                      'rotation.x', 'rotation.y', 'rotation.z', 'rotation.w')):
                values[f'transforms.{k}.transform.{name}'] = poses[:, k, i]
        shape = {'transforms': len(frames)}
        for k, (parent, child) in enumerate(frames):
            shape[f'transforms.{k}.header.frame_id'] = parent
            shape[f'transforms.{k}.child_frame_id'] = child
        yield None, None, shape, values


_ENCODERS = {
    '/clock': SampleMessages._clock, '/joint_states': SampleMessages._joint_states,
    '/head_pose': SampleMessages._head_pose, '/gait_state': SampleMessages._gait_state,
    '/joint_dynamics': SampleMessages._joint_dynamics, '/tf': SampleMessages._tf}
