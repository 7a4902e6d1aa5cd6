"""``ros2 run iceskate_sim simulator``: the simulator node, a thin adapter over LockstepSession.

Publishes ``joint_states``, ``head_pose``, ``gait_state`` and ``/clock`` at every control instant
(the bytes the bag format gives, published raw), ``robot_description`` once (transient local);
takes ``effort_commands``; services ``~/step``, ``~/pause``, ``~/resume``, ``~/reset``.
Lockstep: state t_k out, a command stamped t_k from every source the scene runs, one period,
repeat; a source silent for ``control_timeout`` s ends the run with an error naming it. The bag
is written between publishing t_k and the commands' arrival. ``~/step`` answers at once with the
time the steps will reach (EventsExecutor has no deferred service responses); watch /clock.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import json
import pathlib
import time

from geometry_msgs.msg import PoseStamped
import numpy as np
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from iceskate_interfaces.msg import EffortCommand, GaitState
from iceskate_interfaces.srv import StepSimulation
from iceskate_sim.errors import SimulationError
from iceskate_sim.lockstep import LockstepSession, node_of_source
from iceskate_sim.node_support import (
    CLOCK_QOS,
    LATCHED_QOS,
    STATE_QOS,
    ConfigError,
    check_unknown,
    declare,
    run_node,
)
from iceskate_sim.ros_conversions import (
    command_from_message,
    ns_to_seconds,
    set_stamp,
    stamp_to_ns,
)
from iceskate_sim.scene import load_scene

RESEND_AFTER = 0.25  # s without a full set of commands: publish the state t_k again


@dataclass(frozen=True)
class SimulatorNodeConfig:
    """The simulator node's parameters (see config/simulator.yaml)."""

    scene: str
    duration: float  # s; 0: the scene's
    lockstep: bool
    realtime_factor: float  # free-running pace, simulated s per wall s
    control_timeout: float  # s
    startup_timeout: float  # s
    record_bag: str
    out_dir: str
    start_paused: bool
    exit_on_end: bool
    stats_file: str


