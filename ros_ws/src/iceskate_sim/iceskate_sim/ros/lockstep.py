"""The simulator side of the ROS graph, ROS-free: ``LockstepSession`` (commands in, one period of
the shared ``Session``, state out), ``LoopMonitor`` (the node loop's wall clock: timeouts,
resends, pace) and ``LockstepLoop`` (phases, pause and ~/step, the end of the run). The two
views of an instant and the free-running mode: docs/architecture.md, "One loop"."""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable
import json
import math
import pathlib
import re
import time
from typing import Any

import numpy as np

from iceskate_sim.errors import InputRefused, RunInterrupted, SimulationError
from iceskate_sim.exit_codes import DONE, exit_code_of
from iceskate_sim.model.command import CommandValues
from iceskate_sim.model.robot import COORDINATE_NAMES
from iceskate_sim.model.stamps import ns_to_seconds, seconds_to_ns
from iceskate_sim.physics.hybrid import HybridState
from iceskate_sim.recording.bag_types import make_typestore
from iceskate_sim.recording.messages import SampleMessages
from iceskate_sim.ros.effort_cdr import CommandDecoder, ForeignCommand
from iceskate_sim.run.pace import PaceClock
from iceskate_sim.run.session import Session

#: Live state topics the controllers read, published first, as soon as the state is known (the
#: state, then /clock while their transport threads are awake: 3-5 % faster than /clock first).
CONTROL_TOPICS = ('/gait_state', '/clock')
#: Every live state topic, in publishing order.
STATE_TOPICS = CONTROL_TOPICS + ('/joint_states', '/head_pose')
#: Rejected commands kept whole for the run's summary (the rest are only counted).
FIRST_REJECTED = 5
#: Controller names of other runs' commands said in the log (every command is counted).
FOREIGN_NAMES_SAID = 5
#: Lockstep without controllers: periods stepped per timer tick (nothing to wait for).
UNCONTROLLED_BATCH = 50
#: Period of the simulator node's wall-clock timer [s]: timeouts, resends, the pace.
TICK = 0.02
#: Free-running: periods stepped per timer tick at the most (a pace the machine cannot keep
#: does not hold the node's services for long).
FREE_BATCH = 200
_NUMBERS = re.compile(r'[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?')


class EffortLimitExceeded(SimulationError):
    """A controller of the run asked for more than a coordinate's effort limit: the run ends
    (``controller_failed``), naming the coordinate and the limit."""

    def __init__(self, message: str) -> None:
        super().__init__(message, end='controller_failed')


