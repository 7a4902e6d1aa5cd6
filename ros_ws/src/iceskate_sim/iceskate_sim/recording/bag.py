"""Recording a run to a rosbag2 bag (MCAP) with ``rosbags``, without ROS.

One sample per control period, stamped with the simulation time of the state, on the topics
the ROS simulator node publishes, so a headless run and a ROS run give the same bag layout and
the offline analysis reads either:

* ``/clock`` (rosgraph_msgs/Clock)
* ``/joint_states`` (sensor_msgs/JointState): the 18 coordinates y0, q1..q17; position,
  velocity and the total input effort held over the period
* ``/head_pose`` (geometry_msgs/PoseStamped, frame ``world``): the head-top frame
* ``/gait_state`` (iceskate_interfaces/GaitState): the whole hybrid state (q, v and the
  discrete part), what the controllers read
* ``/joint_dynamics`` (iceskate_interfaces/JointDynamics): accelerations at the sample and the
  effort of every input source (plus ``passive``: damping and soft stops)
* ``/tf`` (tf2_msgs/TFMessage): the world pose of every URDF link as a viewer expects it
  (robot_state_publisher's layout, ``LinkTransforms``): ``world`` -> the URDF's root link, then
  parent link -> child link for every URDF joint, the fixed ones included in every message; with
  ``/robot_description`` it shows the robot moving (e.g. in Foxglove). Bags only: the live
  simulator node does not publish it (no tf2_msgs for rclpy here).
* ``/robot_description`` (std_msgs/String, once): the URDF

Bag metadata (``custom_data``) holds the scene, its parameters, the integrator and the project
version.

Serialising the messages with rosbags costs more than a native control period, so the bag
writes them through ``RecordEncoder``: the same bytes, patched into layouts learned from
rosbags, for a whole ``RecordBlock`` of samples at once (column by column, a few numpy
operations per topic and layout). ``BagRecorder(..., background=True)`` hands the samples, packed
into float arrays (``BagRecord`` one by one, ``RecordBlock`` as the native loop returns them), to
a writer process that encodes and writes the messages while the simulation goes on (the bag's
messages are byte-identical to an in-process recording). The writer also computes the /tf link
poses from the records' q, side and pivot (the robot model is loaded before the fork), so /tf
costs the simulating process nothing.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
import gc
import json
import math
import multiprocessing
from multiprocessing.connection import Connection
import os
import pathlib
import queue
import signal
import struct
from typing import Any, NamedTuple

import numpy as np
import pinocchio as pin
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys.store import Typestore

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import DynamicsResult
from iceskate_sim.model.modes import get_mode
from iceskate_sim.model.robot import (
    COORDINATE_NAMES,
    N_COORDINATES,
    PIVOTS,
    SIDES,
    SOLE_HEEL_Y,
    SOLE_TOE_Y,
    Robot,
    anatomical_map,
    load_robot,
)
from iceskate_sim.model.stamps import ns_to_sec_nanosec, seconds_to_ns
from iceskate_sim.physics.hybrid import HybridState, Transition
from iceskate_sim.recording.bag_bulk import write_many
from iceskate_sim.recording.bag_types import OFFERED_QOS, PASSIVE, make_typestore
from iceskate_sim.shutdown import STOP_SIGNALS, die_with_parent

PROJECT_VERSION = '0.1.0'
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
PIVOT_CODE = {'toe': 1, 'heel': 2}
BATCH = 100  # samples per hand-over to the writer process
QUEUE_BATCHES = 40  # batches in flight before ``write`` waits for the writer process


@dataclass
class Sample:
    """Everything recorded at one control instant t_k.

    :param state: hybrid state at t_k.
    :param result: dynamics at t_k under the inputs held over [t_k, t_k+1] (accelerations,
        multipliers, support forces).
    :param efforts: input torque of each source over [t_k, t_k+1] (18-vectors, N m).
    :param head_pose: head-top world position (3,) [m] and rotation (3x3).
    :param last_transition: the latest transition of the event log (None: none yet).
    """

    state: HybridState
    result: DynamicsResult
    efforts: dict[str, np.ndarray]
    head_position: np.ndarray
    head_rotation: np.ndarray
    last_transition: Transition | None


_N = N_COORDINATES
_SCALARS = 8  # t, t_exchange, t_touchdown, heel_anchor_y, N_s, F_y, CoP y, last transition t
_Q, _V, _QDD, _PASSIVE = (slice(_SCALARS + k * _N, _SCALARS + (k + 1) * _N) for k in range(4))
_MULT = slice(_PASSIVE.stop, _PASSIVE.stop + 3)
_HEAD_P = slice(_MULT.stop, _MULT.stop + 3)
_HEAD_R = slice(_HEAD_P.stop, _HEAD_P.stop + 9)
_EFFORTS = _HEAD_R.stop


class BagRecord(NamedTuple):
    """What the bag holds of a Sample, cheap to pickle: the floats packed into ``values``.

    ``values``: t, t_exchange, t_touchdown, heel_anchor_y [s, m], N_s, F_y [N], CoP y [m], time
    of the last transition [s] (0 if none), then q, v, qdd, passive (18 each), multipliers (3),
    head position (3) and rotation (9, row-major), then the effort of each of ``sources`` (18
    each). Discrete fields as in ``HybridState``; ``last_cause`` None before any transition.
    """

    values: np.ndarray
    mode: int
    side: str
    pivot: str
    step_index: int
    sources: tuple[str, ...]
    last_cause: str | None


def bag_record(sample: Sample) -> BagRecord:
    """Pack ``sample`` into a BagRecord (exact copies of its values)."""
    s, r, last = sample.state, sample.result, sample.last_transition
    head = (s.t, s.t_exchange, s.t_touchdown, s.contact.heel_anchor_y, r.support_normal,
            r.support_tangential, r.cop_y, last.t if last else 0.0)
    values = np.concatenate([head, s.q, s.v, r.qdd, r.passive, r.multipliers,
                             sample.head_position, np.ravel(sample.head_rotation),
                             *sample.efforts.values()], dtype=np.float64)
    return BagRecord(values, s.mode.number, s.contact.side, s.contact.pivot, s.step_index,
                     tuple(sample.efforts), last.cause if last else None)


class RecordBlock(NamedTuple):
    """Consecutive BagRecords column by column, cheap to pickle and to encode at once.

    :ivar values: (n, V) each record's values up to its efforts (``BagRecord.values``).
    :ivar efforts: (n, K, 18) the efforts of each record's sources, in their order (zero past
        them).
    :ivar source_sets: the distinct source tuples; ``source_set`` (n,) indexes them.
    :ivar codes: (n, 4) mode number, side (index in SIDES), pivot (index in PIVOTS), step index.
    :ivar causes: the distinct last-transition causes (None: none yet); ``cause`` (n,)
        indexes them.
    """

    values: np.ndarray
    efforts: np.ndarray
    source_sets: tuple[tuple[str, ...], ...]
    source_set: np.ndarray
    codes: np.ndarray
    causes: tuple[str | None, ...]
    cause: np.ndarray

    def __len__(self) -> int:
        """Records in the block."""
        return self.values.shape[0]

    @classmethod
    def of_records(cls, records: list[BagRecord]) -> RecordBlock:
        """The block of these records (their values copied exactly)."""
        sets = list(dict.fromkeys(r.sources for r in records))
        causes = list(dict.fromkeys(r.last_cause for r in records))
        width = max(len(s) for s in sets)
        values = np.array([r.values[:_EFFORTS] for r in records]).reshape(-1, _EFFORTS)
        efforts = np.zeros((len(records), width, _N))
        for k, r in enumerate(records):
            efforts[k, :len(r.sources)] = r.values[_EFFORTS:].reshape(-1, _N)
        codes = np.array([(r.mode, SIDES.index(r.side), PIVOTS.index(r.pivot), r.step_index)
                          for r in records], dtype=np.int64).reshape(-1, 4)
        return cls(values, efforts, tuple(sets),
                   np.array([sets.index(r.sources) for r in records], dtype=np.intp), codes,
                   tuple(causes),
                   np.array([causes.index(r.last_cause) for r in records], dtype=np.intp))

    @classmethod
    def of_columns(cls, columns: dict[str, np.ndarray], efforts: dict[str, np.ndarray],
                   present: np.ndarray, events: list[Transition]) -> RecordBlock:
        """The block of a native block of samples (the values ``bag_record`` packs).

        :param columns: the block's columns as ``iceskate_native.ControlLoop.run`` returns them
            (t, t_exchange, t_touchdown, heel_anchor_y, support_normal, support_tangential,
            cop_y, q, v, qdd, passive, multipliers, head_position, head_rotation (n, 3, 3), mode,
            side and pivot codes, step_index, last_event: index in ``events``, -1 for none).
        :param efforts: each source's (n, 18) generalized forces, in the order they first
            acted.
        :param present: per sample, bit i set if the i-th source of ``efforts`` acted then.
        :param events: the run's event log.
        """
        n = len(columns['t'])
        last = columns['last_event']
        indices = np.unique(last).tolist()
        last_t = np.zeros(n)
        for i in indices:
            if i >= 0:
                last_t[last == i] = events[i].t
        values = np.hstack([
            np.column_stack([columns[key] for key in (
                't', 't_exchange', 't_touchdown', 'heel_anchor_y', 'support_normal',
                'support_tangential', 'cop_y')] + [last_t]),
            columns['q'], columns['v'], columns['qdd'], columns['passive'],
            columns['multipliers'], columns['head_position'],
            columns['head_rotation'].reshape(n, 9)])
        names = list(efforts)
        masks = np.unique(present).tolist()
        sets = [tuple(name for i, name in enumerate(names) if mask >> i & 1) for mask in masks]
        width = max([len(acting) for acting in sets] + [1])
        acting_efforts = np.zeros((n, width, _N))
        source_set = np.zeros(n, dtype=np.intp)
        for index, (mask, acting) in enumerate(zip(masks, sets, strict=True)):
            rows = present == mask
            source_set[rows] = index
            for j, name in enumerate(acting):
                acting_efforts[rows, j] = efforts[name][rows]
        codes = np.column_stack([columns['mode'], columns['side'], columns['pivot'],
                                 columns['step_index']]).astype(np.int64)
        cause = np.searchsorted(indices, last)
        causes = tuple(events[i].cause if i >= 0 else None for i in indices)
        return cls(values, acting_efforts, tuple(sets), source_set, codes, causes,
                   cause.astype(np.intp))

    def record(self, k: int) -> BagRecord:
        """The k-th record."""
        sources = self.source_sets[self.source_set[k]]
        mode, side, pivot, step = self.codes[k].tolist()
        values = np.concatenate([self.values[k], self.efforts[k, :len(sources)].ravel()])
        return BagRecord(values, mode, SIDES[side], PIVOTS[pivot], step, sources,
                         self.causes[self.cause[k]])


def record_numbers(record: BagRecord, topics: tuple[str, ...] = RECORDED_TOPICS) -> np.ndarray:
    """The record's values, then the total input effort (18) and the head quaternion (4):
    every number its messages hold. The two derived parts are computed only for ``topics``
    that hold them (/joint_states, /head_pose), else left 0."""
    x = record.values
    numbers = np.zeros(x.size + _N + 4)
    numbers[:x.size] = x
    if '/joint_states' in topics and record.sources:
        numbers[_TOTAL] = x[_EFFORTS:].reshape(len(record.sources), _N).sum(axis=0)
    if '/head_pose' in topics:
        numbers[_QUAT] = rotation_to_quaternion(x[_HEAD_R].reshape(3, 3))
    return numbers


def block_numbers(block: RecordBlock, rows: np.ndarray,
                  topics: tuple[str, ...] = RECORDED_TOPICS) -> np.ndarray:
    """``record_numbers`` of the block's ``rows``, which share one source set: (m, size)."""
    acting = len(block.source_sets[block.source_set[rows[0]]])
    values = block.values[rows]
    m, width = values.shape
    numbers = np.zeros((m, width + acting * _N + _N + 4))
    numbers[:, :width] = values
    efforts = block.efforts[rows, :acting]
    numbers[:, width:width + acting * _N] = efforts.reshape(m, acting * _N)
    if '/joint_states' in topics and acting:
        total = efforts[:, 0].copy()
        for j in range(1, acting):  # row by row, as the sum over axis 0 of one record adds
            total += efforts[:, j]
        numbers[:, -_N - 4:-4] = total
    if '/head_pose' in topics:
        for k, rotation in enumerate(values[:, _HEAD_R]):
            numbers[k, -4:] = rotation_to_quaternion(rotation.reshape(3, 3))
    return numbers


