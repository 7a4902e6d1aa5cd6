"""Read a recorded run (a rosbag2 bag, MCAP storage) into time-aligned numpy arrays, without ROS.

``open_bag`` reads a bag record by record, so a bag never closed or cut short gives every message
of its complete chunks; ``BagReading`` joins the samples of the topics the analysis needs on
their header stamps, in blocks of consecutive samples (each message's row written into arrays
as it is decoded, no object per message kept), and ``read_bag`` gives them all at once. Units:
SI; times [ns] as ``t_ns``, [s] as ``t``.
"""

from __future__ import annotations

import bisect
from collections import Counter
from dataclasses import dataclass, field, fields, replace
import functools
import json
import pathlib
import re
from typing import TYPE_CHECKING, Any

from mcap.exceptions import EndOfFile
from mcap.records import Channel, Message, Schema
from mcap.stream_reader import StreamReader
import numpy as np
from rosbags.typesys import Stores, TypesysError, get_types_from_msg, get_typestore

from iceskate_analysis.rows import collect_rows
from iceskate_native.sample import Route, SampleColumn, routed
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.files import regular_file
from iceskate_sim.model.modes import MODES, MULTIPLIER_NAMES
from iceskate_sim.model.robot import COORDINATE_NAMES, N_COORDINATES, SIDES
from iceskate_sim.progress import ProgressBar
from iceskate_sim.recording.bag_types import PASSIVE, make_typestore
from iceskate_sim.ros.conversions import PIVOT_OF_CODE
from iceskate_sim.yaml_io import read_yaml

if TYPE_CHECKING:
    from collections.abc import Callable, Iterable, Iterator

    from mcap.records import McapRecord
    from rosbags.typesys.store import Typestore

    from iceskate_sim.shutdown import StopRequest

__all__ = ['BLOCK', 'BagData', 'BagReading', 'BagTopic', 'LATCHED_TOPICS', 'LATE',
           'OPTIONAL_TOPICS', 'OpenBag', 'PASSIVE', 'REQUIRED_TOPICS', 'Spacing', 'open_bag',
           'read_bag', 'resolve_bag_path']

#: Topics the analysis cannot do without, and the message type each must have.
REQUIRED_TOPICS = {
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/gait_state': 'iceskate_interfaces/msg/GaitState',
    '/joint_dynamics': 'iceskate_interfaces/msg/JointDynamics',
}
#: Topics of one state for the whole run, whose last message is kept by ``OpenBag``'s scan.
LATCHED_TOPICS = ('/robot_description',)
#: Topics read when present.
OPTIONAL_TOPICS = {
    '/head_pose': 'geometry_msgs/msg/PoseStamped',
    '/robot_description': 'std_msgs/msg/String',
}
#: Samples per block of ``BagReading.blocks``.
BLOCK = 4096
#: Header stamps a message may come after its own, at most, and still be joined
#: (``BagReading``).
LATE = 256
#: A spacing of samples over this many times the least is a gap (stamps of a thinned bag are
#: rounded to the nanosecond: their spacings differ by 1 ns).
GAP = 1.5
_WHAT = {
    '/joint_states': 'joint positions and velocities',
    '/gait_state': 'gait mode, support side and step index',
    '/joint_dynamics': 'joint accelerations and the input effort of every source',
}


@dataclass(frozen=True)
class BagData:
    """One recorded run as arrays over its N samples (index k = one control instant).

    Coordinates are ordered ``[y0, q1, ..., q17]`` (18 columns) whatever order the messages
    used. Units: SI (m, rad, s, N, N m).

    :ivar path: the bag directory (or file).
    :ivar t_ns: simulation time of each sample [ns] (N,), strictly increasing.
    :ivar q: positions (N, 18). :ivar v: velocities (N, 18).
    :ivar qdd: accelerations (N, 18), 0 where inactive. :ivar active: (N, 18) bool.
    :ivar effort_total: total input effort of /joint_states (N, 18).
    :ivar efforts: effort of each source (N, 18), keyed by source; ``'passive'`` is the
        joint damping and soft stops. A source missing at a sample counts 0 there.
    :ivar mode: Table 2 mode (N,). :ivar side: support side code, 0 right / 1 left (N,).
    :ivar pivot: 0 none / 1 toe / 2 heel (N,). :ivar step_index: support exchanges (N,).
    :ivar multipliers: (f_nz, f_ny, tau_n) per sample (N, 3), 0 where inactive.
    :ivar support_normal: N_s [N] (N,). :ivar support_friction: F_y [N] (N,).
    :ivar zmp_y: world y of the ZMP, the support foot's centre of pressure [m] (N,).
    :ivar heel_anchor_y: y_h* [m] (N,).
    :ivar last_transition_ns: time of the latest transition at or before each sample [ns]
        (N,; 0: none yet).
    :ivar head_position: head-top world position [m] (N, 3), nan without /head_pose.
    :ivar urdf: the URDF of /robot_description ('' when absent).
    :ivar custom_data: the bag's custom_data (strings; JSON for the scene parameters).
    :ivar notes: what was dropped or assumed while reading.
    """

    path: pathlib.Path
    t_ns: np.ndarray
    q: np.ndarray
    v: np.ndarray
    qdd: np.ndarray
    active: np.ndarray
    effort_total: np.ndarray
    efforts: dict[str, np.ndarray]
    mode: np.ndarray
    side: np.ndarray
    pivot: np.ndarray
    step_index: np.ndarray
    multipliers: np.ndarray
    support_normal: np.ndarray
    support_friction: np.ndarray
    zmp_y: np.ndarray
    heel_anchor_y: np.ndarray
    last_transition_ns: np.ndarray
    head_position: np.ndarray
    urdf: str = ''
    custom_data: dict[str, str] = field(default_factory=dict)
    notes: tuple[str, ...] = ()

    @property
    def t(self) -> np.ndarray:
        """Simulation time of each sample [s] (N,)."""
        return self.t_ns * 1e-9

    @property
    def n_samples(self) -> int:
        """Number of samples N."""
        return int(self.t_ns.size)

    @property
    def sources(self) -> tuple[str, ...]:
        """Input sources recorded (without ``'passive'``)."""
        return tuple(s for s in self.efforts if s != PASSIVE)

    @property
    def scene_name(self) -> str:
        """Scene name from the bag metadata ('' when unknown)."""
        return self.custom_data.get('scene', '')

    @property
    def scene_parameters(self) -> dict[str, Any]:
        """The scene mapping the run was made with ({} when the bag does not carry it)."""
        try:
            value = json.loads(self.custom_data.get('scene_parameters', ''))
        except json.JSONDecodeError:
            return {}
        return value if isinstance(value, dict) else {}

    def side_name(self, k: int) -> str:
        """Support side of sample k ('right' or 'left')."""
        return SIDES[int(self.side[k])]

    def pivot_name(self, k: int) -> str:
        """Pivot edge of the support model of sample k ('toe' while the sole is flat)."""
        return PIVOT_OF_CODE[int(self.pivot[k])]


