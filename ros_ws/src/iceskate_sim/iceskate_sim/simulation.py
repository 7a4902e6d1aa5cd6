"""The hybrid simulation loop: per-mode dynamics, event-locating integration, transitions.

``Simulator.advance(tau)`` integrates one control period with the input held constant (zero
order hold), stopping at every located event to apply its transition (impacts, re-rooting,
coordinate changes) and going on in the new mode. After every period it checks the state's
health: non-finite values or constraint residuals beyond a bound raise ``SimulationError``
naming the time, mode and state; a fall, flight or toe-first touchdown ends the run with a
reason (``Simulator.ended``) instead.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
import math
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from iceskate_sim.command import HeldCommand
from iceskate_sim.dynamics import ContactState, DynamicsParameters, DynamicsResult, GaitDynamics
from iceskate_sim.errors import SimulationError
from iceskate_sim.hybrid import (
    FrictionModel,
    Guard,
    HybridState,
    RunEnded,
    Transition,
    apply_transition,
    fall_reason,
    guard_values,
    guards_of,
    project_positions,
    rerooted_command,
    resolve_contact_mode,
    resolved_cause,
)
from iceskate_sim.integrators import (
    FIXED_STEP,
    GUARD_MARGIN,
    NATIVE_PERIODS,
    Integrator,
    IntegratorConfig,
)
from iceskate_sim.observation import Observation
from iceskate_sim.robot import N_COORDINATES, Robot
from iceskate_sim.ros_conversions import ns_to_seconds, seconds_to_ns

if TYPE_CHECKING:
    from iceskate_sim.native_dynamics import NativeControlLoop

#: Where the physics runs (``SimulatorConfig.engine``).
ENGINES = ('python', 'native')


def stamp_time(t: float) -> float:
    """Time t [s] at a stamp's resolution (whole nanoseconds)."""
    return ns_to_seconds(seconds_to_ns(t))


def observation_of(s: HybridState) -> Observation:
    """The controller's view of a hybrid state (copies of q and v).

    It holds what a GaitState message carries, so a controller computes the same torque
    in-process as from the message: times rounded to whole nanoseconds (a ROS stamp's
    resolution), and the pivot 'toe' while the sole is flat (q1 locked: no pivot is sent, and
    the kinematics rooted at either edge agree up to rounding).
    """
    touchdown = stamp_time(s.t_touchdown) if math.isfinite(s.t_touchdown) else s.t_touchdown
    pivot = s.contact.pivot if s.mode.q1_active else 'toe'
    return Observation(stamp_time(s.t), s.q.copy(), s.v.copy(), s.mode.number, s.contact.side,
                       pivot, s.step_index, stamp_time(s.t_exchange), s.contact.heel_anchor_y,
                       touchdown)