def stamps_ns(t: np.ndarray) -> np.ndarray:
    """``seconds_to_ns`` of each time in ``t`` [s], as int64 [ns].

    :raises SimulationError: as ``seconds_to_ns`` does, for the first time that is not finite
        and >= 0.
    """
    bad = ~(np.isfinite(t) & (t >= 0.0))
    if bad.any():
        seconds_to_ns(float(t[np.argmax(bad)]))
    return np.rint(t * 1e9).astype(np.int64)


def stamp_parts(t: float) -> tuple[int, int]:
    """(sec, nanosec) of a simulation time t [s] (rounded to the nanosecond).

    :raises SimulationError: for a time that is not finite and >= 0.
    """
    return ns_to_sec_nanosec(seconds_to_ns(t))


def stamp(typestore: Typestore, t: float) -> Any:
    """builtin_interfaces/Time of a simulation time t [s] (t >= 0)."""
    sec, nanosec = stamp_parts(t)
    return typestore.types['builtin_interfaces/msg/Time'](sec=sec, nanosec=nanosec)


def rotation_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """(x, y, z, w) of a rotation matrix (Eigen's conversion: ~1 us, scipy's ~40 us)."""
    return np.array(pin.Quaternion(np.ascontiguousarray(rotation)).coeffs())