def resolve_bag_path(path: str | pathlib.Path) -> pathlib.Path:
    """Return the bag of ``path``: the path itself (a bag directory, or an .mcap file), or
    ``path/bag`` for a run directory. A bag directory holds a metadata.yaml or, for a recording
    that was never closed, an .mcap file alone.

    :raises InputRefused: when the path does not exist or holds no rosbag2 bag.
    """
    p = pathlib.Path(path)
    if not p.exists():
        raise InputRefused(f'bag {p} does not exist')
    if p.is_dir() and not _is_bag_dir(p):
        if (p / 'bag').is_dir() and _is_bag_dir(p / 'bag'):
            return p / 'bag'
        raise InputRefused(f'{p} is not a rosbag2 bag: it holds neither a metadata.yaml '
                           'nor an .mcap file (nor a bag/ folder with one)')
    return p


def _is_bag_dir(p: pathlib.Path) -> bool:
    return (p / 'metadata.yaml').is_file() or any(p.glob('*.mcap'))


@dataclass(frozen=True)
class BagTopic:
    """A topic's channels of one message type: topic, message type, message count (``keys``:
    the channels' (file, channel id), in file order: a bag split over several files has one
    channel of the topic in each)."""

    topic: str
    msgtype: str
    count: int
    keys: tuple[tuple[int, int], ...] = field(compare=False, repr=False)


