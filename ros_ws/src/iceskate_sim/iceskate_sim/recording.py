"""Recording a run to a rosbag2 bag (MCAP) with ``rosbags``, without ROS.

One sample per control period, stamped with the simulation time of the state, on the topics
the ROS simulator node publishes, so a headless run and a ROS run give the same bag layout and
the offline analysis reads either:

* ``/clock`` (rosgraph_msgs/Clock)
* ``/joint_states`` (sensor_msgs/JointState): the 18 coordinates y0, q1..q17; position,
  velocity and the total input effort held over the period
* ``/head_pose`` (geometry_msgs/PoseStamped, frame ``world``): the head-top frame
* ``/gait_state`` (iceskate_interfaces/GaitState)
* ``/joint_dynamics`` (iceskate_interfaces/JointDynamics): accelerations at the sample and the
  effort of every input source (plus ``passive``: damping and soft stops)
* ``/robot_description`` (std_msgs/String, once): the URDF

Bag metadata (``custom_data``) holds the scene, its parameters, the integrator and the project
version.
"""

from __future__ import annotations

from dataclasses import dataclass
import json
import pathlib
from typing import Any

import numpy as np
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys.store import Typestore

from iceskate_sim.bag_types import make_typestore
from iceskate_sim.dynamics import DynamicsResult
from iceskate_sim.errors import SimulationError
from iceskate_sim.hybrid import HybridState, Transition
from iceskate_sim.robot import COORDINATE_NAMES

PROJECT_VERSION = '0.1.0'
TOPICS = {
    '/clock': 'rosgraph_msgs/msg/Clock',
    '/joint_states': 'sensor_msgs/msg/JointState',
    '/head_pose': 'geometry_msgs/msg/PoseStamped',
    '/gait_state': 'iceskate_interfaces/msg/GaitState',
    '/joint_dynamics': 'iceskate_interfaces/msg/JointDynamics',
    '/robot_description': 'std_msgs/msg/String',
}
PIVOT_CODE = {'toe': 1, 'heel': 2}


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


