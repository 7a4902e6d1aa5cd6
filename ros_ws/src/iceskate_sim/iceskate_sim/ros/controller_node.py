"""The part the controller nodes share: ``ControllerNode`` (its law's typed parameters,
``gait_state`` bytes in, one raw ``EffortCommand`` per instant out). See docs/usage.md,
'Through ROS 2: the node graph, bags, replay, analysis', and docs/architecture.md, 'One run:
many periods per native call'.
"""

from __future__ import annotations

from typing import Any, Generic, TypeVar

from rcl_interfaces.msg import ParameterDescriptor
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter

from iceskate_interfaces.msg import EffortCommand, GaitState
import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import CommandValues
from iceskate_sim.model.robot import load_robot
from iceskate_sim.physics.native_control import native_kinematics
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.ros.effort_cdr import CommandEncoder
from iceskate_sim.ros.gait_state_cdr import GaitStateReader
from iceskate_sim.ros.node_support import (
    LOCKSTEP_READER_QOS,
    STATE_QOS,
    check_unknown,
    declare_parameters,
)

P = TypeVar('P')
#: Wall seconds between two looks for the simulator (after the first state).
SIMULATOR_CHECK_PERIOD = 0.5


class ControllerNode(Node, Generic[P]):
    """Base of the controller nodes; subclasses set the class attributes and ``compute``."""

    #: The law's parameter class and the error its rules raise.
    parameter_class: type
    parameter_error: type[Exception]
    #: Errors of the subclass's law package (logged per instant, never fatal).
    law_errors: tuple[type[Exception], ...] = ()

    def __init__(self, node_name: str, **kwargs: Any) -> None:
        super().__init__(node_name, **kwargs)
        if 'use_sim_time' not in getattr(self, '_parameter_overrides', {}):
            self.set_parameters([Parameter('use_sim_time', Parameter.Type.BOOL, True)])
        self.params: P = declare_parameters(self, self.parameter_class, self.parameter_error,
                                            self._on_parameters)
        run_token = self.declare_parameter('run_token', '', ParameterDescriptor(
            description='the token of the run this node answers, carried by its commands (its '
                        "launcher gives every node of a run one: the simulator's run_token); "
                        'empty: none', read_only=True)).value
        self.declare_more_parameters()
        check_unknown(self)
        self.kinematics = native_kinematics(load_robot())  # the laws' own model data
        typestore = make_typestore()
        self._encoder = CommandEncoder(node_name, run_token, typestore)
        self._gait_states = GaitStateReader(typestore)
        self._publisher = self.create_publisher(EffortCommand, 'effort_commands', STATE_QOS)
        self._states = self.create_subscription(GaitState, 'gait_state', self.on_gait_state,
                                                LOCKSTEP_READER_QOS, raw=True)
        self._served = False  # a state has come: a simulator serves this node
        self._clash_said = False  # said that states come from more than one simulator
        #: The simulator it served is gone (``node_support.run_node`` then ends the node).
        self.finished = False
        self.create_timer(SIMULATOR_CHECK_PERIOD, self._check_simulator,
                          clock=Clock(clock_type=ClockType.STEADY_TIME))  # /clock stops at the end
        self.get_logger().info('ready: answering gait_state on effort_commands')

    def declare_more_parameters(self) -> None:
        """Declare a subclass's further parameters (called before overrides no parameter
        takes are refused; ``self.params`` is set)."""

    def _check_simulator(self) -> None:
        """End the node once the simulator it served has no gait_state publisher left; say
        once when states come from more than one simulator (two graphs on one domain)."""
        simulators = self._states.get_publisher_count()
        if simulators > 1 and not self._clash_said:
            self._clash_said = True
            self.get_logger().warning(
                f'{simulators} nodes publish gait_state on this ROS domain: this controller '
                'answers the states of more than one simulator (give each graph its own '
                'ROS_DOMAIN_ID)')
        if self._served and not self.finished and simulators == 0:
            self.get_logger().info('the simulator is gone: the run is over')
            self.finished = True

    def _on_parameters(self, params: P) -> None:
        """New parameters (``ros2 param set``), already checked: used from the next state."""
        self.params = params
        self.get_logger().info('parameters changed')

    @property
    def active(self) -> bool:
        """Whether the node answers states (an idle controller sends nothing)."""
        return True

    def compute(self, obs: iceskate_native.Observation) -> CommandValues:
        """This node's command at ``obs`` (its sources summed, with their breakdown)."""
        raise NotImplementedError

    def on_gait_state(self, data: bytes) -> None:
        """Answer the state of one instant (a GaitState's CDR bytes) with this node's command."""
        self._served = True
        if not self.active:
            return
        try:
            ns, obs = self._gait_states.read(data)
        except SimulationError as exc:
            self.get_logger().error(f'no command: {exc}')
            return
        try:
            values = self.compute(obs)
        except (SimulationError, *self.law_errors) as exc:
            self.get_logger().error(f'no command at t={ns / 1e9:.6f} s: {exc}')
            return
        self._publisher.publish(self._encoder.encode(values, ns))