class OpenBag:
    """A bag's .mcap files, read in file order with the ``mcap`` stream reader: the messages of
    every complete chunk (CRC-checked), decoded with our typestore plus the definitions the files
    carry for other types.

    :ivar path: the bag (directory, or an .mcap file without a metadata.yaml beside it).
    :ivar topics: its channels (a topic may have several).
    :ivar custom_data: the custom_data of metadata.yaml ({} without it).
    :ivar recovered: '' for a closed bag (metadata.yaml, every file complete to its footer);
        else what was wrong with it and how much could be read.
    :ivar gaps: '' when the log times of /joint_states (the samples) have no gap, else the note
        of the gaps (``Spacing.note``).
    :ivar incompatible: message types the files define otherwise than our typestore.
    :ivar last_messages: the CDR bytes of the last message of each channel of a topic of
        ``LATCHED_TOPICS`` (keyed as ``BagTopic.keys``).
    """

    def __init__(self, path: pathlib.Path, files: list[pathlib.Path],
                 custom_data: dict[str, str], missing: str, stop: StopRequest | None = None
                 ) -> None:
        """Scan ``files`` once for their channels and message counts (``missing``: what the bag
        lacks, '' for nothing), looking for a stop signal (``stop``) at every record.

        :raises InputRefused: when a bag that is not complete holds no complete chunk.
        :raises RunInterrupted: on a stop signal (t: the log time scanned up to).
        """
        self.path, self._files, self.custom_data = path, files, custom_data
        self._typestore = _typestore()
        self.incompatible: set[str] = set()
        self.last_messages: dict[tuple[int, int], bytes] = {}
        schemas: dict[tuple[int, int], Schema] = {}
        channels: dict[tuple[int, int], Channel] = {}
        counts: Counter[tuple[int, int]] = Counter()
        problems: list[str] = []
        last = 0
        # the increasing log times of /joint_states (the samples), counted a block at a time
        spacing, sampled, latest = Spacing(), list[int](), -1
        for index, record in self._records(problems):
            if stop is not None and stop.requested:
                raise stop.error(last * 1e-9, f'scanning bag {path}')
            if isinstance(record, Schema):
                schemas[(index, record.id)] = record
            elif isinstance(record, Channel):
                channels[(index, record.id)] = record
            elif isinstance(record, Message):
                key = (index, record.channel_id)
                counts[key] += 1
                last = max(last, record.log_time)
                topic = channels[key].topic if key in channels else ''
                if topic in LATCHED_TOPICS:
                    self.last_messages[key] = record.data
                elif topic == '/joint_states' and record.log_time > latest:
                    latest = record.log_time
                    sampled.append(latest)
                    if len(sampled) == BLOCK:
                        spacing.add(np.array(sampled))
                        sampled.clear()
        spacing.add(np.array(sampled, dtype=np.int64))
        self.gaps = spacing.note()
        self.topics: list[BagTopic] = []
        for key, channel in channels.items():
            schema = schemas.get((key[0], channel.schema_id))
            if schema is not None and schema.encoding == 'ros2msg':
                self._register(schema)
            self.topics.append(BagTopic(channel.topic, schema.name if schema else '',
                                        counts[key], (key,)))
        why = missing or ('its index cannot be read' if problems else '')
        total = sum(counts.values())
        if why and not total:
            raise InputRefused(f'cannot read bag {path}: {why}, and its .mcap file holds no '
                               'complete chunk of messages (the file is truncated or '
                               f'corrupt: {"; ".join(problems) or "empty"})')
        end = f'; {"; ".join(problems)}' if problems else ''
        unknown = '' if custom_data else ' (without metadata: the scene parameters are not known)'
        self.recovered = '' if not why else (
            f'bag {path}: {why}; rebuilt from {", ".join(f.name for f in files)}: {total} '
            f'messages of its complete chunks, up to log time {last * 1e-9:.6f} s{end}{unknown}')

    def _records(self, problems: list[str]) -> Iterator[tuple[int, McapRecord]]:
        """(file index, record) of every record of the files, those of a chunk once the whole
        chunk is read and checked; what ended a file early is appended to ``problems``."""
        for index, path in enumerate(self._files):
            with path.open('rb') as stream:
                try:
                    for record in StreamReader(stream, validate_crcs=True,
                                               record_size_limit=1 << 30).records:
                        yield index, record
                except Exception as exc:  # noqa: BLE001 (the mcap package's many kinds)
                    problems.append(
                        f'{path.name} stops early, it ends inside a record: the rest did not '
                        'reach the disk' if isinstance(exc, EndOfFile) else
                        f'{path.name} is damaged, a broken record '
                        f'({str(exc) or type(exc).__name__}): nothing after it is read')

    def _register(self, schema: Schema) -> None:
        """Add the file's definition of ``schema.name`` to the typestore, or note the type as
        incompatible when the typestore defines it (or a type it uses) otherwise."""
        try:
            types = get_types_from_msg(schema.data.decode(), schema.name)
        except (TypesysError, UnicodeDecodeError):  # unreadable: the type stays ours or unknown
            return
        try:
            self._typestore.register(types)
        except TypesysError:
            self.incompatible.add(schema.name)

    def messages(self, topics: Iterable[BagTopic]) -> Iterator[tuple[BagTopic, int, bytes]]:
        """(topic, log time [ns], CDR bytes) of every message of ``topics``, in file order."""
        wanted = {key: t for t in topics for key in t.keys}
        for index, record in self._records([]):
            if isinstance(record, Message) and (index, record.channel_id) in wanted:
                yield wanted[(index, record.channel_id)], record.log_time, record.data

    def deserialize(self, raw: bytes, msgtype: str) -> Any:
        """The message object of CDR bytes."""
        return self._typestore.deserialize_cdr(raw, msgtype)

    def knows(self, msgtype: str) -> bool:
        """Whether messages of ``msgtype`` can be decoded."""
        return msgtype in self._typestore.fielddefs


def open_bag(path: str | pathlib.Path, stop: StopRequest | None = None) -> OpenBag:
    """Open a bag (a bag or run directory, or an .mcap file) for reading. A bag without
    metadata.yaml (never closed: a killed run, a power cut) or with a file cut short is read as
    far as it reached the disk; ``recovered`` says so and how much was read. Its files must be
    regular files (``_check_regular``).

    :raises InputRefused: naming the bag and the problem.
    :raises RunInterrupted: on a signal of ``stop`` while its files are scanned.
    """
    bag = resolve_bag_path(path)
    if not bag.is_dir():
        _check_regular([bag])
        if not (bag.parent / 'metadata.yaml').is_file():
            return OpenBag(bag, [bag], {}, 'it has no metadata.yaml beside it', stop)
        bag = bag.parent
    files = sorted(bag.glob('*.mcap'), key=_recording_order)
    metadata = bag / 'metadata.yaml'
    _check_regular([*files, *([metadata] if metadata.exists() else [])])
    if not metadata.is_file():
        return OpenBag(bag, files, {}, 'it has no metadata.yaml (the recording was not '
                       'closed: a killed run or a power cut)', stop)
    if not files:
        raise InputRefused(f'cannot open bag {bag}: it holds no .mcap file (only MCAP bags '
                           'are read)')
    return OpenBag(bag, files, _metadata_custom_data(metadata), '', stop)