#: Numbers a record's messages hold besides its values, appended to them (``record_numbers``):
#: the total input effort (18) and the head quaternion (x, y, z, w).
_TOTAL, _QUAT = slice(-_N - 4, -4), slice(-4, None)


class LinkTransforms:
    """The /tf transforms of a recorded state in robot_state_publisher's layout: ``world`` ->
    the URDF's root link, then one per URDF joint, parent link -> child link (the fixed joints
    too, constant, in every message), each a row (x, y, z [m], qx, qy, qz, qw).

    The root link's world pose is its placement in the support-rooted model of the state's
    side and pivot at q, as the simulation places every link (``head_placement``); the mode
    and the contact anchors do not enter (q holds the locked coordinates too). A revolute
    joint's row is its origin turned about its axis by its URDF angle (``anatomical_map``).

    :param robot: the robot (its URDF model and support models).
    :raises SimulationError: for a URDF joint neither revolute nor fixed, or one without a
        Table-2 coordinate.
    :ivar frames: (frame_id, child_frame_id) of each row: URDF link names, and ``world``.
    """

    def __init__(self, robot: Robot) -> None:
        self.robot = robot
        self._data = {key: support.new_data() for key, support in robot.models.items()}
        model = robot.urdf_model
        frames = model.frames
        child_of = {f.parentFrame: f for f in frames if f.type == pin.FrameType.BODY}
        self.root = child_of[0].name  # the link on the universe frame
        self.frames = [('world', self.root)]
        origins = [pin.SE3.Identity()]
        moving: list[int] = []
        joints: list[str] = []
        axes: list[np.ndarray] = []
        for k, frame in enumerate(frames):
            if k == 0 or frame.type not in (pin.FrameType.JOINT, pin.FrameType.FIXED_JOINT):
                continue
            parent, child = frames[frame.parentFrame], child_of[k]
            self.frames.append((parent.name, child.name))
            if frame.type == pin.FrameType.FIXED_JOINT:
                origins.append(parent.placement.inverse() * child.placement)
                continue
            origins.append(parent.placement.inverse() * model.jointPlacements[frame.parentJoint])
            moving.append(len(origins) - 1)
            joints.append(frame.name)
            axes.append(_revolute_axis(model, frame.parentJoint))
        self._constant = np.array([[*m.translation, *rotation_to_quaternion(m.rotation)]
                                   for m in origins])
        self._moving = np.array(moving, dtype=np.intp)
        # origin quaternion (v, w) times the turn (a sin h, cos h) about axis a by angle 2 h:
        # sin h (w a + v x a, -v . a) + cos h (v, w)
        v, w, a = self._constant[moving, 3:6], self._constant[moving, 6:], np.array(axes)
        self._sin_part = np.hstack([w * a + np.cross(v, a), -np.sum(v * a, axis=1, keepdims=True)])
        self._cos_part = self._constant[moving, 3:]
        self._coordinates: dict[str, tuple[np.ndarray, np.ndarray]] = {}
        for side in SIDES:
            coordinate = {name: (i, sign) for i, name, sign in anatomical_map(side)}
            missing = sorted(set(joints) - set(coordinate))
            if missing:
                raise SimulationError(f'URDF joints {missing} have no Table-2 coordinate')
            index, sign = zip(*(coordinate[name] for name in joints), strict=True)
            self._coordinates[side] = np.array(index, dtype=np.intp), np.array(sign)

    def rows(self, q: np.ndarray, side: str, pivot: str) -> np.ndarray:
        """The rows (one per ``frames`` entry, shape (n, 7)) at Table-2 coordinates q (18,)
        [m, rad] with the ``side`` foot supporting about its ``pivot`` edge."""
        return self.block_rows(q[None], side, pivot)[0]

    def block_rows(self, q: np.ndarray, side: str, pivot: str) -> np.ndarray:
        """The rows of several states of one side and pivot: q (m, 18) -> (m, n, 7)."""
        support = self.robot.support_model(side, pivot)
        data = self._data[(side, pivot)]
        frame = support.frame_ids[self.root]
        out = np.repeat(self._constant[None], len(q), axis=0)
        for k, qk in enumerate(q):
            pin.forwardKinematics(support.model, data, qk)
            # translation, quaternion: 0.2 us (a 10th of ours)
            out[k, 0] = pin.SE3ToXYZQUAT(pin.updateFramePlacement(support.model, data, frame))
        index, sign = self._coordinates[side]
        half = (0.5 * q[:, index] * sign)[:, :, None]
        with np.errstate(invalid='ignore'):  # an infinite angle: NaN, as the bag copies it
            sin, cos = np.sin(half), np.cos(half)
        out[:, self._moving, 3:] = sin * self._sin_part + cos * self._cos_part
        return out


def _revolute_axis(model: pin.Model, joint: int) -> np.ndarray:
    """The unit axis of a revolute joint of ``model``, in its frame.

    :raises SimulationError: if the joint is not revolute (one coordinate, no translation).
    """
    joint_model = model.joints[joint]
    if joint_model.nq == joint_model.nv == 1:
        data = joint_model.createData()
        joint_model.calc(data, np.zeros(model.nq))  # it reads its entries of the model's q
        subspace = np.ravel(data.S)  # (linear, angular) velocity of a unit joint speed
        if not np.any(subspace[:3]):
            return subspace[3:]
    raise SimulationError(f'URDF joint {model.names[joint]} ({joint_model.shortname()}) is '
                          'neither revolute nor fixed; /tf cannot place its link')