class LockstepSession:
    """A ``Session`` driven by commands that arrive from outside (the controller nodes).

    :param session: the run.
    :param controllers: the controller nodes the scene runs, in summing order, each with the
        names of its command sources in order (its breakdown); None: the breakdown of the
        node's first command (one source named like the node until then), taken while no
        period has run.
    :param lockstep: wait for a command stamped t_k from every controller (True), or hold each
        controller's latest command (False).
    """

    def __init__(self, session: Session, controllers: dict[str, tuple[str, ...] | None],
                 lockstep: bool = True) -> None:
        self.session = session
        self.scene = session.scene
        self.sim = session.sim
        self.robot = session.robot
        self.lockstep = lockstep
        self._breakdown = {c: sources or (c,) for c, sources in controllers.items()}
        self._learning = {c for c, sources in controllers.items() if sources is None}
        self.controllers = tuple(controllers)
        self.messages = (session.recorder.messages if session.recorder else
                         SampleMessages(make_typestore(), self.robot.tf_frames))
        #: the native loop that holds the commands
        self._inbox = session.command_inbox(tuple(self._breakdown.values()))
        self._index = {c: k for k, c in enumerate(self.controllers)}
        self._restart()

    def _restart(self) -> None:
        self._answered: set[str] = set()  # controllers with a command held (free-running)
        self._received: dict[str, CommandValues] = {}  # each controller's latest command
        self._stamps: dict[str, int] = {}
        #: the state, its live sample and the latest event at it
        self._live: tuple[HybridState, tuple[int, int, int]] | None = None

    # ----------------------------------------------------------------------------- state
    @property
    def t_ns(self) -> int:
        """Stamp of the current instant t_k [ns]."""
        return seconds_to_ns(self.sim.time)

    @property
    def sources(self) -> tuple[str, ...]:
        """Every controller's sources, in summing order."""
        return tuple(s for sources in self._breakdown.values() for s in sources)

    def state_bytes(self, topics: tuple[str, ...] = STATE_TOPICS) -> dict[str, bytes]:
        """CDR bytes of the live ``topics``' messages at t_k (see the module docstring), the
        bag's message types, publishable raw (encoded as the bag's records are)."""
        s = self.sim.state
        if self._live is None or self._live[0] is not s:  # taken once per instant
            self._live = (s, self._inbox.kernel.live_fill())
        return self.messages.encode_live(self._inbox.kernel, self._live[1], self.sim.events,
                                         topics)

    # -------------------------------------------------------------------------- commands
    def offer(self, controller: str, stamp_ns: int, command: CommandValues) -> bool:
        """Take a controller's command; False for a repeat of its last stamp (ignored).

        An empty breakdown is the effort of a controller's only source, named like it,
        evaluated at the current state.

        :raises EffortLimitExceeded: for a generalized force at the current state (effort and
            impedance) beyond a coordinate's effort limit (``Robot.effort_limit``).
        :raises SimulationError: for an unknown controller, a breakdown that does not name
            the controller's sources in order, a stamp that is stale (before t_k, or in
            free-running mode before the controller's last command) or in the future, or
            values of a wrong size, not finite or negative gains.
        """
        if controller not in self.controllers:
            raise SimulationError(f'command from unknown source {controller!r}; scene '
                                  f'{self.scene.name!r} runs the controllers '
                                  f'{list(self.controllers)}')
        expected = self._breakdown[controller]
        if controller in self._learning and command.sources and command.sources != expected:
            self._adopt(controller, command.sources)
            expected = command.sources
        self._learning.discard(controller)
        state = self.sim.state
        torque = command.torque(state.q, state.v)
        if not command.sources and expected == (controller,):
            command = command._replace(source_efforts=torque, sources=expected)
        over = np.abs(torque) > self.robot.effort_limit
        if over.any():
            k = int(np.argmax(over))
            raise EffortLimitExceeded(f'command of {controller!r} asks {torque[k]:.6g} '
                                  f'{"N" if k == 0 else "N m"} of {COORDINATE_NAMES[k]} at '
                                  f't={self.sim.time:.6f} s, beyond its effort limit '
                                  f"{self.robot.effort_limit[k]:g} (the URDF's)")
        if command.sources != expected:
            raise SimulationError(f'command of {controller!r} breaks down into sources '
                                  f'{list(command.sources)}; scene {self.scene.name!r} '
                                  f'runs {list(expected)} on it')
        now = self.t_ns
        if stamp_ns > now:
            raise SimulationError(f'command of {controller!r} stamped '
                                  f'{ns_to_seconds(stamp_ns)} s is in the future (simulation '
                                  f'at {ns_to_seconds(now)} s)')
        previous = self._stamps.get(controller, -1)
        if self.lockstep and stamp_ns == previous:  # again (an answer to a resent state)
            return False
        if stamp_ns < now if self.lockstep else stamp_ns < previous:
            raise SimulationError(f'stale command of {controller!r} stamped '
                                  f'{ns_to_seconds(stamp_ns)} s (simulation at '
                                  f'{ns_to_seconds(now)} s)')
        try:
            self._inbox.receive(self._index[controller], command)
        except SimulationError as exc:
            raise SimulationError(f'{exc} (from {controller!r})') from None
        self._answered.add(controller)
        self._stamps[controller] = stamp_ns
        self._received[controller] = command
        return True

    def _adopt(self, controller: str, sources: tuple[str, ...]) -> None:
        """Take ``sources`` as the breakdown of ``controller`` (whose sources were not given):
        a new inbox, holding the commands received so far."""
        if self.session.periods:
            raise SimulationError(f'command of {controller!r} breaks down into sources '
                                  f'{list(sources)} after the run began with '
                                  f'{list(self._breakdown[controller])}')
        self._breakdown[controller] = tuple(sources)
        self._inbox = self.session.command_inbox(tuple(self._breakdown.values()), renew=True)
        self._live = None
        for other, command in self._received.items():
            self._inbox.receive(self._index[other], command)

    def missing(self) -> list[str]:
        """Controllers whose command for t_k has not arrived (free-running: none ever did)."""
        if self.lockstep:
            now = self.t_ns
            return [c for c in self.controllers if self._stamps.get(c) != now]
        return [c for c in self.controllers if c not in self._answered]

    # -------------------------------------------------------------------------- stepping
    def step(self) -> bool:
        """Integrate one period under the commands in (``Session.hold``); False if done."""
        if self.session.done:
            return False
        if self.lockstep and self.missing():
            raise SimulationError(f'step at t={self.sim.time} s without commands of '
                                  f'{self.missing()}')
        taken = self.session.hold(clear=self.lockstep)
        if self.lockstep:
            self._answered.clear()
        return taken

    def reset(self) -> None:
        """Back to the scene's initial state (refused while recording a bag)."""
        self.session.reset()
        self._restart()