def _check_regular(paths: Iterable[pathlib.Path]) -> None:
    """Refuse a bag's file that is not a regular file, before it is opened.

    :raises InputRefused: naming the file and what it is.
    """
    for path in paths:
        regular_file(path, 'bag file')


def _recording_order(path: pathlib.Path) -> tuple[tuple[int, int | str], ...]:
    """Sort key of a bag's files in the order they were recorded: their names with the
    numbers compared as numbers (rosbag2 names a split bag's files ``<bag>_0.mcap``,
    ``<bag>_1.mcap``, ... ``<bag>_10.mcap``)."""
    return tuple((0, int(part)) if part.isdigit() else (1, part)
                 for part in re.split(r'(\d+)', path.name) if part)


def _metadata_custom_data(metadata: pathlib.Path) -> dict[str, str]:
    """custom_data of a rosbag2 metadata.yaml ({} if it cannot be read)."""
    try:
        info = read_yaml(metadata, 'bag metadata')['rosbag2_bagfile_information']
        return {str(k): str(v) for k, v in (info.get('custom_data') or {}).items()}
    except (SimulationError, TypeError, KeyError, AttributeError):
        return {}


def _typestore() -> Typestore:
    """Our typestore; without iceskate_interfaces installed, ROS 2 Jazzy's (the bag's own
    definitions then add ours)."""
    try:
        return make_typestore()
    except (FileNotFoundError, SimulationError):
        return get_typestore(Stores.ROS2_JAZZY)


def _stamp_ns(msg: Any) -> int:
    stamp = msg.header.stamp
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def _order(names: Iterable[str], topic: str, where: str) -> np.ndarray:
    """Indices that reorder a message's arrays into COORDINATE_NAMES order."""
    names = list(names)
    if names == list(COORDINATE_NAMES):
        return np.arange(N_COORDINATES)
    missing = [n for n in COORDINATE_NAMES if n not in names]
    if missing:
        raise InputRefused(f'{topic} at {where}: coordinates {missing} missing from the '
                           f'names {names}')
    return np.array([names.index(n) for n in COORDINATE_NAMES], dtype=np.intp)


def _vector(values: Any, order: np.ndarray, topic: str, what: str, where: str) -> np.ndarray:
    x = np.asarray(values, dtype=float)
    if x.shape[0] <= int(order.max()):
        raise InputRefused(f'{topic} at {where}: {what} has {x.shape[0]} entries, need '
                           f'{N_COORDINATES}')
    return x[order]


def _check_connections(reader: OpenBag, path: pathlib.Path) -> dict[str, BagTopic]:
    """Return the connection of each required/optional topic; refuse missing or odd ones."""
    by_topic: dict[str, list[BagTopic]] = {}
    for conn in reader.topics:
        by_topic.setdefault(conn.topic, []).append(conn)
    chosen: dict[str, BagTopic] = {}
    for topic, expected in {**REQUIRED_TOPICS, **OPTIONAL_TOPICS}.items():
        conns = by_topic.get(topic, [])
        if not conns:
            if topic in REQUIRED_TOPICS:
                raise InputRefused(
                    f'bag {path} has no topic {topic} ({expected}): the {_WHAT[topic]} are '
                    f'needed for the coupling analysis; topics present: {sorted(by_topic)}')
            continue
        other = next((c.msgtype for c in conns if c.msgtype != expected), None)
        if other is not None:
            raise InputRefused(f'bag {path}: topic {topic} has message type '
                               f'{other}, expected {expected}')
        if expected in reader.incompatible:
            raise InputRefused(f'bag {path}: topic {topic} was recorded with an incompatible '
                               f'message definition: the bag defines {expected} otherwise '
                               'than the installed interfaces')
        if not reader.knows(expected):
            raise InputRefused(
                f'bag {path}: message type {expected} of topic {topic} is unknown: the bag '
                'carries no definition of it and the iceskate_interfaces .msg files were not '
                'found (build ros_ws or run from the source tree)')
        conn = BagTopic(topic, expected, sum(c.count for c in conns),
                        tuple(sorted(key for c in conns for key in c.keys)))
        if topic in REQUIRED_TOPICS and conn.count == 0:
            raise InputRefused(f'bag {path}: topic {topic} has no messages: no '
                               f'{_WHAT[topic]} were recorded')
        chosen[topic] = conn
    return chosen


def _value(msg: Any, path: str) -> Any:
    """The field ``path`` ('zmp.y') of a decoded message."""
    return functools.reduce(getattr, path.split('.'), msg)


def _read_back(topic: str) -> list[tuple[SampleColumn, Route]]:
    """The sample columns ``BagData`` holds that ``topic``'s messages give back, with their
    route there."""
    held = {f.name for f in fields(BagData)}
    return [(column, route) for column, route in routed(topic, read_back=True)
            if column.name in held]


