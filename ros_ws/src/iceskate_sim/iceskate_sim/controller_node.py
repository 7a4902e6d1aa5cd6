"""The part the controller nodes (visual_lifting, gait_manager) share: state in, commands out.

A ``ControllerNode`` subscribes ``gait_state`` (the whole hybrid state of an instant: one message
in per instant, best effort), taken as CDR bytes and decoded with the bag's typestore (rosbags:
8 us, where rclpy's message classes take 19 us), rebuilds the ``Observation``, asks the
subclass's law (``compute``) for the command of each of its sources and publishes their sum,
with the per-source breakdown, as one ``EffortCommand`` (source: the node's name) on
``effort_commands``, stamped with the state's stamp (the lockstep key): one message out per
instant and node. Each cross-process delivery costs tens of microseconds here, so the lockstep
keeps them few. The message object is made once and refilled.
Parameters: ``scene`` (name or path; the laws' parameters come from it) and ``use_sim_time``
(true unless overridden).
A law failing at one instant logs an error and sends nothing: the simulator's timeout then names
the node.
"""

from __future__ import annotations

from typing import Any

from rclpy.node import Node
from rclpy.parameter import Parameter

from iceskate_interfaces.msg import EffortCommand, GaitState
from iceskate_sim.bag_types import make_typestore
from iceskate_sim.command import ControllerCommand, JointCommand
from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.errors import SimulationError
from iceskate_sim.node_support import (
    LOCKSTEP_READER_QOS,
    STATE_QOS,
    ConfigError,
    check_unknown,
    declare,
)
from iceskate_sim.observation import Observation
from iceskate_sim.recording import TOPICS
from iceskate_sim.robot import load_robot
from iceskate_sim.ros_conversions import (
    command_fields,
    observation_from_gait_state,
    set_stamp,
    stamp_to_ns,
)
from iceskate_sim.scene import Scene, load_scene


class ControllerNode(Node):
    """Base of the controller nodes; subclasses implement ``configure`` and ``compute``."""

    #: Errors of the subclass's law package (logged per instant, never fatal).
    law_errors: tuple[type[Exception], ...] = ()

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        if 'use_sim_time' not in getattr(self, '_parameter_overrides', {}):
            self.set_parameters([Parameter('use_sim_time', Parameter.Type.BOOL, True)])
        scene_name = declare(self, 'scene', 'stand', 'shipped scene name, or scene YAML path')
        self.declare_extra()
        check_unknown(self)
        try:
            scene = load_scene(scene_name)
        except SimulationError as exc:
            raise ConfigError(f'parameter scene={scene_name!r}: {exc}') from None
        self.dynamics = GaitDynamics(load_robot())  # own model data, default physics
        self.active = self.configure(scene)
        if not self.active:
            self.get_logger().warning(f'scene {scene.name!r} does not run {node_name}: idle')
        self._message = EffortCommand(source=node_name)
        self._publisher = self.create_publisher(EffortCommand, 'effort_commands', STATE_QOS)
        self._typestore = make_typestore()
        self.create_subscription(GaitState, 'gait_state', self.on_gait_state,
                                 LOCKSTEP_READER_QOS, raw=True)

    def declare_extra(self) -> None:
        """Declare the subclass's own parameters (none by default)."""

    def configure(self, scene: Scene) -> bool:
        """Set the law up from the scene; return False if the scene does not run it."""
        raise NotImplementedError

    def compute(self, obs: Observation) -> dict[str, JointCommand]:
        """The commands of every source of this node at ``obs``."""
        raise NotImplementedError

    def on_gait_state(self, data: bytes) -> None:
        """Answer the state of one instant (a GaitState's CDR bytes) with this node's command."""
        if not self.active:
            return
        try:
            msg = self._typestore.deserialize_cdr(data, TOPICS['/gait_state'])
        except Exception as exc:  # rosbags raises several kinds on bytes it cannot decode
            self.get_logger().error(f'undecodable gait_state ({len(data)} bytes): {exc}')
            return
        ns = stamp_to_ns(msg.header.stamp)
        try:
            obs = observation_from_gait_state(msg)
            commands = self.compute(obs)
        except (SimulationError, *self.law_errors) as exc:
            self.get_logger().error(f'no command at t={ns / 1e9:.6f} s: {exc}')
            return
        message = self._message
        for field, value in command_fields(ControllerCommand.of(commands, obs.q, obs.v)).items():
            setattr(message, field, value)
        set_stamp(message.header.stamp, ns)
        self._publisher.publish(message)
