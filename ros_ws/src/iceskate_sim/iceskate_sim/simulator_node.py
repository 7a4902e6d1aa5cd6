"""``ros2 run iceskate_sim simulator``: the simulator node, a thin adapter over LockstepSession.

Publishes ``joint_states``, ``head_pose``, ``gait_state`` and ``/clock`` at every control instant
(the CDR bytes of the bag's message types, published raw) and ``robot_description`` once
(transient local); takes ``effort_commands``; services ``~/step``, ``~/pause``, ``~/resume``,
``~/reset``. Lockstep: state t_k out, a command stamped t_k from every source the scene runs,
one period, repeat; a source silent for ``control_timeout`` s ends the run with an error naming
it and its node. The bag is written while the controllers compute. ``~/step`` answers at once
with the time the steps will reach (the EventsExecutor cannot defer a response): watch /clock.
"""

from __future__ import annotations

from dataclasses import replace
import json
import pathlib
import sys
import time
from types import SimpleNamespace

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState
from std_msgs.msg import String
from std_srvs.srv import Trigger

from iceskate_interfaces.msg import EffortCommand, GaitState
from iceskate_interfaces.srv import StepSimulation
from iceskate_sim.errors import SimulationError
from iceskate_sim.lockstep import LockstepSession, LoopMonitor, node_of_source
from iceskate_sim.node_support import (
    CLOCK_QOS,
    LATCHED_QOS,
    STATE_QOS,
    ConfigError,
    check_unknown,
    declare,
    run_node,
)
from iceskate_sim.ros_conversions import command_from_message, set_stamp, stamp_to_ns
from iceskate_sim.scene import load_scene

#: name, default, description (units), bounds of a float (see config/simulator.yaml).
PARAMETERS = (
    ('scene', 'stand', 'shipped scene name, or path of a scene YAML', None),
    ('duration', 0.0, 'run length [s]; 0: the scene duration', (0.0, 3600.0)),
    ('lockstep', True, 'wait for every command stamped t_k (else free-running)', None),
    ('realtime_factor', 1.0, 'free-running pace [simulated s per wall s]', (1e-3, 1e3)),
    ('control_timeout', 5.0, 'a controller silent this long ends the run [s]', (1e-3, 3600.0)),
    ('startup_timeout', 60.0, 'wait for the controller nodes [s]', (0.0, 3600.0)),
    ('record_bag', '', 'path of the MCAP bag to write; empty: none', None),
    ('out_dir', '', 'directory for metrics.json, events.json, trajectory.npz; empty: none',
     None),
    ('start_paused', False, 'start paused (~/step, ~/resume)', None),
    ('exit_on_end', True, 'exit when the run is over', None),
    ('stats_file', '', 'JSON file for the loop timings; empty: none', None),
)