class RecordFlags(NamedTuple):
    """What a record's messages decide from its numbers (with the discrete part, this fixes
    everything in them that is not a number copied from ``record_numbers``)."""

    touched: bool  # the swing heel has struck (t_touchdown is finite)
    cop_known: bool  # the centre of pressure is finite
    zmp_inside: bool  # ... and inside the flat support sole


def record_flags(record: BagRecord) -> RecordFlags:
    """The flags of a record (see ``RecordFlags``)."""
    x = record.values
    cop = float(x[6])
    known = math.isfinite(cop)
    y0 = float(x[_Q.start])
    inside = (known and not get_mode(record.mode).q1_active
              and y0 + SOLE_HEEL_Y <= cop <= y0 + SOLE_TOE_Y)
    return RecordFlags(math.isfinite(float(x[2])), known, inside)


#: Whether a mode's q1 (the support foot's pitch) is free, by mode number.
_Q1_ACTIVE = np.array([number > 0 and get_mode(number).q1_active for number in range(21)])


def block_flags(block: RecordBlock) -> np.ndarray:
    """``record_flags`` of every record of the block, as (n, 3) booleans."""
    x = block.values
    cop, y0 = x[:, 6], x[:, _Q.start]
    known = np.isfinite(cop)
    with np.errstate(invalid='ignore'):
        inside = (known & ~_Q1_ACTIVE[block.codes[:, 0]] & (y0 + SOLE_HEEL_Y <= cop)
                  & (cop <= y0 + SOLE_TOE_Y))
    return np.column_stack([np.isfinite(x[:, 2]), known, inside])