def _routed_reader(topic: str) -> Callable[[Any, str, np.ndarray | None], list[Any]]:
    """What ``topic``'s messages give back of the sample columns (``_read_back``):
    reader(msg, where, order of its coordinate arrays) -> a value per column. A JointState's
    effort may be empty (0)."""
    parts = _read_back(topic)

    def read(msg: Any, where: str, order: np.ndarray | None) -> list[Any]:
        values: list[Any] = []
        for column, route in parts:
            value = _value(msg, route.path)
            if route.axes:
                value = np.array([getattr(value, axis) for axis in route.axes], dtype=float)
            elif column.width == N_COORDINATES:
                if route.path == 'effort' and len(value) == 0:
                    value = np.zeros(N_COORDINATES)
                else:
                    value = _vector(value, order, topic, route.path, where)
            values.append(value)
        return values
    return read


def _joint_states(msg: Any, where: str) -> list[Any]:
    return _READ_ROUTED['/joint_states'](msg, where, _order(msg.name, '/joint_states', where))


def _gait_state(msg: Any, where: str) -> list[Any]:
    multipliers = np.zeros(len(MULTIPLIER_NAMES))
    if len(msg.multiplier_names) != len(msg.multipliers):
        raise InputRefused(f'/gait_state at {where}: {len(msg.multiplier_names)} multiplier '
                           f'names but {len(msg.multipliers)} values')
    for name, value in zip(msg.multiplier_names, msg.multipliers, strict=True):
        if name in MULTIPLIER_NAMES:
            multipliers[MULTIPLIER_NAMES.index(name)] = float(value)
    last = msg.last_transition_stamp
    return [*_READ_ROUTED['/gait_state'](msg, where, None), multipliers,
            int(last.sec) * 1_000_000_000 + int(last.nanosec)]


def _joint_dynamics(msg: Any, where: str) -> list[Any]:
    if len(msg.acceleration) == 0:
        raise InputRefused(f'/joint_dynamics at {where}: the message carries no joint '
                           'accelerations (empty acceleration array)')
    order = _order(msg.name, '/joint_dynamics', where)
    sources = [str(s) for s in msg.source_names]
    if len(set(sources)) != len(sources):
        raise InputRefused(f'/joint_dynamics at {where}: repeated source names {sources}')
    n = len(msg.name)
    values = np.asarray(msg.source_efforts, dtype=float)
    if values.shape != (len(sources) * n,):
        raise InputRefused(f'/joint_dynamics at {where}: source_efforts has {values.size} '
                           f'values for {len(sources)} sources x {n} names')
    efforts = {source: _vector(row, order, '/joint_dynamics', f'effort of {source!r}', where)
               for source, row in zip(sources, values.reshape(len(sources), n), strict=True)}
    return [*_READ_ROUTED['/joint_dynamics'](msg, where, order), efforts]


def _head_pose(msg: Any, where: str) -> list[Any]:
    return _READ_ROUTED['/head_pose'](msg, where, None)


#: What a message of each sampled topic gives: reader(msg, where) -> its row.
_READERS = {'/joint_states': _joint_states, '/gait_state': _gait_state,
            '/joint_dynamics': _joint_dynamics, '/head_pose': _head_pose}
_READ_ROUTED = {topic: _routed_reader(topic) for topic in _READERS}


def _row_dtype(column: SampleColumn) -> type:
    """How the bag's rows hold a column: messages' bools as bool, integers as int64."""
    if column.dtype == np.uint8:
        return bool
    return np.int64 if column.dtype.kind in 'iu' else float


#: The fields of each sampled topic's rows: (name, shape of one row, dtype), in row order: the
#: sample columns it gives back, then /gait_state's multipliers (by name) and latest transition
#: (``/joint_dynamics``' last value, the efforts by source, is kept apart: ``_Table.efforts``).
_FIELDS = {topic: (*((column.name, column.shape(), _row_dtype(column))
                     for column, _ in _read_back(topic)),
                   *((('multipliers', (len(MULTIPLIER_NAMES),), float),
                      ('last_transition_ns', (), np.int64)) if topic == '/gait_state' else ()))
           for topic in _READERS}