class SimulatorNode(Node):
    """The simulator of a scene, in lockstep with the controller nodes (or free-running)."""

    def __init__(self, **kwargs) -> None:
        super().__init__('simulator', **kwargs)
        c = self.config = SimpleNamespace(**{
            name: declare(self, name, default, text, *(bounds or ()))
            for name, default, text, bounds in PARAMETERS})
        check_unknown(self)
        try:
            scene = load_scene(c.scene)
            scene = replace(scene, duration=c.duration) if c.duration > 0 else scene
            self.session = LockstepSession(
                scene, pathlib.Path(c.out_dir) if c.out_dir else None,
                pathlib.Path(c.record_bag) if c.record_bag else None, c.lockstep)
        except SimulationError as exc:
            raise ConfigError(f'parameter scene={c.scene!r} (or record_bag, out_dir): {exc}') \
                from None
        period = scene.simulator.control_period
        self.monitor = LoopMonitor(self.session.sources, c.control_timeout, period,
                                   c.realtime_factor)
        self.finished, self.exit_code, self.paused = False, 0, c.start_paused
        self._budget, self._phase = 0, 'starting'
        self._pub = {'/clock': self.create_publisher(Clock, '/clock', CLOCK_QOS)} | {
            f'/{n}': self.create_publisher(t, n, STATE_QOS) for n, t in
            (('joint_states', JointState), ('head_pose', PoseStamped), ('gait_state', GaitState))}
        self.create_publisher(String, 'robot_description', LATCHED_QOS).publish(
            String(data=self.session.robot.urdf_path.read_text(encoding='utf-8')))
        self.create_service(StepSimulation, '~/step', self.step_callback)
        for name in ('pause', 'resume', 'reset'):
            self.create_service(Trigger, f'~/{name}', getattr(self, f'{name}_callback'))
        pace = min(0.02, period / c.realtime_factor) if not c.lockstep else 0.02
        self.create_timer(pace, self.timer_callback)
        self.create_subscription(EffortCommand, 'effort_commands', self.on_effort_commands,
                                 STATE_QOS)

    # --------------------------------------------------------------------------- loop
    def _publish_state(self, again: bool = False) -> None:
        for topic, message in self.session.state_messages().items():
            self._pub[topic].publish(self.session.serialize(topic, message))
        self.monitor.published(again)

    def _may_step(self) -> bool:
        return self._phase == 'running' and (not self.paused or self._budget > 0)

    def _step(self) -> None:
        start = time.perf_counter()
        self.session.step()
        self.monitor.samples['physics'].append(time.perf_counter() - start)
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
            self.monitor.rejected += 1
            return self.get_logger().error(f'rejected command: {exc}')
        complete = self.session.lockstep and not self.session.missing()
        self.monitor.command(msg.source, complete)
        if complete and self._may_step():
            self._step()

    def timer_callback(self) -> None:
        """Start once the controllers are up; watchdog and resend; free-running pace."""
        if self._phase == 'starting':
            return self._try_start()
        if self._phase != 'running' or not self._may_step():
            return
        s, m = self.session, self.monitor
        overdue = m.overdue(s.missing(), s.lockstep)
        if overdue:
            who = ', '.join(f'{x!r} (node {node_of_source(x)})' for x in overdue)
            return self._finish(SimulationError(
                f'controller timeout at t={s.sim.time:.6f} s: no command from source {who} '
                f'within {self.config.control_timeout} s'))
        if s.lockstep and s.missing() and m.resend_due():
            self._publish_state(again=True)
        for _ in range(0 if s.lockstep else m.due(s.periods)):
            if self._phase == 'running' and self._may_step():
                self._step()

    def _try_start(self) -> None:
        nodes = {node_of_source(s) for s in self.session.sources}
        up = {i.node_name for i in self.get_publishers_info_by_topic('effort_commands')}
        for topic in ('joint_states', 'gait_state'):
            up &= {i.node_name for i in self.get_subscriptions_info_by_topic(topic)}
        matched = min(self._pub[t].get_subscription_count() for t in ('/joint_states',
                                                                       '/gait_state'))
        if nodes <= up and matched >= len(nodes):
            self.get_logger().info(f'running {self.session.scene.name!r}: sources '
                                   f'{list(self.session.sources)}, nodes {sorted(nodes)}')
            self._phase = 'running'
            self.monitor.start()
            return self._publish_state()
        if time.monotonic() - self.monitor.started_at > self.config.startup_timeout:
            self._finish(SimulationError(
                f'controller node(s) {sorted(nodes - up)} not up within '
                f'{self.config.startup_timeout} s (publishing effort_commands, subscribed to '
                'joint_states and gait_state)'))

    def _finish(self, error: SimulationError | None = None) -> None:
        metrics = self.session.finish(error)
        self._phase, self.exit_code = 'finished', int(self.session.error is not None)
        text = f'run over at t={metrics["sim_time_s"]:.6f} s: {metrics["failure"] or "complete"}'
        if not self.context.ok():  # stopped by a signal: rosout is gone
            print(f'[simulator] {text}', file=sys.stderr)
        else:
            (self.get_logger().error if self.exit_code else self.get_logger().info)(text)
        if self.config.stats_file:
            pathlib.Path(self.config.stats_file).write_text(json.dumps(self.monitor.stats(
                self.session.periods, metrics['wall_time_s']), indent=1))
        self.finished = self.config.exit_on_end

    def close(self) -> None:
        """Close the bag and write the outputs if the run was stopped (SIGTERM)."""
        if self._phase != 'finished':
            self._finish(SimulationError(f'stopped at t={self.session.sim.time:.6f} s'))

    # ----------------------------------------------------------------------- services
    def step_callback(self, request, response):
        """Queue N periods of a paused simulation; sim_time: the time they will reach."""
        ok = self.paused and self._phase == 'running' and request.control_periods >= 1
        periods = self._budget + request.control_periods if ok else 0
        target = self.session.sim.time + periods * self.session.scene.simulator.control_period
        set_stamp(response.sim_time, int(round(target * 1e9)))
        response.success, response.message = ok, (
            f'stepping to t={target:.6f} s' if ok else
            'step needs a paused, running simulation and control_periods >= 1')
        if ok:
            self._budget = periods
            self._go_on()
        return response

    def _go_on(self) -> None:
        self.monitor.wait_anew()
        if self.session.lockstep and not self.session.missing() and self._may_step():
            self._step()

    def pause_callback(self, request, response):
        """Stop after the current period."""
        self.paused, response.success, response.message = True, True, 'paused'
        return response

    def resume_callback(self, request, response):
        """Run on."""
        self.paused, self._budget, response.success, response.message = False, 0, True, 'running'
        self._go_on()
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
