"""What each topic's message holds of a recorded sample, written as CDR bytes by the native core.

``SampleMessages`` gives, per topic and message shape, the sample column and element of each
number (``encode``: a block's messages, the bag; ``encode_live``: the simulator node's topics);
``TOPICS``, ``RECORDED_TOPICS``. See docs/architecture.md, 'One sample form'.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
from rosbags.typesys.store import Typestore

import iceskate_native
from iceskate_native.sample import routed
from iceskate_sim.model.modes import MODES, MULTIPLIER_NAMES
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES
from iceskate_sim.recording.bag_types import PASSIVE
from iceskate_sim.recording.cdr import layout_for

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
_POSE = ('translation.x', 'translation.y', 'translation.z', 'rotation.x', 'rotation.y',
         'rotation.z', 'rotation.w')

#: A number's source: (column name, element) of the sample (``efforts.<i>``: source i's
#: efforts); per field path, one per number.
Sources = dict[str, list[tuple[str, int]]]


def _numbers(column: str, count: int, first: int = 0) -> list[tuple[str, int]]:
    return [(column, first + k) for k in range(count)]


def _routed(topic: str) -> tuple[dict[str, int], Sources]:
    """The message shape (array lengths) and sources of the sample columns routed to
    ``topic`` (``iceskate_native.sample``): a field per number, a Point's fields, or an array."""
    shape: dict[str, int] = {}
    sources: Sources = {}
    for column, route in routed(topic):
        if route.axes:
            sources.update({f'{route.path}.{axis}': [(column.name, i)]
                            for i, axis in enumerate(route.axes)})
        elif column.width == 1:
            sources[route.path] = [(column.name, 0)]
        else:
            shape[route.path] = column.width
            sources[route.path] = _numbers(column.name, column.width)
    return shape, sources