class _Table:
    """The rows of one sampled topic not yet joined, as arrays filled in place as the messages
    are read: no Python object per message is kept."""

    def __init__(self, topic: str, capacity: int) -> None:
        self.by_source = topic == '/joint_dynamics'  # its rows end with the efforts by source
        self.size = 0
        self.stamps = np.zeros(max(capacity, 1), dtype=np.int64)
        self.fields = {name: np.zeros((self.stamps.size, *shape), dtype=dtype)
                       for name, shape, dtype in _FIELDS[topic]}
        self.efforts: dict[str, np.ndarray] = {}  # /joint_dynamics: source -> (capacity, 18)
        # source -> its place among each row's sources (-1: the row does not carry it)
        self.places: dict[str, np.ndarray] = {}

    def append(self, stamp: int, row: list[Any]) -> None:
        """Add a message's row (``_READERS``' output) at header ``stamp`` [ns]."""
        k = self.size
        if k == self.stamps.size:
            self._grow()
        self.stamps[k] = stamp
        values, by_source = (row[:-1], row[-1]) if self.by_source else (row, {})
        for array, value in zip(self.fields.values(), values, strict=True):
            array[k] = value
        for places in self.places.values():  # a slot may hold a dropped row's
            places[k] = -1
        for place, (source, tau) in enumerate(by_source.items()):
            if source not in self.efforts:
                self.efforts[source] = np.zeros((self.stamps.size, N_COORDINATES))
                self.places[source] = np.full(self.stamps.size, -1, dtype=np.int32)
            self.efforts[source][k] = tau
            self.places[source][k] = place
        self.size = k + 1

    def _groups(self) -> tuple[tuple[dict[str, np.ndarray], int], ...]:
        return (self.fields, 0), (self.efforts, 0), (self.places, -1)

    def _grow(self) -> None:
        def grown(a: np.ndarray, fill: int) -> np.ndarray:
            return np.concatenate([a, np.full((a.shape[0], *a.shape[1:]), fill, a.dtype)])
        self.stamps = grown(self.stamps, 0)
        for group, fill in self._groups():
            for name in group:
                group[name] = grown(group[name], fill)

    def latest(self, before: int | None) -> tuple[np.ndarray, np.ndarray, int]:
        """(stamps, row of each, rows read): every header stamp below ``before`` (None: every
        one) once, increasing, with the row of its last message; and how many rows have those
        stamps."""
        reversed_stamps = self.stamps[:self.size][::-1]
        stamps, first = np.unique(reversed_stamps, return_index=True)
        rows = self.size - 1 - first
        if before is None:
            return stamps, rows, self.size
        below = stamps < before
        return stamps[below], rows[below], int(np.sum(self.stamps[:self.size] < before))

    def drop_before(self, before: int | None) -> None:
        """Forget the rows stamped below ``before`` (None: all)."""
        keep = (np.zeros(self.size, dtype=bool) if before is None
                else self.stamps[:self.size] >= before)
        dropped = self.size - int(keep.sum())
        if dropped:
            arrays = [self.stamps, *(a for group, _ in self._groups() for a in group.values())]
            for a in arrays:
                a[:self.size - dropped] = a[:self.size][keep]
            self.size -= dropped


class BagReading:
    """A bag's samples, read in blocks of consecutive samples: the sampled topics are joined on
    their header stamps as the messages come, a stamp once every sampled topic still to come is
    ``LATE`` stamps past it (``_Cut``), so what is held is a block and ``LATE`` rows of each
    topic, whatever the length of the bag (while no topic stalls). A sample needs all of
    ``REQUIRED_TOPICS`` (a repeated stamp: each topic's last message of it).

    :ivar path: the bag. :ivar custom_data: its metadata's custom_data.
    :ivar urdf: the URDF of /robot_description ('' when the bag has none).
    :ivar notes: what was dropped or assumed; complete once ``blocks`` is exhausted.
    """

    def __init__(self, path: str | pathlib.Path, progress: bool = False,
                 stop: StopRequest | None = None) -> None:
        """Open the bag and check its topics; the scan of its files and ``blocks`` look for
        a stop signal (``stop``) at every record.

        :raises InputRefused: as ``read_bag``.
        :raises RunInterrupted: on a stop signal.
        """
        self._stop = stop
        self._reader = open_bag(path, stop)
        self.path = self._reader.path
        self.custom_data = self._reader.custom_data
        self._chosen = _check_connections(self._reader, self.path)
        self._progress = progress
        self.urdf = ''
        description = self._chosen.get('/robot_description')
        latched = [key for key in description.keys if key in self._reader.last_messages] \
            if description is not None else []
        if latched:  # the last file's
            raw = self._reader.last_messages[latched[-1]]
            self.urdf = str(self._decode(description, 'its last message', raw).data)
        self.notes: list[str] = []

    @property
    def sample_bound(self) -> int:
        """The most samples the bag can give (its /joint_states messages)."""
        return self._chosen['/joint_states'].count

    def blocks(self, size: int = BLOCK) -> Iterator[BagData]:
        """The samples in time order, at most ``size`` per block; each block is checked
        (``_validate``) before it is given.

        :raises InputRefused: as ``read_bag``, when the block it concerns is reached.
        :raises RunInterrupted: on a stop signal (t: the log time read up to).
        """
        sampled = [t for t in _READERS if t in self._chosen and self._chosen[t].count]
        tables = {t: _Table(t, min(self._chosen[t].count, size + 2 * LATE)
                            if t in self._chosen else 0) for t in _READERS}
        join = _Join(self.path, self.custom_data, self.urdf)
        cut = _Cut({t: self._chosen[t].count for t in sampled})
        bar = ProgressBar(sum(self._chosen[t].count for t in sampled),
                          f'reading {self.path.name}', 'msg', self._progress, leave=False)
        due = size + LATE  # rows of /joint_states that call for a join
        try:
            for conn, log_ns, raw in self._reader.messages(self._chosen[t] for t in sampled):
                if self._stop is not None and self._stop.requested:
                    raise self._stop.error(log_ns * 1e-9, f'reading bag {self.path}')
                bar.update(1)
                msg = self._decode(conn, f'log time {log_ns * 1e-9:.6f} s', raw)
                stamp = _stamp_ns(msg)
                if not cut.admit(conn.topic, stamp):
                    join.late += 1
                    continue
                where = f'log time {log_ns * 1e-9:.6f} s'
                try:
                    tables[conn.topic].append(stamp, _READERS[conn.topic](msg, where))
                except AttributeError as exc:
                    raise InputRefused(
                        f'bag {self.path}: {conn.topic} message at {where} lacks a field the '
                        f'analysis needs ({exc}); the bag was recorded with an incompatible '
                        'message definition') from exc
                if tables['/joint_states'].size >= due:
                    yield from join.samples(tables, cut.stamp, size)
                    # a topic that stalls holds the others back: wait for twice as much
                    due = max(size + LATE, 2 * tables['/joint_states'].size)
            yield from join.samples(tables, None, size)
        finally:
            bar.close()
        self.notes = ([self._reader.recovered] if self._reader.recovered else []) + join.notes()

    def _decode(self, conn: BagTopic, where: str, raw: bytes) -> Any:
        try:
            return self._reader.deserialize(raw, conn.msgtype)
        except Exception as exc:  # noqa: BLE001 (rosbags raises several kinds)
            raise InputRefused(f'bag {self.path}: cannot decode a {conn.msgtype} message of '
                               f'{conn.topic} at {where} ({exc})') from exc