class MessageFactory:
    """Builds the rosbags message objects of a Sample (shared with the ROS node's bag).

    Messages are built from a record's discrete part, its flags and its numbers (values,
    total effort, head quaternion: ``record_numbers``; for /tf: ``tf_numbers``); every number
    in them is a copy of one of those numbers or a stamp of one (``RecordEncoder`` relies on
    it).

    :param typestore: the types (default: ``make_typestore()``).
    :param robot: the robot whose links /tf places (default: ``load_robot()``, the package
        URDF's, which the callers record as /robot_description).
    """

    def __init__(self, typestore: Typestore | None = None, robot: Robot | None = None) -> None:
        self.typestore = typestore or make_typestore()
        self.transforms = LinkTransforms(robot or load_robot())
        types = self.typestore.types
        self._header = types['std_msgs/msg/Header']
        self._clock = types['rosgraph_msgs/msg/Clock']
        self._joint_state = types['sensor_msgs/msg/JointState']
        self._pose_stamped = types['geometry_msgs/msg/PoseStamped']
        self._pose = types['geometry_msgs/msg/Pose']
        self._point = types['geometry_msgs/msg/Point']
        self._quaternion = types['geometry_msgs/msg/Quaternion']
        self._gait_state = types['iceskate_interfaces/msg/GaitState']
        self._dynamics = types['iceskate_interfaces/msg/JointDynamics']
        self._string = types['std_msgs/msg/String']
        self._tf = types['tf2_msgs/msg/TFMessage']
        self._transform_stamped = types['geometry_msgs/msg/TransformStamped']
        self._transform = types['geometry_msgs/msg/Transform']
        self._vector = types['geometry_msgs/msg/Vector3']
        self.names = list(COORDINATE_NAMES)
        self._build = {'/clock': self._clock_message, '/joint_states': self._joint_state_message,
                       '/head_pose': self._pose_message, '/gait_state': self._gait_state_message,
                       '/joint_dynamics': self._dynamics_message, '/tf': self._tf_message}

    def header(self, t: float, frame: str = '') -> Any:
        """std_msgs/Header at simulation time t."""
        return self._header(stamp=stamp(self.typestore, t), frame_id=frame)

    def messages(self, sample: Sample, topics: tuple[str, ...] = RECORDED_TOPICS
                 ) -> dict[str, Any]:
        """Topic -> message of one sample, for ``topics`` (default: every recorded topic)."""
        return self.record_messages(bag_record(sample), topics)

    def record_messages(self, record: BagRecord, topics: tuple[str, ...] = RECORDED_TOPICS
                        ) -> dict[str, Any]:
        """Topic -> message of one packed sample (see ``BagRecord``), for ``topics``."""
        numbers, flags = record_numbers(record, topics), record_flags(record)
        return {topic: self._build[topic](record, self.tf_numbers(record) if topic == '/tf'
                                          else numbers, flags) for topic in topics}

    def tf_numbers(self, record: BagRecord) -> np.ndarray:
        """The numbers of the record's /tf message: t [s], then the rows of its link poses
        (``LinkTransforms.rows``, 7 each)."""
        x = record.values
        rows = self.transforms.rows(x[_Q], record.side, record.pivot)
        return np.concatenate([x[:1], rows.ravel()])

    def tf_block_numbers(self, block: RecordBlock) -> np.ndarray:
        """``tf_numbers`` of every record of the block: (n, 1 + 7 frames)."""
        x = block.values
        out = np.empty((len(x), 1 + 7 * len(self.transforms.frames)))
        out[:, 0] = x[:, 0]
        contact = block.codes[:, 1] * len(PIVOTS) + block.codes[:, 2]
        for code in np.unique(contact).tolist():
            rows = np.flatnonzero(contact == code)
            side, pivot = SIDES[code // len(PIVOTS)], PIVOTS[code % len(PIVOTS)]
            out[rows, 1:] = self.transforms.block_rows(x[rows, _Q], side, pivot).reshape(
                len(rows), -1)
        return out

    def built(self, record: BagRecord, numbers: np.ndarray, flags: RecordFlags,
              topics: tuple[str, ...] = RECORDED_TOPICS) -> dict[str, Any]:
        """Topic -> message of a record's discrete part (``record.values`` unused) with these
        numbers (``tf_numbers`` for /tf) and flags."""
        return {topic: self._build[topic](record, numbers, flags) for topic in topics}

    def _clock_message(self, record: BagRecord, n: np.ndarray, flags: RecordFlags) -> Any:
        return self._clock(clock=stamp(self.typestore, float(n[0])))

    def _joint_state_message(self, record: BagRecord, n: np.ndarray, flags: RecordFlags) -> Any:
        return self._joint_state(header=self.header(float(n[0])), name=self.names,
                                 position=n[_Q].copy(), velocity=n[_V].copy(),
                                 effort=n[_TOTAL].copy())

    def _pose_message(self, record: BagRecord, n: np.ndarray, flags: RecordFlags) -> Any:
        (px, py, pz), (qx, qy, qz, qw) = n[_HEAD_P].tolist(), n[_QUAT].tolist()
        return self._pose_stamped(header=self.header(float(n[0]), 'world'), pose=self._pose(
            position=self._point(x=px, y=py, z=pz),
            orientation=self._quaternion(x=qx, y=qy, z=qz, w=qw)))

    def _gait_state_message(self, record: BagRecord, n: np.ndarray, flags: RecordFlags) -> Any:
        t, t_exchange, t_touchdown, heel_anchor_y, normal, tangential, cop, last_t = (
            n[:_SCALARS].tolist())
        mode = get_mode(record.mode)
        names = list(mode.multipliers)
        index = {'f_nz': 0, 'f_ny': 1, 'tau_n': 2}
        multipliers = n[_MULT]
        last = record.last_cause is not None
        return self._gait_state(
            header=self.header(t), mode=mode.number,
            support_side=0 if record.side == 'right' else 1,
            pivot=PIVOT_CODE[record.pivot] if mode.q1_active else 0,
            step_index=record.step_index, y0_active=mode.y0_active, q1_active=mode.q1_active,
            multiplier_names=names,
            multipliers=np.array([multipliers[index[n]] for n in names], dtype=np.float64),
            support_normal_force=normal, support_friction_force=tangential,
            zmp=self._point(x=0.0, y=cop if flags.cop_known else float('nan'), z=0.0),
            zmp_inside_support=flags.zmp_inside,
            last_transition_cause=record.last_cause if last else '',
            last_transition_stamp=stamp(self.typestore, last_t if last else 0.0),
            support_exchange_stamp=stamp(self.typestore, t_exchange),
            touched_down=flags.touched,
            touchdown_stamp=stamp(self.typestore, t_touchdown if flags.touched else 0.0),
            heel_anchor_y=heel_anchor_y, position=n[_Q].copy(), velocity=n[_V].copy())

    def _dynamics_message(self, record: BagRecord, n: np.ndarray, flags: RecordFlags) -> Any:
        mode = get_mode(record.mode)
        efforts = n[_EFFORTS:_EFFORTS + len(record.sources) * _N]
        active = np.zeros(_N, dtype=bool)  # np.isin would take 10 % of the writer's time
        active[mode.active] = True
        return self._dynamics(header=self.header(float(n[0])), name=self.names, active=active,
                              acceleration=n[_QDD].copy(),
                              source_names=[*record.sources, PASSIVE],
                              source_efforts=np.concatenate([efforts, n[_PASSIVE]]))

    def _tf_message(self, record: BagRecord, n: np.ndarray, flags: RecordFlags) -> Any:
        t = float(n[0])
        rows = n[1:].reshape(-1, 7).tolist()
        return self._tf(transforms=[
            self._transform_stamped(
                header=self.header(t, parent), child_frame_id=child,
                transform=self._transform(translation=self._vector(x=x, y=y, z=z),
                                          rotation=self._quaternion(x=qx, y=qy, z=qz, w=qw)))
            for (parent, child), (x, y, z, qx, qy, qz, qw)
            in zip(self.transforms.frames, rows, strict=True)])

    def description(self, urdf: str) -> Any:
        """std_msgs/String holding the URDF."""
        return self._string(data=urdf)


class _Layout(NamedTuple):
    """Where a record's numbers and discrete codes go in the CDR bytes of one topic's message
    (for one key)."""

    template: bytes  # the bytes of a message of this key
    slots: np.ndarray  # float64 slots (8-byte units after the 4-byte CDR header) to write ...
    index: np.ndarray  # ... with these entries of the numbers
    stamps: tuple[tuple[int, tuple[int, ...]], ...]  # (entry, byte offsets): Time of entry
    integers: tuple[tuple[int, int], ...] = ()  # (byte offset, column of the codes)

    def fill(self, numbers: np.ndarray, codes: tuple[int, ...]) -> bytes:
        """The bytes of the message with these numbers and codes (``_codes``)."""
        out = bytearray(self.template)
        if self.slots.size:
            np.frombuffer(out, '<f8', (len(out) - 4) // 8, 4)[self.slots] = numbers[self.index]
        for entry, offsets in self.stamps:
            time = _TIME.pack(*stamp_parts(float(numbers[entry])))
            for offset in offsets:
                out[offset:offset + _TIME.size] = time
        for offset, column in self.integers:
            data = _INTEGER_FIELDS[column].pack(codes[column])
            out[offset:offset + len(data)] = data
        return bytes(out)

    def fill_rows(self, numbers: np.ndarray, codes: np.ndarray) -> list[bytes | np.ndarray]:
        """``fill`` of each row of numbers (m, size) and codes (m, 4), at once: the bytes of
        each message as a row (uint8) of one array, or as bytes where ``fill`` is used."""
        m, size = len(numbers), len(self.template)
        seconds = [numbers[:, entry] for entry, _ in self.stamps]
        if not all(np.all(np.isfinite(t) & (t >= 0.0) & (t < _MAX_STAMP)) for t in seconds):
            # a stamp fill refuses: its error, from the first row it comes from
            return [self.fill(n, tuple(c)) for n, c in zip(numbers, codes.tolist(), strict=True)]
        # rows of 4 bytes of padding, then the message: its 8-byte slots after the 4-byte CDR
        # header are aligned float64 columns 1, 2, ... of the row
        width = (size + 4 + 7) // 8 * 8
        rows = np.empty((m, width), dtype=np.uint8)
        out = rows[:, 4:4 + size]
        out[:] = np.frombuffer(self.template, dtype=np.uint8)
        if self.slots.size:
            rows.view('<f8')[:, 1 + self.slots] = numbers[:, self.index]
        for (_, offsets), t in zip(self.stamps, seconds, strict=True):
            ns = np.rint(t * 1e9).astype(np.int64)
            time = np.empty(m, dtype=_TIME_DTYPE)
            time['sec'], time['nanosec'] = np.divmod(ns, 1_000_000_000)
            for offset in offsets:
                out[:, offset:offset + 8] = time.view(np.uint8).reshape(m, 8)
        for offset, column in self.integers:
            field = _INTEGER_FIELDS[column]
            written = codes[:, column] if field.values is None else np.take(field.values,
                                                                            codes[:, column])
            values = np.ascontiguousarray(written, dtype=field.dtype)
            out[:, offset:offset + field.size] = values.view(np.uint8).reshape(m, field.size)
        return list(out)  # each row a contiguous buffer


_TIME = struct.Struct('<iI')
_TIME_DTYPE = np.dtype([('sec', '<i4'), ('nanosec', '<u4')])
_MAX_STAMP = 2.0 ** 31  # [s]: a Time's sec is an int32


class _IntegerField(NamedTuple):
    """How a discrete code of a record appears in a message: its CDR integer type, and the
    value it writes for a code (``dtype`` has ``size`` bytes)."""

    dtype: str
    size: int
    values: tuple[int, ...] | None  # code -> value written (None: the code itself)

    def pack(self, code: int) -> bytes:
        """The bytes of a code."""
        value = code if self.values is None else self.values[code]
        return np.array(value, dtype=self.dtype).tobytes()


#: By column of ``RecordBlock.codes`` (mode, side, pivot, step index): the integer fields the
#: messages carry that the encoder patches (the mode is part of the layout's key).
_INTEGER_FIELDS = {1: _IntegerField('<u1', 1, None),  # GaitState.support_side: 0 right, 1 left
                   2: _IntegerField('<u1', 1, (PIVOT_CODE['toe'], PIVOT_CODE['heel'])),
                   3: _IntegerField('<u4', 4, None)}  # GaitState.step_index


def _codes(record: BagRecord) -> tuple[int, int, int, int]:
    """A record's discrete codes, as a row of ``RecordBlock.codes``."""
    return (record.mode, SIDES.index(record.side), PIVOTS.index(record.pivot),
            record.step_index)


def _with_codes(record: BagRecord, codes: list[int]) -> BagRecord:
    """The record with the side, pivot and step index of ``codes`` (its mode kept)."""
    return record._replace(side=SIDES[codes[1]], pivot=PIVOTS[codes[2]], step_index=codes[3])


def sentinels(size: int) -> np.ndarray:
    """``size`` distinct numbers whose float64 bytes and Time bytes (as times) are unlike
    anything else in the recorded messages: 1e5 + 2 i + 0.5 (exact, half-second stamps)."""
    return 1.0e5 + 2.0 * np.arange(size) + 0.5


class RecordEncoder:
    """The CDR bytes of a record's messages, equal to rosbags' serialisation of the factory's
    messages, at a fraction of its cost (the bag writer's main work).

    Two records with the same mode, sources, last cause and flags (the key) give messages that
    differ only in numbers copied from ``record_numbers`` (or stamps of them) and in the
    integer fields of the side, pivot and step index. The first record of a key is serialised
    by rosbags as is, with every number replaced by a distinct sentinel (where each sentinel
    lands gives the number slots), and with each integer field set to two other values (where
    the bytes change gives its slot); the layout must reproduce every one of these
    serialisations exactly (else that topic and key keep the plain rosbags path). Later records
    of the key copy the bytes and write their numbers and codes into them, one record
    (``encode``) or a block of them with a few array operations per layout (``encode_block``).
    The /tf message holds only numbers (``tf_numbers``), so one layout of it serves every key.

    :param factory: the message factory (and its typestore).
    :param capacity: keys kept (the oldest learned is dropped first).
    """

    def __init__(self, factory: MessageFactory, capacity: int = 256) -> None:
        self.factory = factory
        self.capacity = capacity
        self._layouts: dict[tuple, dict[str, _Layout | None]] = {}
        self._keyless: dict[str, _Layout | None] = {}  # /tf's layout, the same for every key

    def encode(self, record: BagRecord, topics: tuple[str, ...] = RECORDED_TOPICS
               ) -> dict[str, bytes]:
        """Topic -> CDR bytes of the record's message, for ``topics``."""
        numbers, flags = record_numbers(record, topics), record_flags(record)
        layouts = self._keyed(record, flags, numbers.size)
        codes = _codes(record)
        out = {}
        for topic in topics:
            if topic == '/tf':
                out[topic] = self._bytes(self._keyless, topic, record,
                                         self.factory.tf_numbers(record), flags, codes)
            else:
                out[topic] = self._bytes(layouts, topic, record, numbers, flags, codes)
        return out

    def encode_block(self, block: RecordBlock, topics: tuple[str, ...] = RECORDED_TOPICS
                     ) -> dict[str, list[bytes]]:
        """Topic -> the CDR bytes of each record's message in the block (``encode`` of each
        record, the same bytes), for ``topics``."""
        n = len(block)
        out: dict[str, list[bytes]] = {topic: [b''] * n for topic in topics}
        flags = block_flags(block)
        keys = np.column_stack([block.codes[:, 0], block.source_set, block.cause,
                                flags @ np.array([1, 2, 4])])
        _, group = np.unique(keys, axis=0, return_inverse=True)
        group = group.ravel()
        for g in range(int(group.max()) + 1 if n else 0):
            rows = np.flatnonzero(group == g)
            first = block.record(int(rows[0]))
            numbers = block_numbers(block, rows, topics)
            record_flag = record_flags(first)
            layouts = self._keyed(first, record_flag, numbers.shape[1])
            for topic in topics:
                if topic != '/tf':
                    self._rows(out[topic], layouts, topic, block, rows, numbers, first,
                               record_flag)
        if '/tf' in topics and n:
            first = block.record(0)
            self._rows(out['/tf'], self._keyless, '/tf', block, np.arange(n),
                       self.factory.tf_block_numbers(block), first, record_flags(first))
        return out

    def _keyed(self, record: BagRecord, flags: RecordFlags, size: int
               ) -> dict[str, _Layout | None]:
        """The layouts of the record's key (see the class), by topic."""
        key = (record.mode, record.sources, record.last_cause, flags, size)
        layouts = self._layouts.get(key)
        if layouts is None:
            layouts = self._layouts[key] = {}
            if len(self._layouts) > self.capacity:
                del self._layouts[next(iter(self._layouts))]
        return layouts

    def _rows(self, out: list[bytes], layouts: dict[str, _Layout | None], topic: str,
              block: RecordBlock, rows: np.ndarray, numbers: np.ndarray, first: BagRecord,
              flags: RecordFlags) -> None:
        """Write the bytes of ``topic``'s message of the block's ``rows`` (one key, ``first``
        the first of them; their numbers) into ``out``."""
        if topic not in layouts:
            layouts[topic] = self._learn(topic, first, numbers[0], flags)
        layout = layouts[topic]
        if layout is not None:
            encoded = layout.fill_rows(numbers, block.codes[rows])
        else:
            encoded = [self._serialize(topic, block.record(k), row, flags)
                       for k, row in zip(rows.tolist(), numbers, strict=True)]
        for k, data in zip(rows.tolist(), encoded, strict=True):
            out[k] = data

    def _bytes(self, layouts: dict[str, _Layout | None], topic: str, record: BagRecord,
               numbers: np.ndarray, flags: RecordFlags, codes: tuple[int, ...]) -> bytes:
        """The bytes of ``topic``'s message through its layout in ``layouts`` (learned first if
        missing; rosbags if none fits)."""
        if topic not in layouts:
            layouts[topic] = self._learn(topic, record, numbers, flags)
        layout = layouts[topic]
        return (layout.fill(numbers, codes) if layout is not None
                else self._serialize(topic, record, numbers, flags))

    def _serialize(self, topic: str, record: BagRecord, numbers: np.ndarray,
                   flags: RecordFlags) -> bytes:
        message = self.factory.built(record, numbers, flags, (topic,))[topic]
        return bytes(self.factory.typestore.serialize_cdr(message, TOPICS[topic]))

    def _learn(self, topic: str, record: BagRecord, numbers: np.ndarray,
               flags: RecordFlags) -> _Layout | None:
        """The layout of ``topic`` for this record's key, or None if none reproduces rosbags."""
        actual = self._serialize(topic, record, numbers, flags)
        probe_numbers = sentinels(numbers.size)
        probe = self._serialize(topic, record, probe_numbers, flags)
        if len(probe) != len(actual):
            return None
        slots: list[tuple[int, int]] = []
        stamps: list[tuple[int, int]] = []
        for entry, value in enumerate(probe_numbers.tolist()):
            for pattern, found in ((struct.pack('<d', value), slots),
                                   (_TIME.pack(*stamp_parts(value)), stamps)):
                offset = probe.find(pattern)
                while offset >= 0:
                    found.append((offset, entry))
                    offset = probe.find(pattern, offset + 1)
        if any((offset - 4) % 8 for offset, _ in slots):
            return None
        times: dict[int, list[int]] = {}
        for offset, entry in stamps:
            times.setdefault(entry, []).append(offset)
        # the integer fields at other values: where the bytes change is a field's slot
        def variant(changes: dict[int, int]) -> tuple[tuple[int, ...], bytes]:
            codes = list(_codes(record))
            for column, code in changes.items():
                codes[column] = code
            return tuple(codes), self._serialize(topic, _with_codes(record, codes),
                                                 probe_numbers, flags)

        others = {column: (0, 1) if column != 3 else (0x01020304, 0x0A0B0C0D)
                  for column in _INTEGER_FIELDS}
        variants = [variant({column: pair[k] for column, pair in others.items()})
                    for k in range(2)]
        integers = []
        if any(serialised != probe for _, serialised in variants):  # else: none in this topic
            for column, pair in others.items():
                both = [variant({column: code}) for code in pair]
                if any(len(serialised) != len(probe) for _, serialised in both):
                    return None
                changed = [k for k, (a, b) in enumerate(zip(both[0][1], both[1][1], strict=True))
                           if a != b]
                if changed:
                    if changed[-1] - changed[0] >= _INTEGER_FIELDS[column].size:
                        return None
                    integers.append((changed[-1] + 1 - _INTEGER_FIELDS[column].size, column))
                variants += both
        layout = _Layout(actual, np.array([(o - 4) // 8 for o, _ in slots], dtype=np.intp),
                         np.array([e for _, e in slots], dtype=np.intp),
                         tuple((entry, tuple(offsets)) for entry, offsets in times.items()),
                         tuple(integers))
        try:
            fits = (layout.fill(numbers, _codes(record)) == actual
                    and layout.fill(probe_numbers, _codes(record)) == probe
                    and all(layout.fill(probe_numbers, c) == b for c, b in variants))
        except SimulationError:  # a stamp of a non-finite number: ambiguous sentinels
            fits = False
        return layout if fits else None


class _BagFile:
    """The open MCAP bag: metadata, connections and the URDF written; serialises messages."""

    def __init__(self, path: pathlib.Path, metadata: dict[str, Any], urdf: str,
                 factory: MessageFactory) -> None:
        self.factory = factory
        self._encoder = RecordEncoder(factory)
        self._writer = Writer(path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        for key, value in metadata.items():
            self._writer.set_custom_data(key, value if isinstance(value, str)
                                         else json.dumps(value, sort_keys=True))
        self._writer.set_custom_data('project_version', PROJECT_VERSION)
        ts = factory.typestore
        self._connections = {topic: self._writer.add_connection(
            topic, msgtype, typestore=ts, offered_qos_profiles=OFFERED_QOS.get(topic, ()))
            for topic, msgtype in TOPICS.items()}
        self.write('/robot_description', 0.0, factory.description(urdf))

    def write(self, topic: str, t: float, message: Any) -> None:
        """Serialise ``message`` and write it at simulation time t [s]."""
        data = self.factory.typestore.serialize_cdr(message, TOPICS[topic])
        self._writer.write(self._connections[topic], seconds_to_ns(t), data)

    def write_block(self, block: RecordBlock) -> None:
        """Write the messages of a block of packed samples, sample by sample, in one go
        (``bag_bulk.write_many``)."""
        stamps = stamps_ns(block.values[:, 0]).tolist()
        encoded = self._encoder.encode_block(block)
        columns = [(self._connections[topic], encoded[topic]) for topic in RECORDED_TOPICS]
        write_many(self._writer, [(connection, ns, column[k]) for k, ns in enumerate(stamps)
                                  for connection, column in columns])

    def close(self) -> None:
        """Finish the bag (idempotent)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None


def _writer_process(path: pathlib.Path, metadata: dict[str, Any], urdf: str,
                    factory: MessageFactory, records: multiprocessing.Queue,
                    status: Connection) -> None:
    """Body of the writer process: write the batches of ``records`` until None, then close the
    bag and send ('ok', samples) or ('error', message) on ``status``.

    SIGINT, SIGTERM and SIGHUP are ignored: sent to the whole process group (Ctrl-C, ``timeout``,
    a closed terminal), they reach the parent too, which ends the run and closes the bag through
    this process. When the parent dies (even by SIGKILL) the kernel sends SIGUSR1
    (``die_with_parent``; it comes when the forking thread ends, so the parent is looked at
    again a second later, by SIGALRM): this process writes the batches that arrived whole,
    closes the bag (with its metadata) and exits; a batch the parent was sending when it died is
    dropped (SIGALRM ends a read that would wait for its missing part forever)."""
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)
    gc.freeze()  # what the parent had: not this process's garbage, never collected here
    reading, orphaned = False, False

    parent = multiprocessing.parent_process()

    def parent_gone(signum: int, frame: Any) -> None:
        nonlocal orphaned
        if signum == signal.SIGUSR1:  # the thread that forked this process ended: look again
            signal.alarm(1)  # in a second, when the rest of the parent is gone too
            return
        if parent is not None and parent.is_alive():  # only that thread ended
            return
        orphaned = True
        if reading:  # blocked on the queue: give up the read (else only note it)
            raise _ParentGone

    signal.signal(signal.SIGUSR1, parent_gone)
    signal.signal(signal.SIGALRM, parent_gone)
    die_with_parent(signal.SIGUSR1, parent.pid if parent is not None else None)
    count = 0
    try:
        bag = _BagFile(path, metadata, urdf, factory)
        try:
            while True:
                if orphaned:
                    signal.alarm(2)  # what is left in the queue must come within 2 s
                reading = True
                try:
                    batch = records.get(timeout=1.0)
                except queue.Empty:
                    if orphaned or (parent is not None and not parent.is_alive()):
                        break
                    continue
                except (_ParentGone, EOFError, OSError):
                    break
                finally:
                    reading = False
                if batch is None:
                    break
                block = batch if isinstance(batch, RecordBlock) else RecordBlock.of_records(batch)
                bag.write_block(block)
                count += len(block)
        finally:
            signal.alarm(0)
            bag.close()
    except BaseException as exc:  # reported to the parent, which raises it
        with contextlib.suppress(OSError):  # unless it is gone
            status.send(('error', f'{type(exc).__name__}: {exc}'))
    else:
        with contextlib.suppress(OSError):
            status.send(('ok', count))
    finally:
        status.close()


class _ParentGone(Exception):
    """The writer's parent died while the writer waited for a batch."""


class BagRecorder:
    """Writes samples to an MCAP rosbag2 bag; closes cleanly even when a run fails.

    :param background: build, serialise and write the messages in a writer process, forked
        here (a few ms, no re-import of ``__main__``; the writer touches neither ROS nor the
        simulation, so threads of the parent do not matter) and run under SCHED_IDLE: it takes
        only the CPU time the run and the ROS nodes leave.
        ``write`` packs the sample and hands it over in batches of ``BATCH``, ``write_block``
        a block at once; they wait while ``QUEUE_BATCHES`` batches are in flight and raise
        SimulationError once the writer has failed. ``close`` waits until everything is
        written.
    """

    def __init__(self, path: str | pathlib.Path, metadata: dict[str, Any], urdf: str,
                 typestore: Typestore | None = None, background: bool = False) -> None:
        self.path = pathlib.Path(path)
        if self.path.exists():
            raise SimulationError(f'bag {self.path} already exists; choose a new --out')
        self.factory = MessageFactory(typestore)
        self.count = 0
        self._bag: _BagFile | None = None
        self._process: multiprocessing.process.BaseProcess | None = None
        if not background:
            self._bag = _BagFile(self.path, metadata, urdf, self.factory)
            return
        context = multiprocessing.get_context('fork')
        self._records = context.Queue(maxsize=QUEUE_BATCHES)
        self._status, child_status = context.Pipe(duplex=False)
        self._process = context.Process(
            target=_writer_process, name='bag-writer', daemon=True,
            args=(self.path, metadata, urdf, self.factory, self._records, child_status))
        self._process.start()
        # the lowest priority: the writer never delays the run or a lockstep node (its queue
        # is bounded: a parent that gets ahead waits, and the writer then has the CPU)
        os.sched_setscheduler(self._process.pid, os.SCHED_IDLE, os.sched_param(0))
        child_status.close()
        self._batch: list[BagRecord] = []

    def write(self, sample: Sample) -> None:
        """Record one control instant."""
        record = bag_record(sample)
        if self._bag is not None:
            self._bag.write_block(RecordBlock.of_records([record]))
        elif self._process is not None:
            self._batch.append(record)
            if len(self._batch) >= BATCH:
                batch, self._batch = self._batch, []
                self._hand_over(batch)
        else:
            raise SimulationError(f'bag {self.path} is closed')
        self.count += 1

    def write_block(self, block: RecordBlock) -> None:
        """Record consecutive control instants packed as a block (after those written before)."""
        if self._bag is not None:
            self._bag.write_block(block)
        elif self._process is not None:
            if self._batch:
                batch, self._batch = self._batch, []
                self._hand_over(batch)
            self._hand_over(block)
        else:
            raise SimulationError(f'bag {self.path} is closed')
        self.count += len(block)

    def _hand_over(self, item: list[BagRecord] | RecordBlock | None) -> None:
        """Queue a batch (None: the end) for the writer process, waiting while it is busy."""
        self._check_writer()
        while True:
            try:
                self._records.put(item, timeout=0.2)
                return
            except queue.Full:
                self._check_writer()

    def _check_writer(self) -> None:
        """Raise SimulationError if the writer process has failed or ended early."""
        if self._status.poll() or not self._process.is_alive():
            process, self._process = self._process, None
            process.join(timeout=5.0)
            self._records.cancel_join_thread()
            raise SimulationError(f'bag writer for {self.path} failed: '
                                  f'{self._writer_status(process)}')

    def _writer_status(self, process: multiprocessing.process.BaseProcess) -> str:
        """The writer's report ('ok' or the error), or its exit code if it sent none."""
        if self._status.poll():
            try:
                kind, detail = self._status.recv()
                return 'ok' if kind == 'ok' else detail
            except EOFError:
                pass
        return f'writer process exited with code {process.exitcode}'

    def close(self) -> None:
        """Finish the bag (idempotent); a background writer first writes all it was given.

        :raises SimulationError: if the background writer failed.
        """
        if self._bag is not None:
            self._bag.close()
            self._bag = None
        if self._process is None:
            return
        if self._batch:
            batch, self._batch = self._batch, []
            self._hand_over(batch)
        self._hand_over(None)
        process, self._process = self._process, None
        process.join()
        self._records.cancel_join_thread()  # what a failed writer left unread stays unread
        self._records.close()
        status = self._writer_status(process)
        if status != 'ok':
            raise SimulationError(f'bag writer for {self.path} failed: {status}')

    def __enter__(self) -> BagRecorder:
        """Context manager: the bag is closed on exit, also after an exception."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the bag."""
        self.close()