class LoopMonitor:
    """The wall-clock side of the simulator's loop (ROS-free): timeouts, resends, pace, stats.

    :param sources: the controllers of the scene (the sources of commands).
    :param control_timeout: a source silent this long [s] ends the run.
    :param period: control period [s].
    :param pace: simulated seconds per wall second (0: none); free-running needs one.
    :param resend_after: publish the state t_k again after this long without every command [s].
    """

    def __init__(self, sources: tuple[str, ...], control_timeout: float, period: float,
                 pace: float = 0.0, resend_after: float = 0.25) -> None:
        self.sources, self.timeout, self.resend_after = sources, control_timeout, resend_after
        self.period, self.clock = period, PaceClock(pace)
        self.started_at = self.published_at = self.waiting_since = time.monotonic()
        self.heard = dict.fromkeys(sources, self.started_at)
        self.samples: dict[str, list[float]] = {'round_trip': [], 'physics': []}
        self.rejected = 0
        self.rejected_by_reason: Counter[str] = Counter()
        self.rejected_first: list[str] = []

    def reject(self, reason: str) -> None:
        """A command was refused for ``reason`` (counted by its kind: the reason without its
        numbers; the first ``FIRST_REJECTED`` kept whole)."""
        self.rejected += 1
        self.rejected_by_reason[_NUMBERS.sub('#', reason)] += 1
        if len(self.rejected_first) < FIRST_REJECTED:
            self.rejected_first.append(reason)

    def rejected_summary(self) -> dict[str, Any]:
        """The commands refused: count, count per reason, the first few (metrics.json)."""
        return {'count': self.rejected, 'by_reason': dict(self.rejected_by_reason.most_common()),
                'first': list(self.rejected_first)}

    def start(self) -> None:
        """The run starts now (the pace counts from here)."""
        self.started_at = self.waiting_since = time.monotonic()
        self.clock.restart()
        self.heard = dict.fromkeys(self.sources, self.started_at)

    def published(self, again: bool = False) -> None:
        """A state went out (``again``: the same t_k once more)."""
        self.published_at = time.monotonic()
        if not again:
            self.waiting_since = self.published_at

    def command(self, source: str, complete: bool) -> None:
        """A valid command came in; ``complete``: now every source has answered t_k."""
        self.heard[source] = time.monotonic()
        if complete:
            self.samples['round_trip'].append(self.heard[source] - self.published_at)

    def overdue(self, missing: list[str], lockstep: bool) -> list[str]:
        """Sources whose silence ends the run (lockstep: while waiting for t_k)."""
        now = time.monotonic()
        if lockstep:
            return missing if missing and now - self.waiting_since > self.timeout else []
        return [s for s, t in self.heard.items() if now - t > self.timeout]

    def resend_due(self) -> bool:
        """Time to publish the state t_k again (a state may be lost before discovery ends)."""
        return time.monotonic() - self.published_at > self.resend_after

    def due(self, t: float, most: int) -> int:
        """Periods due now from simulated time ``t`` [s] at the pace (no pace: ``most``)."""
        return self.clock.due(t, self.period, most)

    def stats(self, periods: int, wall_time: float) -> dict[str, Any]:
        """Median, p95 and p99 [s] of the round trip and the physics step per period; counts."""
        out: dict[str, Any] = {k: np.percentile(v, [50, 95, 99]).tolist() if v else []
                               for k, v in self.samples.items()}
        return out | {'rejected': self.rejected, 'periods': periods, 'wall_time_s': wall_time}