class _Cut:
    """The header stamp below which every sample is final: ``LATE`` distinct stamps behind the
    newest of the sampled topic that lags most (a topic whose messages were all read holds
    nothing back). It only rises, and a message stamped below it comes too late to be joined,
    so the samples do not depend on when they are joined."""

    def __init__(self, counts: dict[str, int]) -> None:
        """``counts``: the messages of each sampled topic."""
        self.left = dict(counts)  # messages still to come
        self.newest: dict[str, list[int]] = {t: [] for t in counts}  # at most LATE, increasing
        self.stamp = -1  # [ns]

    def admit(self, topic: str, stamp: int) -> bool:
        """Whether a message of ``topic`` stamped ``stamp`` [ns] can still be joined."""
        self.left[topic] -= 1
        admitted = stamp >= self.stamp
        newest = self.newest[topic]
        k = bisect.bisect_left(newest, stamp)
        if admitted and (k == len(newest) or newest[k] != stamp):
            newest.insert(k, stamp)
            if len(newest) > LATE:
                del newest[0]
        self.stamp = max(self.stamp, min(
            np.iinfo(np.int64).max if self.left[t] <= 0 else
            self.newest[t][0] if len(self.newest[t]) == LATE else -1 for t in self.newest))
        return admitted


class _Join:
    """Joins the rows of the tables into samples, one stretch of stamps at a time, and counts
    what it drops for the notes."""

    def __init__(self, path: pathlib.Path, custom: dict[str, str], urdf: str) -> None:
        self.path, self.custom, self.urdf = path, custom, urdf
        self.sources: list[str] = []  # every source, by the first sample that carries it
        self.emitted = 0  # samples given
        self.missing = self.duplicates = self.late = self.heads = 0
        self.stamps = {t: 0 for t in REQUIRED_TOPICS}  # distinct stamps of each
        self.spacing = Spacing()  # of the samples given

    def samples(self, tables: dict[str, _Table], before: int | None, size: int
                ) -> Iterator[BagData]:
        """The samples stamped below ``before`` (None: all left), in blocks of ``size``;
        their rows are then dropped from the tables."""
        latest = {}
        for topic, table in tables.items():
            stamps, rows, read = table.latest(before)
            if topic in REQUIRED_TOPICS:
                self.duplicates += read - stamps.size
                self.stamps[topic] += stamps.size
            latest[topic] = stamps, rows
        stamps = functools.reduce(functools.partial(np.intersect1d, assume_unique=True),
                                  (latest[t][0] for t in REQUIRED_TOPICS))
        union = functools.reduce(np.union1d, (latest[t][0] for t in REQUIRED_TOPICS))
        self.missing += union.size - stamps.size
        for start in range(0, stamps.size, size):
            yield self._block(tables, latest, stamps[start:start + size])
        for table in tables.values():
            table.drop_before(before)

    def _block(self, tables: dict[str, _Table],
               latest: dict[str, tuple[np.ndarray, np.ndarray]], stamps: np.ndarray
               ) -> BagData:
        columns: dict[str, np.ndarray] = {}
        for topic in REQUIRED_TOPICS:
            known, rows = latest[topic]
            rows = rows[np.searchsorted(known, stamps)]
            table = tables[topic]
            for name, array in table.fields.items():
                columns[name] = array[rows]
            if topic == '/joint_dynamics':  # new sources by the first sample that carries
                # them, then their place in it
                places = {s: table.places[s][rows] for s in table.efforts}
                first = {s: (int(np.argmax(p >= 0)), int(p[np.argmax(p >= 0)]))
                         for s, p in places.items() if s not in self.sources and np.any(p >= 0)}
                self.sources += sorted(first, key=first.get)
                efforts = {s: table.efforts[s][rows] for s in self.sources}
                for s in self.sources:  # a source a row does not carry counts 0 there
                    efforts[s][places[s] < 0] = 0.0
        known, rows = latest['/head_pose']
        at = np.minimum(np.searchsorted(known, stamps), max(known.size - 1, 0))
        has = known[at] == stamps if known.size else np.zeros(stamps.size, dtype=bool)
        head_position = np.full((stamps.size, 3), np.nan)
        head_position[has] = tables['/head_pose'].fields['head_position'][rows[at[has]]]
        self.heads += int(has.sum())
        self.emitted += stamps.size
        self.spacing.add(stamps)
        data = BagData(path=self.path, t_ns=stamps, efforts=efforts,
                       head_position=head_position, urdf=self.urdf, custom_data=self.custom,
                       **columns)
        _validate(data)
        return data

    def notes(self) -> list[str]:
        """What was dropped or assumed, once every sample was given.

        :raises InputRefused: when no sample had every required topic.
        """
        if not self.emitted:
            raise InputRefused(f'bag {self.path}: no sample has all of '
                               f'{sorted(REQUIRED_TOPICS)} at the same header stamp '
                               f'(header stamps per topic: {self.stamps})')
        notes = []
        if self.missing:
            notes.append(f'{self.missing} sample(s) miss one of {sorted(REQUIRED_TOPICS)} '
                         'and were dropped')
        if self.duplicates:
            notes.append(f'{self.duplicates} message(s) repeated a header stamp; the later one '
                         'was kept')
        if self.late:
            notes.append(f'{self.late} message(s) came {LATE} samples or more after their '
                         'header stamp and were dropped')
        if not self.heads:
            notes.append('no /head_pose at any sample: head positions are nan')
        if not self.urdf:
            notes.append('no /robot_description: the installed URDF is assumed')
        gaps = self.spacing.note()
        if gaps:
            notes.append(gaps)
        return notes