def stamp(typestore: Typestore, t: float) -> Any:
    """builtin_interfaces/Time of a simulation time t [s] (t >= 0)."""
    time_cls = typestore.types['builtin_interfaces/msg/Time']
    ns = int(round(t * 1e9))
    return time_cls(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


def rotation_to_quaternion(rotation: np.ndarray) -> np.ndarray:
    """(x, y, z, w) of a rotation matrix."""
    from scipy.spatial.transform import Rotation
    return Rotation.from_matrix(rotation).as_quat()


class MessageFactory:
    """Builds the rosbags message objects of a Sample (shared with the ROS node's bag)."""

    def __init__(self, typestore: Typestore | None = None) -> None:
        self.typestore = typestore or make_typestore()
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
        self._effort = types['iceskate_interfaces/msg/EffortCommand']
        self._string = types['std_msgs/msg/String']
        self.names = list(COORDINATE_NAMES)

    def header(self, t: float, frame: str = '') -> Any:
        """std_msgs/Header at simulation time t."""
        return self._header(stamp=stamp(self.typestore, t), frame_id=frame)

    def messages(self, sample: Sample) -> dict[str, Any]:
        """Topic -> message of one sample."""
        s, r = sample.state, sample.result
        t = s.t
        total = np.sum(list(sample.efforts.values()), axis=0) if sample.efforts else np.zeros(18)
        joint_state = self._joint_state(
            header=self.header(t), name=self.names, position=s.q.astype(np.float64),
            velocity=s.v.astype(np.float64), effort=np.asarray(total, dtype=np.float64))
        quat = rotation_to_quaternion(sample.head_rotation)
        pos = sample.head_position
        pose = self._pose_stamped(header=self.header(t, 'world'), pose=self._pose(
            position=self._point(x=float(pos[0]), y=float(pos[1]), z=float(pos[2])),
            orientation=self._quaternion(x=float(quat[0]), y=float(quat[1]), z=float(quat[2]),
                                         w=float(quat[3]))))
        mode = s.mode
        names = list(mode.multipliers)
        index = {'f_nz': 0, 'f_ny': 1, 'tau_n': 2}
        last = sample.last_transition
        touched = bool(np.isfinite(s.t_touchdown))
        cop = r.cop_y
        heel_y, toe_y = s.q[0] - 0.06, s.q[0] + 0.20
        inside = bool(np.isfinite(cop) and heel_y <= cop <= toe_y) if not mode.q1_active else False
        gait = self._gait_state(
            header=self.header(t), mode=mode.number,
            support_side=0 if s.contact.side == 'right' else 1,
            pivot=PIVOT_CODE[s.contact.pivot] if mode.q1_active else 0,
            step_index=s.step_index, y0_active=mode.y0_active, q1_active=mode.q1_active,
            multiplier_names=names,
            multipliers=np.array([r.multipliers[index[n]] for n in names], dtype=np.float64),
            support_normal_force=float(r.support_normal),
            support_friction_force=float(r.support_tangential),
            zmp=self._point(x=0.0, y=float(cop) if np.isfinite(cop) else float('nan'), z=0.0),
            zmp_inside_support=inside,
            last_transition_cause=last.cause if last else '',
            last_transition_stamp=stamp(self.typestore, last.t if last else 0.0),
            support_exchange_stamp=stamp(self.typestore, s.t_exchange),
            touched_down=touched,
            touchdown_stamp=stamp(self.typestore, s.t_touchdown if touched else 0.0),
            heel_anchor_y=float(s.contact.heel_anchor_y))
        efforts = [self.effort(t, source, tau) for source, tau in sample.efforts.items()]
        efforts.append(self.effort(t, 'passive', r.passive))
        dynamics = self._dynamics(header=self.header(t), name=self.names,
                                  active=np.isin(np.arange(18), mode.active),
                                  acceleration=r.qdd.astype(np.float64), efforts=efforts)
        return {'/clock': self._clock(clock=stamp(self.typestore, t)),
                '/joint_states': joint_state, '/head_pose': pose, '/gait_state': gait,
                '/joint_dynamics': dynamics}

    def effort(self, t: float, source: str, tau: np.ndarray) -> Any:
        """EffortCommand holding the generalized force of one source at the sample [N m]."""
        empty = np.zeros(0)
        return self._effort(header=self.header(t), source=source, joint_names=self.names,
                            effort=np.asarray(tau, dtype=np.float64), stiffness=empty,
                            damping=empty, position_reference=empty)

    def description(self, urdf: str) -> Any:
        """std_msgs/String holding the URDF."""
        return self._string(data=urdf)


class BagRecorder:
    """Writes samples to an MCAP rosbag2 bag; closes cleanly even when a run fails."""

    def __init__(self, path: str | pathlib.Path, metadata: dict[str, Any], urdf: str,
                 typestore: Typestore | None = None) -> None:
        self.path = pathlib.Path(path)
        if self.path.exists():
            raise SimulationError(f'bag {self.path} already exists; choose a new --out')
        self.factory = MessageFactory(typestore)
        self._writer = Writer(self.path, version=9, storage_plugin=StoragePlugin.MCAP)
        self._writer.open()
        for key, value in metadata.items():
            self._writer.set_custom_data(key, value if isinstance(value, str)
                                         else json.dumps(value, sort_keys=True))
        self._writer.set_custom_data('project_version', PROJECT_VERSION)
        ts = self.factory.typestore
        self._connections = {topic: self._writer.add_connection(topic, msgtype, typestore=ts)
                             for topic, msgtype in TOPICS.items()}
        self._write('/robot_description', 0.0, self.factory.description(urdf))
        self.count = 0

    def _write(self, topic: str, t: float, message: Any) -> None:
        ts = self.factory.typestore
        data = ts.serialize_cdr(message, TOPICS[topic])
        self._writer.write(self._connections[topic], int(round(t * 1e9)), data)

    def write(self, sample: Sample) -> None:
        """Record one control instant."""
        for topic, message in self.factory.messages(sample).items():
            self._write(topic, sample.state.t, message)
        self.count += 1

    def close(self) -> None:
        """Finish the bag (idempotent)."""
        if self._writer is not None:
            self._writer.close()
            self._writer = None

    def __enter__(self) -> BagRecorder:
        """Context manager: the bag is closed on exit, also after an exception."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close the bag."""
        self.close()