def _stamp(which: int = 0) -> list[tuple[str, int]]:
    """A builtin_interfaces/Time from ``stamps_ns``: 0 t, 1 exchange, 2 heel strike, 3 latest
    transition."""
    return [('stamps_ns', which)]


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
    """Encodes samples into the CDR bytes of the recorded topics' messages.

    :param typestore: the types (``bag_types.make_typestore()``).
    :param tf_frames: the (parent, child) frames of /tf (``Robot.tf_frames``), those of the
        samples' ``tf`` column.
    """

    def __init__(self, typestore: Typestore, tf_frames: Sequence[tuple[str, str]]) -> None:
        self.typestore = typestore
        self.tf_frames = list(tf_frames)
        self._programs: dict[tuple[str, Any], tuple[iceskate_native.CdrProgram,
                                                    tuple[str, ...]]] = {}

    def encode(self, block: Mapping[str, Any], events: Events,
               topics: Sequence[str] = RECORDED_TOPICS) -> dict[str, list[bytes]]:
        """Topic -> the bytes of its message at each row of ``block``."""
        rows = len(block['t'])
        out: dict[str, list[bytes]] = {}
        for topic in topics:
            encoded: list[bytes] = [b''] * rows
            for key, selected in _keys(topic, block, events):
                program, names = self._program(topic, key)
                arrays = [block['efforts'][int(name[len('efforts.'):])]
                          if name.startswith('efforts.') else block[name] for name in names]
                if selected is None:
                    encoded = [row.tobytes() for row in iceskate_native.encode_rows(
                        program, arrays, rows)]
                    break
                messages = iceskate_native.encode_rows(
                    program, [np.ascontiguousarray(a[selected]) for a in arrays], len(selected))
                for k, row in zip(selected.tolist(), messages, strict=True):
                    encoded[k] = row.tobytes()
            out[topic] = encoded
        return out

    def encode_live(self, loop: Any, taken: tuple[int, int, int], events: Sequence[Any],
                    topics: Sequence[str]) -> dict[str, bytes]:
        """Topic -> the bytes of its message of the live sample the native ``ControlLoop``
        ``loop`` took (its ``live_fill()``: ``taken``, its mode, latest transition and sources
        present); ``events``: the event log."""
        mode, last, _ = taken
        out = {}
        for topic in topics:
            key = (mode, events[last].cause if last >= 0 else '') if topic == '/gait_state' \
                else ((0, _LIVE_SOURCE),) if topic == '/joint_dynamics' else None
            program, names = self._program(topic, key)
            out[topic] = loop.live_messages(names, [program])[0]
        return out

    def description(self, urdf: str) -> bytes:
        """The /robot_description message holding ``urdf``."""
        return layout_for(self.typestore, TOPICS['/robot_description'], {'data': urdf}).template

    def _program(self, topic: str, key: Any) -> tuple[iceskate_native.CdrProgram,
                                                      tuple[str, ...]]:
        """The writer of ``topic``'s messages of shape ``key`` and the columns it numbers."""
        found = self._programs.get((topic, key))
        if found is None:
            shape, sources = _FIELDS[topic](self, key)
            names = tuple(dict.fromkeys(name for numbers in sources.values()
                                        for name, _ in numbers))
            index = {name: k for k, name in enumerate(names)}
            layout = layout_for(self.typestore, TOPICS[topic], shape)
            program = layout.program({path: [(index[name], element) for name, element in numbers]
                                      for path, numbers in sources.items()})
            found = self._programs[(topic, key)] = (program, names)
        return found

    # ------------------------------------------------ what each field holds, per message shape
    def _clock(self, key: None) -> tuple[dict, Sources]:
        return {}, {'clock': _stamp()}

    def _joint_states(self, key: None) -> tuple[dict, Sources]:
        shape, sources = _routed('/joint_states')
        return {'name': COORDINATE_NAMES, **shape}, {'header.stamp': _stamp(), **sources}

    def _head_pose(self, key: None) -> tuple[dict, Sources]:
        shape, sources = _routed('/head_pose')
        return {'header.frame_id': 'world', **shape}, {'header.stamp': _stamp(), **sources}

    def _gait_state(self, key: tuple[int, str]) -> tuple[dict, Sources]:
        number, cause = key
        names = _MODES[number].multipliers
        shape, sources = _routed('/gait_state')
        return {'multiplier_names': names, 'multipliers': len(names),
                'last_transition_cause': cause, **shape}, {
            'header.stamp': _stamp(), **sources,
            'multipliers': [('multipliers', MULTIPLIER_NAMES.index(name)) for name in names],
            'last_transition_stamp': _stamp(3), 'support_exchange_stamp': _stamp(1),
            'touchdown_stamp': _stamp(2)}

    def _joint_dynamics(self, key: tuple[tuple[int, str], ...]) -> tuple[dict, Sources]:
        names = [*(name for _, name in key), PASSIVE]
        efforts = [n for i, _ in key for n in _numbers(f'efforts.{i}', _N)]
        shape, sources = _routed('/joint_dynamics')
        return {'name': COORDINATE_NAMES, 'source_names': names,
                'source_efforts': _N * len(names), **shape}, {
            'header.stamp': _stamp(), **sources,
            'source_efforts': [*efforts, *_numbers('passive', _N)]}

    def _tf(self, key: None) -> tuple[dict, Sources]:
        shape: dict[str, Any] = {'transforms': len(self.tf_frames)}
        sources: Sources = {}
        for k, (parent, child) in enumerate(self.tf_frames):
            shape[f'transforms.{k}.header.frame_id'] = parent
            shape[f'transforms.{k}.child_frame_id'] = child
            sources[f'transforms.{k}.header.stamp'] = _stamp()
            for i, name in enumerate(_POSE):
                sources[f'transforms.{k}.transform.{name}'] = [('tf', 7 * k + i)]
        return shape, sources


#: the one source of the live sample (``ControlLoop.live``): the held input
_LIVE_SOURCE = 'held'

_FIELDS = {
    '/clock': SampleMessages._clock, '/joint_states': SampleMessages._joint_states,
    '/head_pose': SampleMessages._head_pose, '/gait_state': SampleMessages._gait_state,
    '/joint_dynamics': SampleMessages._joint_dynamics, '/tf': SampleMessages._tf}


def _keys(topic: str, block: Mapping[str, Any], events: Events
          ) -> Iterator[tuple[Any, np.ndarray | None]]:
    """(message shape, its rows) for each shape of ``topic``'s messages in ``block``; rows
    None when it is every row."""
    if topic == '/gait_state':
        causes = len(events.causes)
        for code, rows in _groups(block['mode'] * causes + events.cause):
            number, cause = divmod(code, causes)
            yield (number, events.causes[cause]), rows
    elif topic == '/joint_dynamics':
        sources = block['sources']
        for mask, rows in _groups(block['present']):
            yield tuple((i, sources[i]) for i in range(len(sources)) if mask >> i & 1), rows
    else:
        yield None, None


def _groups(key: np.ndarray) -> Iterator[tuple[int, np.ndarray | None]]:
    """(value, rows) for each distinct value of ``key``; rows None when it is every row."""
    first = key[0]
    if (key == first).all():
        yield int(first), None
        return
    for value in np.unique(key).tolist():
        yield value, np.flatnonzero(key == value)