class LockstepLoop:
    """The simulator node's loop without ROS: phases, pause and step budget, commands, outputs.

    :param session: the run.
    :param publish: ``publish(topic, data)`` sends one live state message (CDR bytes).
    :param report: ``report(text, failed)`` tells how the run ended (once).
    :param control_timeout: a source silent this long [s] ends the run.
    :param pace: simulated seconds per wall second that the run never goes beyond (0: as fast
        as the controllers answer); free-running: the pace it keeps (> 0).
    :param paused: start paused (``~/step``, ``resume``).
    :param stats_file: JSON file for the loop timings (None or '': none).
    :param listened: ``listened(topic)``: whether a live topic has readers (its messages are
        built only then).
    :param run_token: the token every command of this run carries ('': nodes started by hand,
        commands without one).
    """

    def __init__(self, session: LockstepSession, publish: Callable[[str, bytes], None],
                 report: Callable[[str, bool], None], control_timeout: float = 5.0,
                 pace: float = 0.0, paused: bool = False,
                 stats_file: str | pathlib.Path | None = None,
                 listened: Callable[[str], bool] = lambda topic: True,
                 run_token: str = '') -> None:
        if not session.lockstep and pace <= 0.0:
            raise InputRefused('a free-running run (lockstep false) needs a pace > 0')
        self.session = session
        self._listened = listened
        self.monitor = LoopMonitor(session.controllers, control_timeout,
                                   session.scene.simulator.control_period, pace)
        self._publish, self._report = publish, report
        self._decoder = CommandDecoder(run_token)
        self._foreign: set[str] = set()  # controller names another run's commands carried
        self._clashes: set[str] = set()  # what ``clashes`` said
        self._stats_file = pathlib.Path(stats_file) if stats_file else None
        self.phase, self.paused, self.budget, self.exit_code = 'starting', paused, 0, 0

    @property
    def timer_period(self) -> float:
        """Period of the node's wall-clock timer (``tick``) [s]: ``TICK``; free-running: a
        period at its pace, at the most ``TICK``."""
        m = self.monitor
        return TICK if self.session.lockstep else min(TICK, m.period / m.clock.pace)

    @property
    def pace(self) -> float:
        """Simulated seconds per wall second the run keeps to (0: none)."""
        return self.monitor.clock.pace

    @pace.setter
    def pace(self, pace: float) -> None:
        self.monitor.clock.pace = pace

    def may_step(self) -> bool:
        """Running, and not paused or with ~/step periods left."""
        return self.phase == 'running' and (not self.paused or self.budget > 0)

    def try_begin(self, up: set[str], matched: int, startup_timeout: float) -> bool:
        """Run (and publish the state at t_0) once every controller node is up.

        :param up: nodes publishing commands and subscribed to the state (gait_state).
        :param matched: matched readers of gait_state.
        :param startup_timeout: end the run with an error naming the missing nodes after
            this long [s].
        :returns: whether the run started now.
        """
        nodes = set(self.session.controllers)
        if nodes <= up and matched >= len(nodes):
            self.phase = 'running'
            self.monitor.start()
            self.publish_state()
            return True
        if time.monotonic() - self.monitor.started_at > startup_timeout:
            self.finish(SimulationError(
                f'controller node(s) {sorted(nodes - up)} not up within {startup_timeout} s '
                '(publishing effort_commands, subscribed to gait_state)',
                end='controller_timeout'))
        return False

    def clashes(self, simulators: int, command_writers: list[str]) -> list[str]:
        """What the ROS graph shows of another graph on this domain, each said once: more
        than one ``simulators`` (gait_state writers), and ``command_writers`` (the nodes
        publishing effort_commands, one name per writer) that are not this run's controllers
        or name one of them twice."""
        said = []
        if simulators > 1 and 'simulators' not in self._clashes:
            self._clashes.add('simulators')
            said.append(f'{simulators} nodes publish gait_state on this ROS domain: another '
                        'simulator runs here, and controllers may answer both (give each '
                        'graph its own ROS_DOMAIN_ID)')
        counts = Counter(command_writers)
        ours = set(self.session.controllers)
        for name in sorted(counts):
            others = counts[name] - (name in ours)  # writers of that name besides the run's
            if others and name not in self._clashes:
                self._clashes.add(name)
                said.append(
                    f'{others} node(s) named {name[:64]!r} publish effort_commands on '
                    'this ROS domain' + (" besides the run's own" if name in ours else '')
                    + ("; commands without this run's token are refused"
                       if self._decoder.run_token else
                       "; their commands cannot be told from the run's own (a run started "
                       'by run_scene --ros gives its nodes a token that tells them apart)'))
        return said

    def publish_state(self, again: bool = False) -> None:
        """Publish the live state at t_k (``again``: the same t_k once more): the controllers'
        topics first; then, while they compute, the periods stepped are recorded (trajectory,
        bag) and the other topics go out."""
        self._publish_live(CONTROL_TOPICS)
        self.monitor.published(again)
        self.session.session.flush(whole=False)
        self._publish_live(STATE_TOPICS[len(CONTROL_TOPICS):])

    def _publish_live(self, topics: tuple[str, ...]) -> None:
        """Build and publish the state messages of the ``topics`` somebody listens to."""
        wanted = tuple(topic for topic in topics if self._listened(topic))
        if wanted:
            for topic, data in self.session.state_bytes(wanted).items():
                self._publish(topic, data)

    def step(self) -> None:
        """One period, then the next state out (``publish_state``); an error on the way (e.g.
        ``io_error``: the disk is full) ends the run with it, as a headless run ends."""
        start = time.perf_counter()
        try:
            self.session.step()
            self.monitor.samples['physics'].append(time.perf_counter() - start)
            self.budget = max(0, self.budget - 1)
            if not self.session.session.done:
                self.publish_state()
                return
        except SimulationError as exc:
            return self.finish(exc)
        self.finish()

    def take(self, data: bytes) -> str | None:
        """Take an EffortCommand (its CDR bytes); step once every source has answered t_k
        (lockstep), when the pace allows (``_step_on_pace``).

        :returns: why the command was rejected (None: taken, ignored while not running, or
            another run's command from a controller name already reported).
        """
        if self.phase != 'running':
            return None
        try:
            source, stamp_ns, command = self._decoder.decode(data)
            self.session.offer(source, stamp_ns, command)
        except ForeignCommand as exc:  # said once per name (a few names), every one counted
            self.monitor.reject(ForeignCommand.REASON)  # one reason, whatever names they forge
            if exc.source in self._foreign or len(self._foreign) >= FOREIGN_NAMES_SAID:
                return None
            self._foreign.add(exc.source)
            return f'rejected command: {exc} (ignored from now on, counted in metrics.json)'
        except EffortLimitExceeded as exc:  # the run's own controller: its law is broken
            self.monitor.reject(str(exc))
            self.finish(exc)
            return f'rejected command: {exc}; the run ends'
        except SimulationError as exc:
            self.monitor.reject(str(exc))
            return f'rejected command: {exc}'
        complete = self.session.lockstep and not self.session.missing()
        self.monitor.command(source, complete)
        if complete and self.may_step():
            self._step_on_pace()
        return None

    def _step_on_pace(self) -> None:
        """Lockstep, every command in: step now, or when the pace allows (waiting here up to
        one ``TICK``; later: the timer's ``tick`` steps)."""
        wait = self.monitor.clock.wait(self.session.sim.time
                                       + self.session.scene.simulator.control_period)
        if wait > TICK:
            return
        if wait > 0.0:
            time.sleep(wait)
        self.step()

    def tick(self) -> None:
        """Wall-clock timer: command timeout, resend of an unanswered state, a lockstep step the
        pace held back, the periods due of a run without controllers or free-running."""
        if not self.may_step():
            return
        s, m = self.session, self.monitor
        overdue = m.overdue(s.missing(), s.lockstep)
        if overdue:
            return self.finish(SimulationError(
                f'controller timeout at t={s.sim.time:.6f} s: no command from node(s) '
                f'{", ".join(map(repr, overdue))} within {m.timeout} s',
                end='controller_timeout'))
        if s.lockstep and s.missing() and m.resend_due():
            self.publish_state(again=True)
        if s.lockstep and s.controllers:
            if not s.missing():  # a step the pace held back
                self._step_on_pace()
            return
        # free-running: keep the pace (its batch: twice a timer period's worth, at most
        # FREE_BATCH); lockstep without controllers: nothing to wait for
        most = UNCONTROLLED_BATCH if s.lockstep else min(FREE_BATCH, max(
            10, math.ceil(2 * self.timer_period * self.pace / m.period)))
        for _ in range(m.due(s.sim.time, most)):
            if self.may_step():
                self.step()

    def finish(self, error: SimulationError | None = None) -> None:
        """End the run (outputs, bag, report, loop timings).

        The exit code: 0, 1 after an error, 128 + signum after a ``RunInterrupted``
        (``exit_code_of``).
        """
        run = self.session.session
        metrics = run.finish(error, {'rejected_commands': self.monitor.rejected_summary()})
        failed = run.error
        self.phase = 'finished'
        self.exit_code = DONE if failed is None else exit_code_of(failed)
        self._report(f'run over at t={metrics["sim_time_s"]:.6f} s: '
                     f'{metrics["failure"] or "complete"}', bool(self.exit_code))
        if self._stats_file is not None:
            self._stats_file.write_text(json.dumps(self.monitor.stats(
                run.periods, metrics['wall_time_s']), indent=1))

    def stop(self, signum: int | None = None, detail: str = '') -> None:
        """End a run that is not over yet: the node was stopped, by the signal ``signum``
        (a ``RunInterrupted``, ``detail`` added to its message) or otherwise."""
        if self.phase != 'finished':
            t = self.session.sim.time
            self.finish(RunInterrupted(signum, t, detail) if signum is not None
                        else SimulationError(f'stopped at t={t:.6f} s'))

    # ------------------------------------------------------------------------------ services
    def request_steps(self, periods: int) -> tuple[bool, int, str]:
        """Queue periods of a paused, running simulation: (accepted, stamp they reach [ns], text).

        The answer comes before the steps are taken (watch /clock for them).
        """
        ok = self.paused and self.phase == 'running' and periods >= 1
        total = self.budget + periods if ok else 0
        target = self.session.sim.time + total * self.session.scene.simulator.control_period
        text = (f'stepping to t={target:.6f} s' if ok else
                'step needs a paused, running simulation and control_periods >= 1')
        if ok:
            self.budget = total
            self._go_on()
        return ok, seconds_to_ns(target), text

    def _go_on(self) -> None:
        self.monitor.waiting_since = time.monotonic()  # the command timeout starts anew
        self.monitor.clock.restart()  # no catching up after a pause
        if self.session.lockstep and not self.session.missing() and self.may_step():
            self._step_on_pace()

    def pause(self) -> tuple[bool, str]:
        """Stop after the current period."""
        self.paused = True
        return True, 'paused'

    def resume(self) -> tuple[bool, str]:
        """Run on."""
        self.paused, self.budget = False, 0
        self._go_on()
        return True, 'running'

    def reset(self) -> tuple[bool, str]:
        """Back to the scene's initial state (refused while recording a bag)."""
        try:
            self.session.reset()
        except SimulationError as exc:
            return False, str(exc)
        self.phase, self.budget = 'running', 0
        self.monitor.clock.restart()
        self.publish_state()
        return True, 'reset to t=0'