class Spacing:
    """The spacings of increasing stamps given a block at a time, counted in bins of 1/64
    octave (``_bin``), for the note of the gaps among them (``note``): a spacing over ``GAP``
    times the least is a gap."""

    def __init__(self) -> None:
        self.last: int | None = None  # the last stamp given [ns]
        self.least = 0  # the least spacing [ns]
        self.spacings: dict[int, int] = {}  # spacing bin -> how many
        self.longest = (0, 0)  # the longest spacing [ns] and the stamp before it

    def add(self, stamps: np.ndarray) -> None:
        """Count the spacings of ``stamps`` [ns] (increasing, after the last given)."""
        if not stamps.size:
            return
        starts = stamps if self.last is None else np.concatenate([[self.last], stamps])
        steps = np.diff(starts)
        self.last = int(stamps[-1])
        if not steps.size:
            return
        self.least = int(steps.min()) if not self.least else min(self.least, int(steps.min()))
        for spacing, count in zip(*np.unique(_bin(steps), return_counts=True), strict=True):
            self.spacings[int(spacing)] = self.spacings.get(int(spacing), 0) + int(count)
        k = int(np.argmax(steps))
        if steps[k] > self.longest[0]:
            self.longest = (int(steps[k]), int(starts[k]))

    def note(self) -> str:
        """What the gaps are ('' for none)."""
        gaps = sum(n for spacing, n in self.spacings.items()
                   if spacing > _bin(np.array([GAP * self.least]))[0])
        if not gaps:
            return ''
        step, start = self.longest
        return (f'the samples have {gaps} gap(s) (sampled every {self.least * 1e-9:g} s); the '
                f'longest from t = {start * 1e-9:.6f} s to {(start + step) * 1e-9:.6f} s')


def _bin(spacings: np.ndarray) -> np.ndarray:
    """Bins of 1/64 octave of spacings [ns] (a count of every distinct spacing of jittered
    stamps would grow with the bag)."""
    return np.round(64.0 * np.log2(np.maximum(spacings, 1))).astype(np.int64)


def _validate(data: BagData) -> None:
    bad_modes = sorted(set(data.mode[~np.isin(data.mode, list(MODES))].tolist()))
    if bad_modes:
        raise InputRefused(f'bag {data.path}: /gait_state has modes {bad_modes} outside '
                           f'the mode table (1-{len(MODES)})')
    if np.any((data.side < 0) | (data.side > 1)) or np.any((data.pivot < 0) | (data.pivot > 2)):
        raise InputRefused(f'bag {data.path}: /gait_state has an unknown support_side or '
                           'pivot code')
    for name, x in (('positions', data.q), ('velocities', data.v),
                    ('accelerations', data.qdd)):
        if not np.all(np.isfinite(x)):
            k = int(np.flatnonzero(~np.all(np.isfinite(x), axis=1))[0])
            raise InputRefused(f'bag {data.path}: non-finite joint {name} at t = '
                               f'{data.t[k]:.6f} s')


def read_bag(path: str | pathlib.Path, progress: bool = False) -> BagData:
    """Read a recorded run into time-aligned arrays, all of it at once (``BagReading`` gives
    it in blocks).

    A bag that was never closed (no metadata.yaml: a killed run) or whose file was cut is
    rebuilt from what reached the disk (``open_bag``); the first note says so.

    :param path: rosbag2 directory (or a run directory holding ``bag/``, or an .mcap file).
    :param progress: show a tqdm progress bar on stderr.
    :return: the samples joined on their header stamps.
    :raises InputRefused: on a missing path, a missing or empty required topic, a topic of
        the wrong or an unknown message type, a file with no complete chunk, or messages that
        lack the fields the analysis needs; the message names what is wrong.
    """
    reading = BagReading(path, progress)
    # small blocks: little is held beside the arrays
    whole = collect_rows(reading.blocks(LATE), reading.sample_bound)
    return replace(whole, notes=tuple(reading.notes))