@dataclass(frozen=True)
class SimulatorConfig:
    """Settings of a simulation run.

    :param control_period: period of the zero-order-hold inputs [s]; an integer multiple of
        the fixed step for fixed-step integrators.
    :param integrator: the integrator and its tolerances.
    :param friction: floor friction rule and coefficient.
    :param dynamics: joint damping, soft stops, Baumgarte constant (its mu is replaced by the
        friction model's).
    :param projection: project positions and velocities onto the active swing constraints
        after every control period (drift control).
    :param residual_bound: constraint residual [m or rad] beyond which the run fails.
    :param fall_height: head-top height [m] below which the robot has fallen (run ends).
    :param max_speed: largest coordinate speed [rad/s, m/s] a physical run can reach; beyond
        it the integration has diverged (SimulationError), even if no value is non-finite.
    :param max_instant_transitions: transitions allowed at one instant before the run is
        declared chattering.
    :param zeno_window: transitions fired within this time [s] of each other count as one
        burst; a burst of more than ``max_instant_transitions`` (a Zeno sequence, whose events
        come ever closer without reaching one instant) rests the firing guard for
        ``chatter_dwell``.
    :param chatter_dwell: when a transition would bring back a (mode, side) already visited at
        the same instant (a Zeno cycle of complementary guards, e.g. flat <-> edge in a closed
        double-support chain), it is not applied and its guard is suppressed for this long
        [s]; every such case is counted in ``stats.suppressed_cycles``.
    :param engine: where the physics runs: 'native' (the C++ kernel: eq. (7) by
        ``NativeGaitDynamics``, and whole control periods by ``NativePeriods`` with a fixed-step
        method or rk45) or 'python' (the readable reference, ``GaitDynamics`` and this class's
        loop).
    """

    control_period: float = 1.0e-3
    integrator: IntegratorConfig = field(default_factory=IntegratorConfig)
    friction: FrictionModel = field(default_factory=FrictionModel)
    dynamics: DynamicsParameters = field(default_factory=DynamicsParameters)
    projection: bool = True
    residual_bound: float = 1.0e-3
    fall_height: float = 1.2
    max_speed: float = 200.0
    max_instant_transitions: int = 20
    zeno_window: float = 1.0e-6
    chatter_dwell: float = 0.005
    engine: str = 'native'

    def __post_init__(self) -> None:
        """Check the engine, and the control period against the integrator step."""
        if self.engine not in ENGINES:
            raise SimulationError(f'engine must be one of {list(ENGINES)}, got {self.engine!r}')
        if not (np.isfinite(self.control_period) and self.control_period > 0.0):
            raise SimulationError(f'control_period must be > 0 s, got {self.control_period!r}')
        if self.integrator.method in FIXED_STEP:
            ratio = self.control_period / self.integrator.step
            if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
                raise SimulationError(
                    f'control_period {self.control_period} s is not an integer multiple of '
                    f'the {self.integrator.method} step {self.integrator.step} s')


@dataclass
class RunStatistics:
    """Counters of a run."""

    steps: int = 0
    evaluations: int = 0
    control_periods: int = 0
    max_constraint_residual: float = 0.0  # of the states the periods end in [m, rad]
    max_constraint_drift: float = 0.0  # a period leaves before its projection [m, rad]
    suppressed_cycles: int = 0
    resolved_cycles: int = 0