class SimulatorNode(Node):
    """The simulator of a scene, in lockstep with the controller nodes (or free-running)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('simulator', **kwargs)
        c = self.config = self._read_parameters()
        try:
            scene = load_scene(c.scene)
            scene = replace(scene, duration=c.duration) if c.duration > 0 else scene
            self.session = LockstepSession(
                scene, pathlib.Path(c.out_dir) if c.out_dir else None,
                pathlib.Path(c.record_bag) if c.record_bag else None, c.lockstep)
        except SimulationError as exc:
            raise ConfigError(f'parameter scene={c.scene!r} (or record_bag/out_dir): {exc}') \
                from None
        self.finished, self.exit_code, self.paused = False, 0, c.start_paused
        self._budget, self._phase, self._published_at = 0, 'starting', 0.0
        self._started_at = time.monotonic()
        self._heard = {s: self._started_at for s in self.session.sources}
        self._stats: dict[str, list[float]] = {'round_trip': [], 'physics': [], 'rejected': []}
        self._pub = {'/clock': self.create_publisher(Clock, '/clock', CLOCK_QOS)} | {
            f'/{n}': self.create_publisher(t, n, STATE_QOS) for n, t in
            (('joint_states', JointState), ('head_pose', PoseStamped), ('gait_state', GaitState))}
        self.create_publisher(String, 'robot_description', LATCHED_QOS).publish(
            String(data=self.session.robot.urdf_path.read_text(encoding='utf-8')))
        self.create_service(StepSimulation, '~/step', self.step_callback)
        for name in ('pause', 'resume', 'reset'):
            self.create_service(Trigger, f'~/{name}', getattr(self, f'{name}_callback'))
        period = scene.simulator.control_period / c.realtime_factor
        self.create_timer(min(0.02, period) if not c.lockstep else 0.02, self.timer_callback)
        self._commands = self.create_subscription(EffortCommand, 'effort_commands',
                                                  self.on_effort_commands, STATE_QOS)

    def _read_parameters(self) -> SimulatorNodeConfig:
        cfg = SimulatorNodeConfig(
            declare(self, 'scene', 'stand', 'shipped scene name, or path of a scene YAML'),
            declare(self, 'duration', 0.0, 'run length [s]; 0: the scene duration', 0.0, 3600.0),
            declare(self, 'lockstep', True, 'wait for every command (else free-running)'),
            declare(self, 'realtime_factor', 1.0, 'free-running pace [-]', 1e-3, 1e3),
            declare(self, 'control_timeout', 5.0, 'wait for a command [s]', 1e-3, 3600.0),
            declare(self, 'startup_timeout', 60.0, 'wait for the controllers [s]', 0.0, 3600.0),
            declare(self, 'record_bag', '', 'path of the MCAP bag to write; empty: none'),
            declare(self, 'out_dir', '', 'directory for metrics.json & co.; empty: none'),
            declare(self, 'start_paused', False, 'start paused (~/step, ~/resume)'),
            declare(self, 'exit_on_end', True, 'exit when the run is over'),
            declare(self, 'stats_file', '', 'JSON file for loop timings; empty: none'))
        check_unknown(self)
        if not cfg.scene:
            raise ConfigError("parameter 'scene' must name a scene")
        return cfg

    # --------------------------------------------------------------------------- loop
    def _publish_state(self) -> None:
        for topic, message in self.session.state_messages().items():
            self._pub[topic].publish(self.session.serialize(topic, message))
        self._published_at = time.monotonic()

    def _may_step(self) -> bool:
        return self._phase == 'running' and (not self.paused or self._budget > 0)

    def _step(self) -> None:
        start = time.perf_counter()
        self.session.step()
        self._stats['physics'].append(time.perf_counter() - start)
        self._budget = max(0, self._budget - 1)
        if self.session.done:
            return self._finish()
        self._publish_state()
        self.session.flush()

    def on_effort_commands(self, msg: EffortCommand) -> None:
        """Take one command; step once every source has answered t_k (lockstep)."""
        if self._phase != 'running':
            return
        try:
            self.session.offer(msg.source, stamp_to_ns(msg.header.stamp),
                               command_from_message(msg))
        except SimulationError as exc:
            self._stats['rejected'].append(ns_to_seconds(self.session.t_ns))
            return self.get_logger().error(f'rejected command: {exc}')
        self._heard[msg.source] = time.monotonic()
        if self.session.lockstep and not self.session.missing():
            self._stats['round_trip'].append(time.monotonic() - self._published_at)
            if self._may_step():
                self._step()

    def timer_callback(self) -> None:
        """Start once the controllers are up; watchdog; free-running pace."""
        now, s = time.monotonic(), self.session
        if self._phase == 'starting':
            return self._try_start(now)
        if self._phase != 'running':
            return
        if not s.lockstep:
            silent = [k for k, t in self._heard.items() if now - t > self.config.control_timeout]
            if silent:
                return self._fail(silent)
            due = int((now - self._started_at) * self.config.realtime_factor
                      / s.scene.simulator.control_period)
            for _ in range(min(10, due - s.periods)):
                if self._phase == 'running' and self._may_step():
                    self._step()
        elif self._may_step() and s.missing():
            if now - self._published_at > self.config.control_timeout:
                self._fail(s.missing())
            elif now - self._published_at > RESEND_AFTER:
                self._publish_state()

    def _try_start(self, now: float) -> None:
        nodes = {node_of_source(s) for s in self.session.sources}
        seen = {i.node_name for i in self.get_publishers_info_by_topic('effort_commands')}
        for topic in ('joint_states', 'gait_state'):
            seen &= {i.node_name for i in self.get_subscriptions_info_by_topic(topic)}
        matched = min(p.get_subscription_count() for p in self._pub.values()
                      if p.topic_name != '/clock')
        if nodes <= seen and matched >= len(nodes):
            self._phase, self._started_at = 'running', now
            self._heard = dict.fromkeys(self._heard, now)
            self.get_logger().info(f'running {self.session.scene.name!r}: sources '
                                   f'{list(self.session.sources)}, nodes {sorted(nodes)}')
            return self._publish_state()
        if now - self._started_at > self.config.startup_timeout:
            self._finish(SimulationError(
                f'controller node(s) {sorted(nodes - seen)} not up within '
                f'{self.config.startup_timeout} s (publishing effort_commands, subscribed to '
                'joint_states and gait_state)'))

    def _fail(self, sources: list[str]) -> None:
        who = ', '.join(f'{s!r} (node {node_of_source(s)})' for s in sources)
        self._finish(SimulationError(
            f'controller timeout at t={self.session.sim.time:.6f} s: no command from source '
            f'{who} within {self.config.control_timeout} s'))

    def _finish(self, error: SimulationError | None = None) -> None:
        metrics = self.session.finish(error)
        self._phase = 'finished'
        self.exit_code = 1 if self.session.error is not None else 0
        log = self.get_logger().error if self.exit_code else self.get_logger().info
        log(f'run over at t={metrics["sim_time_s"]:.6f} s: {metrics["failure"] or "complete"}')
        if self.config.stats_file:
            stats = {k: np.percentile(v, [50, 99]).tolist() if v and k != 'rejected'
                     else len(v) for k, v in self._stats.items()}
            stats |= {'periods': self.session.periods, 'wall_time_s': metrics['wall_time_s']}
            pathlib.Path(self.config.stats_file).write_text(json.dumps(stats, indent=1))
        self.finished = self.config.exit_on_end

    def close(self) -> None:
        """Close the bag and write the outputs if the run was stopped (SIGTERM)."""
        if self._phase != 'finished':
            self._finish(SimulationError(f'stopped at t={self.session.sim.time:.6f} s'))

    # ----------------------------------------------------------------------- services
    def step_callback(self, request, response):
        """Queue N control periods of a paused simulation; sim_time is the time they reach."""
        response.success = self.paused and self._phase == 'running' and \
            request.control_periods >= 1
        periods = self._budget + request.control_periods if response.success else 0
        target = self.session.sim.time + periods * self.session.scene.simulator.control_period
        set_stamp(response.sim_time, int(round(target * 1e9)))
        response.message = (f'stepping to t={target:.6f} s' if response.success else
                            'step needs a paused running simulation and control_periods >= 1')
        if response.success:
            self._budget = periods
            self._resume_waiting()
        return response

    def _resume_waiting(self) -> None:
        self._published_at = time.monotonic()
        if self.session.lockstep and not self.session.missing() and self._may_step():
            self._step()

    def pause_callback(self, request, response):
        """Stop after the current period."""
        self.paused, response.success, response.message = True, True, 'paused'
        return response

    def resume_callback(self, request, response):
        """Run on."""
        self.paused, self._budget, response.success, response.message = False, 0, True, 'running'
        self._resume_waiting()
        return response

    def reset_callback(self, request, response):
        """Back to the scene's initial state (refused while recording a bag)."""
        try:
            self.session.reset()
        except SimulationError as exc:
            response.success, response.message = False, str(exc)
            return response
        self._phase, self._budget = 'running', 0
        self._publish_state()
        response.success, response.message = True, 'reset to t=0'
        return response


def main(args: list[str] | None = None) -> int:
    """Console entry point (``ros2 run iceskate_sim simulator``)."""
    return run_node(SimulatorNode, 'simulator', args)


if __name__ == '__main__':
    raise SystemExit(main())
