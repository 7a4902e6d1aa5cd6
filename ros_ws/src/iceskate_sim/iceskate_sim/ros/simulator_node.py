"""``ros2 run iceskate_sim simulator``: the simulator node, a thin adapter over LockstepLoop.

Publishes ``gait_state``, ``/clock``, ``joint_states``, ``head_pose`` and ``robot_description``,
takes ``effort_commands`` in lockstep, serves ``~/step``, ``~/pause``, ``~/resume``, ``~/reset``.
See docs/usage.md, 'Through ROS 2: the node graph, bags, replay, analysis'.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from functools import partial
import pathlib
import sys
import time
from typing import Any

from geometry_msgs.msg import PoseStamped
from rcl_interfaces.msg import ParameterDescriptor
from rclpy.exceptions import ParameterUninitializedException
from rclpy.node import Node
from rclpy.parameter import Parameter
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from iceskate_interfaces.msg import EffortCommand, GaitState
from iceskate_interfaces.srv import StepSimulation
from iceskate_native.parameters import checked, setting
from iceskate_sim.errors import InputRefused
from iceskate_sim.model.stamps import set_stamp
from iceskate_sim.ros.lockstep import LockstepLoop, LockstepSession
from iceskate_sim.ros.node_support import (
    CLOCK_QOS,
    LATCHED_QOS,
    LOCKSTEP_READER_QOS,
    STATE_QOS,
    ConfigError,
    check_unknown,
    declare_parameters,
    run_node,
)
from iceskate_sim.run.pace import MAX_PACE
from iceskate_sim.run.scene import MAX_DURATION, Scene, load_scene
from iceskate_sim.run.session import Session

#: Wall seconds between two looks at the graph for another run on the domain.
GRAPH_CHECK_PERIOD = 0.5
#: The node name rmw gives an endpoint whose node it has not discovered yet.
UNNAMED = '_NODE_NAME_UNKNOWN_'


@dataclass(frozen=True)
class SimulatorNodeParameters:
    """The simulator node's ROS parameters (see config/simulator.yaml); each field is a
    ``setting`` with its description, unit and range."""

    scene: str = setting('skate', 'a shipped scene name or the path of a scene YAML (its '
                         'simulator part: floor, initial state, integrator, disturbances, '
                         'duration, recording)')
    duration: float = setting(0.0, 'run length; 0: the scene duration', unit='s', low=0.0,
                              high=MAX_DURATION)
    lockstep: bool = setting(True, 'wait for every command stamped t_k (else free-running)')
    pace: float = setting(0.0, 'simulated s per wall s the run never goes beyond (0: as fast '
                          'as the controllers answer; free-running needs one); also settable '
                          'while it runs', low=0.0, high=MAX_PACE)
    control_timeout: float = setting(5.0, 'a controller silent this long ends the run',
                                     unit='s', low=1e-3, high=3600.0)
    startup_timeout: float = setting(60.0, 'wait for the controller nodes', unit='s', low=0.0,
                                     high=3600.0)
    record_bag: str = setting('', 'path of the MCAP bag to write; empty: none')
    out_dir: str = setting('', 'directory for metrics.json, events.json, trajectory.npz; '
                           'empty: none')
    start_paused: bool = setting(False, 'start paused (~/step, ~/resume)')
    exit_on_end: bool = setting(True, 'exit when the run is over')
    stats_file: str = setting('', 'JSON file for the loop timings; empty: none')
    run_token: str = setting('', "the token every command of this run must carry (its "
                             "launcher gives it to each node of the run: the controllers' "
                             'run_token); empty: commands without one')

    def __post_init__(self) -> None:
        checked(InputRefused)(self)
        if not self.lockstep and self.pace <= 0.0:
            raise InputRefused('pace must be > 0 when lockstep is false (a free-running run '
                               'keeps it)')


class SimulatorNode(Node):
    """The simulator of a scene, in lockstep with the controller nodes (or free-running)."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('simulator', **kwargs)
        c = self.config = declare_parameters(self, SimulatorNodeParameters, InputRefused,
                                             self._on_parameters)
        self._declare_controllers()
        check_unknown(self)
        try:
            scene = load_scene(c.scene)
            scene = replace(scene, duration=c.duration) if c.duration > 0 else scene
            out = pathlib.Path(c.out_dir) if c.out_dir else None
            # the parameter files and scene a graph's launcher writes into out/params for it
            made = (('params',) if out is not None
                    and pathlib.Path(c.scene).resolve().parent == (out / 'params').resolve()
                    else ())
            session = Session(scene, out, pathlib.Path(c.record_bag) if c.record_bag else None,
                              made=made)
        except InputRefused as exc:  # its message names the scene, bag or folder
            raise ConfigError(str(exc)) from None
        controllers = self._controllers(scene)
        self.session = LockstepSession(session, controllers, c.lockstep)
        self.loop = LockstepLoop(
            self.session, lambda topic, data: self._pub[topic].publish(data), self._report,
            c.control_timeout, c.pace, c.start_paused, c.stats_file,
            lambda topic: topic in self._readers, c.run_token)
        self._pub = {'/clock': self.create_publisher(Clock, '/clock', CLOCK_QOS)} | {
            f'/{n}': self.create_publisher(t, n, STATE_QOS) for n, t in
            (('joint_states', JointState), ('head_pose', PoseStamped), ('gait_state', GaitState))}
        self._readers: set[str] = set()  # live topics with readers (``timer_callback``)
        self._waited: set[str] | None = None  # controller nodes seen up while starting
        self._graph_seen_at = 0.0  # when the graph was last looked at for another run [s]
        self.create_publisher(String, 'robot_description', LATCHED_QOS).publish(
            String(data=self.session.robot.urdf_path.read_text(encoding='utf-8')))
        self.create_service(StepSimulation, '~/step', self.step_callback)
        for name in ('pause', 'resume', 'reset'):
            self.create_service(Trigger, f'~/{name}', partial(self._trigger,
                                                             getattr(self.loop, name)))
        self.create_timer(self.loop.timer_period, self.timer_callback)
        self.create_subscription(EffortCommand, 'effort_commands', self.on_effort_commands,
                                 LOCKSTEP_READER_QOS, raw=True)

    def _on_parameters(self, config: SimulatorNodeParameters) -> None:
        """``ros2 param set``: a new ``pace`` holds from now on (the others are read once)."""
        if config.pace != self.loop.pace:
            self.loop.pace = config.pace
            self.get_logger().info(f'pace {config.pace:g}x real time'
                                   + (' (none)' if config.pace == 0 else ''))

    def _declare_controllers(self) -> None:
        """``controllers`` and, for each, ``sources.<controller>`` (string arrays)."""
        self.declare_parameter('controllers', Parameter.Type.STRING_ARRAY, ParameterDescriptor(
            description='controller nodes whose commands are summed, in order (empty: the '
                        "scene's inputs; a node without sources.<node>: the sources its first "
                        'command names)'))
        overrides = getattr(self, '_parameter_overrides', {})
        for name in overrides.get('controllers', Parameter('', value=[])).value or []:
            self.declare_parameter(f'sources.{name}', Parameter.Type.STRING_ARRAY,
                                   ParameterDescriptor(description=f'command sources of {name}, '
                                                       'in the order of its breakdown'))

    def _controllers(self, scene: Scene) -> dict[str, tuple[str, ...] | None]:
        """Each controller node (parameter ``controllers``, else the scene's inputs) with its
        sources (parameter ``sources.<node>``; None: the breakdown of its first command)."""
        try:
            names = list(self.get_parameter('controllers').value) or list(scene.inputs)
        except ParameterUninitializedException:  # not given: the scene's controller blocks
            names = list(scene.inputs)
        out = {}
        for name in names:
            try:
                sources = (self.get_parameter(f'sources.{name}').value
                           if self.has_parameter(f'sources.{name}') else None)
            except ParameterUninitializedException:  # declared for `controllers`, not given
                sources = None
            out[name] = tuple(sources) if sources else None
        return out

    @property
    def finished(self) -> bool:
        """The run is over and the node should exit (parameter exit_on_end)."""
        return self.config.exit_on_end and self.loop.phase == 'finished'

    @property
    def exit_code(self) -> int:
        """The run's exit status (``LockstepLoop.finish``): 0, 1 after an error, 128 + N after
        signal N."""
        return self.loop.exit_code

    def _report(self, text: str, failed: bool) -> None:
        if not self.context.ok():  # stopped by a signal: rosout is gone
            print(f'[simulator] {text}', file=sys.stderr)
        else:
            (self.get_logger().error if failed else self.get_logger().info)(text)

    def on_effort_commands(self, data: bytes) -> None:
        """Take one command (CDR bytes); step once every source has answered t_k (lockstep),
        at the pace."""
        if rejected := self.loop.take(data):
            self.get_logger().error(rejected)

    def timer_callback(self) -> None:
        """Start once the controllers are up; watchdog and resend; the pace (``tick``)."""
        # the live topics with readers (4 rmw calls: here, not at every instant)
        self._readers = {t for t, pub in self._pub.items() if pub.get_subscription_count()}
        now = time.monotonic()
        if now - self._graph_seen_at > GRAPH_CHECK_PERIOD:
            self._graph_seen_at = now
            writers = [i.node_name for i in self.get_publishers_info_by_topic('effort_commands')
                       if i.node_name != UNNAMED]  # named once discovery has it
            for text in self.loop.clashes(self.count_publishers('gait_state'), writers):
                self.get_logger().warning(text)
        self._try_start() if self.loop.phase == 'starting' else self.loop.tick()

    def _try_start(self) -> None:
        up = ({i.node_name for i in self.get_publishers_info_by_topic('effort_commands')}
              & {i.node_name for i in self.get_subscriptions_info_by_topic('gait_state')})
        matched = self._pub['/gait_state'].get_subscription_count()
        nodes = set(self.session.controllers)
        if self._waited is None and nodes:  # once: what it waits for, then each arrival
            self._waited = set()
            self.get_logger().info(
                f'waiting up to {self.config.startup_timeout:g} s for the controller node(s) '
                f'{sorted(nodes)} (after `. ./env.sh`, e.g. `visual_lifting --ros-args '
                '--params-file DIR/params/visual_lifting.yaml` on this ROS_DOMAIN_ID; '
                '`run_scene SCENE --ros` starts them all)')
        for name in sorted((up & nodes) - (self._waited or set())):
            self._waited.add(name)
            self.get_logger().info(f'controller node {name!r} is up')
        if self.loop.try_begin(up, matched, self.config.startup_timeout):
            self.get_logger().info(f'running {self.session.scene.name!r}: sources '
                                   f'{list(self.session.sources)}, nodes '
                                   f'{sorted(self.session.controllers)}')

    def close(self, signum: int | None = None, detail: str = '') -> None:
        """Close the bag and write the outputs if the run was stopped (by the signal
        ``signum``: the metrics say 'interrupted by SIG... at t=...'; ``detail`` is added)."""
        self.loop.stop(signum, detail)

    def step_callback(self, request: Any, response: Any) -> Any:
        """Queue N periods of a paused simulation; sim_time: the time they will reach."""
        response.success, ns, response.message = self.loop.request_steps(
            request.control_periods)
        set_stamp(response.sim_time, ns)
        return response

    def _trigger(self, action: Any, request: Any, response: Any) -> Any:
        """~/pause, ~/resume, ~/reset: the loop's action, its (success, message)."""
        response.success, response.message = action()
        return response


def main(args: list[str] | None = None) -> int:
    """Console entry point (``ros2 run iceskate_sim simulator``)."""
    return run_node(SimulatorNode, 'iceskate_sim', 'simulator', args, __doc__,
                    SimulatorNodeParameters)


if __name__ == '__main__':
    raise SystemExit(main())