class Simulator:
    """A hybrid simulation of the humanoid from an initial state."""

    def __init__(self, robot: Robot, config: SimulatorConfig, initial: HybridState) -> None:
        self.robot = robot
        self.config = config
        params = replace(config.dynamics, mu=config.friction.mu)
        #: whole periods run natively (native engine, fixed-step method), else in Python
        self._periods = None
        if config.engine == 'native':
            from iceskate_sim.native_dynamics import NativeGaitDynamics, NativePeriods
            self.dynamics: GaitDynamics = NativeGaitDynamics(robot, params)
            if config.integrator.method in NATIVE_PERIODS:
                self._periods = NativePeriods(
                    self.dynamics, initial, control_period=config.control_period,
                    integrator=config.integrator, friction=config.friction,
                    projection=config.projection, residual_bound=config.residual_bound,
                    fall_height=config.fall_height, max_speed=config.max_speed,
                    max_instant_transitions=config.max_instant_transitions,
                    zeno_window=config.zeno_window, chatter_dwell=config.chatter_dwell)
        else:
            self.dynamics = GaitDynamics(robot, params)
        self._initial = initial
        self._integrator = Integrator(config.integrator)
        self.reset()

    def reset(self) -> None:
        """Return to the initial state; clear the event log and the statistics."""
        self._command = HeldCommand.torque_only(np.zeros(N_COORDINATES))
        self._push: tuple[str, np.ndarray] | None = None
        self._head: tuple[HybridState | None, pin.SE3 | None] = (None, None)
        self._result: DynamicsResult | None = None
        #: (start_state, start_result) of the last period (None: not mirrored yet)
        self._start: tuple[HybridState, DynamicsResult] | None = None
        self.events: list[Transition] = []
        self.stats = RunStatistics()
        if self._periods is not None:
            self._periods.reset()
            self._mirror_periods()
            return
        q, v = self._initial.q.copy(), self._initial.v.copy()
        self.state = replace(self._initial, q=q, v=v)
        if 'hy' in self.state.mode.constraints:  # a pinned heel is held where it stands
            heel = self.dynamics.frame_placement(self.state.contact, q, 'swing_heel')
            self.state = replace(self.state, contact=replace(
                self.state.contact, heel_anchor_y=float(heel.translation[1])))
        self.ended: str | None = None
        self._integrator = Integrator(self.config.integrator)
        self._suppressed: dict[str, float] = {}
        self._instant: tuple[float, set[tuple[int, str]]] = (float('nan'), set())
        self.result = self._evaluate(self.state.q, self.state.v)
        try:
            self._settle()
        except RunEnded as end:
            self.ended = end.reason
            self.state = end.state

    def set_state(self, state: HybridState) -> None:
        """Continue from ``state`` (the event log, counters and rested guards kept; a run that
        had ended goes on), as after a period that ended there under the current command."""
        if self._periods is not None:
            self._periods.set_state(state)
            self._mirror_periods()
            return
        self.state, self.ended = state, None
        self.result = self._evaluate(state.q, state.v)

    # -------------------------------------------------------------- accessors
    @property
    def command(self) -> HeldCommand:
        """The input held over the last period (zero torque before the first), in the
        coordinates of the current support foot."""
        return self._command

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return self.state.t

    def observation(self) -> Observation:
        """The controller's view of the current state."""
        return observation_of(self.state)

    def head_height(self) -> float:
        """Height of the head top [m]."""
        return float(self.head_placement().translation[2])

    def head_placement(self) -> pin.SE3:
        """World placement of the head-top frame in the current state (kept until the state
        changes: the health check and the next sample ask for the same one)."""
        if self._head[0] is not self.state:
            self._head = (self.state, self.dynamics.frame_placement(
                self.state.contact, self.state.q, 'head_top'))
        return self._head[1]

    # ---------------------------------------------------------------- stepping
    def _evaluate(self, q: np.ndarray, v: np.ndarray) -> DynamicsResult:
        c = self._command
        return self.dynamics.evaluate(self.state.contact, q, v, c.bias, self._push, c.stiffness,
                                      c.damping)

    def _rhs(self, t: float, x: np.ndarray, implicit_step: float = 0.0,
             ) -> tuple[np.ndarray, DynamicsResult | None]:
        """(xdot, dynamics) at x; with ``implicit_step`` h > 0 the accelerations of an implicit
        step of size h, without the rest of the dynamics (None)."""
        n = N_COORDINATES
        c = self._command
        if implicit_step > 0.0:
            qdd = self.dynamics.implicit_acceleration(self._contact, x[:n], x[n:], c.bias,
                                                      self._push, c.stiffness, c.damping,
                                                      implicit_step)
            return np.concatenate([x[n:], qdd]), None
        result = self.dynamics.evaluate(self._contact, x[:n], x[n:], c.bias, self._push,
                                        c.stiffness, c.damping)
        return np.concatenate([x[n:], result.qdd]), result

    def _guards(self, t: float, x: np.ndarray, result: DynamicsResult) -> np.ndarray:
        n = N_COORDINATES
        return self._masked(HybridState(t, x[:n], x[n:], self._contact), result)

    def _masked(self, state: HybridState, result: DynamicsResult) -> np.ndarray:
        """Guard values with the suppressed guards held at -1 (not due)."""
        values = guard_values(state, result, self.config.friction)
        if self._suppressed:
            for i, guard in enumerate(guards_of(state.mode)):
                if self._suppressed.get(guard.name, -np.inf) > state.t:
                    values[i] = -1.0
        return values

    def advance(self, command: HeldCommand | np.ndarray,
                push: tuple[str, np.ndarray] | None = None) -> DynamicsResult:
        """Integrate one control period holding the input command (zero-order hold).

        :param command: a HeldCommand (feed-forward plus joint impedance, evaluated at every
            physics step) or a plain torque vector (18,) held constant.
        :param push: optional external force (link frame, world force [N]) held over the
            period.

        :returns: the dynamics at the end of the period (accelerations, multipliers, ...).
        :raises SimulationError: on bad input or divergence. A run that ends physically
            (fall, flight, toe-first touchdown) sets ``ended`` and stops advancing.
        """
        self._require_running()
        if not isinstance(command, HeldCommand):
            tau = np.asarray(command, dtype=float)
            if tau.shape != (N_COORDINATES,) or not np.all(np.isfinite(tau)):
                raise SimulationError(f'input torque must be {N_COORDINATES} finite values '
                                      f'[y0, q1..q17], got shape {tau.shape}')
            command = HeldCommand.torque_only(tau)
        self._command = command
        self._push = None if push is None else (push[0], np.asarray(push[1], dtype=float))
        if self._periods is not None:
            side, first = self.state.contact.side, len(self.events)
            try:
                self._periods.advance(command, self._push)
            finally:
                self._mirror_periods()
                for event in self.events[first:]:  # the native periods re-root it likewise
                    if event.side != side:
                        self._command, side = rerooted_command(self._command), event.side
            return self.result
        self.result = self._evaluate(self.state.q, self.state.v)
        self._start = (self.state, self.result)
        t_end = self.state.t + self.config.control_period
        n = N_COORDINATES
        instant, at_instant = self.state.t, 0
        try:
            self._settle()  # a guard the new command makes due fires at the period start
            self._start = (self.state, self.result)
            while t_end - self.state.t > 1e-12:
                self._contact = self.state.contact
                x0 = np.concatenate([self.state.q, self.state.v])
                start = (np.concatenate([self.state.v, self.result.qdd]), self.result)
                try:
                    seg = self._integrator.integrate_segment(self._rhs, self._guards,
                                                             self.state.t, x0, t_end, start)
                except SimulationError as exc:
                    raise SimulationError(f'{exc} (during the period from '
                                          f'{self.state.summary()})') from exc
                self.stats.steps += seg.steps
                self.stats.evaluations += seg.evaluations
                if not np.isfinite(seg.x).all():
                    self._diverged('non-finite state', replace(self.state, t=seg.t))
                self.state = replace(self.state, t=seg.t, q=seg.x[:n].copy(),
                                     v=seg.x[n:].copy())
                self.result = seg.result
                if seg.fired is not None:
                    guard = guards_of(self.state.mode)[seg.fired]
                    if seg.t - instant > self.config.zeno_window:
                        instant, at_instant = seg.t, 0
                    at_instant += 1
                    if at_instant > self.config.max_instant_transitions:
                        # a Zeno burst (events ever closer, e.g. stick <-> slip at a heel at
                        # rest): rest the firing guard, the last resort
                        self._rest(guard)
                        instant, at_instant = seg.t, 0
                        continue
                    self._transition(guard)
                    self._settle()
            residuals = None
            if self.config.projection and self.state.mode.constraints:
                residuals = self._project()
            self._check_health(residuals)
        except RunEnded as end:
            self._check_speed(end.state)  # a blow-up is not a physical end
            self.ended = end.reason
            self.state = end.state
        self.stats.control_periods += 1
        return self.result

    def control_loop(self, kinematics: object, controllers: list, pushes: tuple,
                     head_origin: np.ndarray, inbox: tuple[tuple[str, ...], ...] = ()
                     ) -> NativeControlLoop | None:
        """The native loop of many control periods on this simulator (see
        ``NativeControlLoop``; advance it with ``run_loop`` or, for the commands of its
        ``inbox``, ``hold_period``), or None where periods do not run natively (the Python
        engine, dop853)."""
        if self._periods is None:
            return None
        from iceskate_sim.native_dynamics import NativeControlLoop
        return NativeControlLoop(self._periods, kinematics, controllers, pushes, head_origin,
                                 inbox)

    def _require_running(self) -> None:
        """:raises SimulationError: once the run has ended (no further period)."""
        if self.ended is not None:
            raise SimulationError(f'the run ended at t={self.state.t:.6f} s in mode '
                                  f'{self.state.mode.number} ({self.ended}); no further '
                                  'period can be simulated')

    def hold_period(self, loop: NativeControlLoop, clear: bool = True) -> None:
        """One control period of ``loop`` holding the commands it received
        (``NativeControlLoop.hold``; the sample stays in its block), then this simulator
        mirrors the native state, events, counters and end (the dynamics when asked).

        :raises SimulationError: where the physics failed, as ``advance``.
        """
        self._require_running()
        try:
            loop.hold(clear)
        finally:
            self._mirror_periods()

    def run_loop(self, loop: NativeControlLoop, periods: int) -> tuple[dict, Exception | None]:
        """Up to ``periods`` control periods of ``loop`` (``NativeControlLoop.run``: the samples
        and what stopped the block early), then this simulator mirrors the native state, events,
        counters and end."""
        self._require_running()
        try:
            block, error = loop.run(periods)
        finally:
            self._mirror_periods()
        return block, error

    # the dynamics of the native periods are mirrored when asked (a lockstep period needs none)
    @property
    def result(self) -> DynamicsResult:
        """The dynamics at the current state under the last input."""
        if self._result is None:
            self._result = self._periods.result()
        return self._result

    @result.setter
    def result(self, value: DynamicsResult) -> None:
        self._result = value

    @property
    def start_state(self) -> HybridState:
        """The state at the start of the last period, after the transitions due then."""
        if self._start is None:
            self._start = self._periods.start()
        return self._start[0]

    @property
    def start_result(self) -> DynamicsResult:
        """The dynamics at ``start_state`` under the last period's input."""
        if self._start is None:
            self._start = self._periods.start()
        return self._start[1]

    def _mirror_periods(self) -> None:
        """Take the state, new events, counters and end of the native periods (their dynamics
        when asked: ``result``, ``start_state``, ``start_result``)."""
        periods = self._periods
        self.state = periods.state()
        self._result = self._start = None
        self.events.extend(periods.events_since(len(self.events)))
        s = self.stats
        (s.steps, s.evaluations, s.control_periods, s.max_constraint_residual,
         s.max_constraint_drift, s.suppressed_cycles, s.resolved_cycles) = periods.statistics()
        self.ended = periods.ended()

    def _transition(self, guard: object) -> None:
        t = self.state.t
        if not abs(t - self._instant[0]) <= self.config.integrator.event_tolerance * 10:
            self._instant = (t, {(self.state.mode.number, self.state.contact.side)})
        new, record = apply_transition(self.dynamics, self.config.friction, self.state,
                                       guard, self.result)
        key = (new.mode.number, new.contact.side)
        if key in self._instant[1]:  # a cycle of single switches: solve for a consistent mode
            self._resolve(guard)
            return
        self._instant[1].add(key)
        self.events.append(record)
        if new.contact.side != self.state.contact.side:
            self._command = rerooted_command(self._command)
        self.state = new
        self.result = self._evaluate(new.q, new.v)

    def _resolve(self, guard: Guard) -> None:
        """Replace a same-instant cycle by the contact-consistent mode, if there is one;
        otherwise rest the cycling guard for ``chatter_dwell``."""
        def evaluate(contact: ContactState, q: np.ndarray, v: np.ndarray) -> DynamicsResult:
            c = self._command
            return self.dynamics.evaluate(contact, q, v, c.bias, self._push, c.stiffness,
                                          c.damping)
        found = resolve_contact_mode(self.dynamics, self.config.friction, self.state, evaluate)
        if found is None or found[0].contact == self.state.contact:
            self._rest(guard)
            return
        new, result = found
        self.stats.resolved_cycles += 1
        self.events.append(Transition(self.state.t, self.state.mode.number, new.mode.number,
                                      'R', resolved_cause(guard.name), (), new.step_index,
                                      new.contact.side))
        self._instant[1].add((new.mode.number, new.contact.side))
        self.state = new
        self.result = result

    def _rest(self, guard: Guard) -> None:
        """Suppress ``guard`` for ``chatter_dwell`` from now (counted in the stats)."""
        self._suppressed[guard.name] = self.state.t + self.config.chatter_dwell
        self.stats.suppressed_cycles += 1

    def _settle(self) -> None:
        """Apply transitions that are due at once (cascade), with a chattering limit."""
        for _ in range(self.config.max_instant_transitions):
            values = self._masked(self.state, self.result)
            due = np.flatnonzero(values > GUARD_MARGIN)
            if not due.size:
                return
            self._transition(guards_of(self.state.mode)[due[0]])
        self._chattering()

    def _chattering(self) -> None:
        raise SimulationError(f'chattering: more than {self.config.max_instant_transitions} '
                              f'transitions at one instant ({self.state.summary()}); last '
                              f'events {[e.event for e in self.events[-6:]]}')

    def _project(self) -> tuple[np.ndarray, np.ndarray] | None:
        """Project q onto the active swing constraints and v onto their tangent space.

        :returns: the residuals (C, J qd) of the state when it needed no correction (the state
            is then unchanged), else None.
        """
        s = self.state
        C, Cdot = self.dynamics.constraint_residuals(s.contact, s.q, s.v)
        residual = float(np.max(np.abs(C)))
        self.stats.max_constraint_drift = max(self.stats.max_constraint_drift, residual)
        if residual < 1e-12 and float(np.max(np.abs(Cdot))) < 1e-12:
            return C, Cdot  # nothing to correct (the profile showed 27 % of a run spent here)
        q, _ = project_positions(self.dynamics, s.contact, s.q)
        act = s.mode.active
        J = self.dynamics.constraint_jacobian(s.contact, q)[:, act]
        M = self.dynamics.mass_matrix(s.contact, q)
        v = s.v.copy()
        minv_jt = np.linalg.solve(M, J.T)
        v[act] -= minv_jt @ np.linalg.solve(J @ minv_jt, J @ v[act])
        self.state = replace(s, q=q, v=v)
        self.result = self._evaluate(q, v)
        return None

    def _check_speed(self, state: HybridState) -> None:
        speed = float(np.max(np.abs(state.v)))
        if not speed <= self.config.max_speed:
            self._diverged(f'speed {speed:.3g} beyond {self.config.max_speed:g} rad/s or m/s',
                           state)

    def _check_health(self, residuals: tuple[np.ndarray, np.ndarray] | None = None) -> None:
        """Non-finite values, speed, constraint residual (``residuals``: C and J qd of the
        current state if known) and fall height of the current state."""
        s = self.state
        if not (np.isfinite(s.q).all() and np.isfinite(s.v).all()):
            self._diverged('non-finite state', s)
        self._check_speed(s)
        if s.mode.constraints:
            C, _ = residuals or self.dynamics.constraint_residuals(s.contact, s.q, s.v)
            worst = float(np.max(np.abs(C)))
            self.stats.max_constraint_residual = max(self.stats.max_constraint_residual, worst)
            self.stats.max_constraint_drift = max(self.stats.max_constraint_drift, worst)
            if worst > self.config.residual_bound:
                self._diverged(f'constraint residual {worst:.3g} beyond '
                               f'{self.config.residual_bound:g}', s)
        if self.head_height() < self.config.fall_height:
            raise RunEnded(fall_reason(self.config.fall_height), s)

    def _diverged(self, what: str, state: HybridState) -> None:
        raise SimulationError(f'simulation diverged ({what}) at {state.summary()}')


def initial_state(q: np.ndarray, mode: int, side: str = 'right', pivot: str = 'toe',
                  v: np.ndarray | None = None, t: float = 0.0) -> HybridState:
    """A HybridState at rest (or with velocity ``v``) in Table 2 ``mode``."""
    from iceskate_sim.modes import get_mode
    gait_mode = get_mode(mode)
    q = np.asarray(q, dtype=float).copy()
    v = np.zeros(N_COORDINATES) if v is None else np.asarray(v, dtype=float).copy()
    if q.shape != (N_COORDINATES,) or v.shape != (N_COORDINATES,):
        raise SimulationError(f'initial q and v need {N_COORDINATES} entries')
    contact = ContactState(gait_mode, side, pivot)
    touchdown = t if gait_mode.swing != 'A' else float('nan')  # a foot already down counts
    return HybridState(t, q, v, contact, t_touchdown=touchdown)
