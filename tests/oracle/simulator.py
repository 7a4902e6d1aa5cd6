"""Test oracle: the hybrid simulation loop in Python (docs/model.md §6-§9), the readable
formulation the native periods (``iceskate_native.HybridSimulator``) are checked against.

``ReferenceSimulator.advance(command)`` integrates one control period with the input held
constant (zero-order hold), stopping at every located event to apply its transition (impacts,
re-rooting, coordinate changes) and going on in the new mode. After every period it checks the
state's health: non-finite values or constraint residuals beyond a bound raise
``SimulationError`` naming the time, mode and state; a fall, flight or toe-first touchdown ends
the run with a reason (``ended``) instead.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, replace
import math

import numpy as np
import pinocchio as pin

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import HeldCommand
from iceskate_sim.model.dynamics import ContactState, DynamicsResult
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import N_COORDINATES, SIDES, Robot
from iceskate_sim.model.stamps import ns_to_seconds, seconds_to_ns
from iceskate_sim.physics.hybrid import (
    Guard,
    HybridState,
    Transition,
    fall_reason,
    guards_of,
    resolved_cause,
)
from iceskate_sim.physics.integrators import GUARD_MARGIN, IntegratorConfig
from iceskate_sim.physics.simulation import RunStatistics, SimulatorConfig, StateQueries
from iceskate_sim.run.scene import Scene
from oracle.automaton import (
    RunEnded,
    apply_transition,
    guard_values,
    project_positions,
    rerooted_command,
    resolve_contact_mode,
)
from oracle.commands import ControllerCommand, held_of_controllers
from oracle.dynamics import GaitDynamics
from oracle.integrators import Integrator


class ReferenceSimulator(StateQueries):
    """The hybrid simulation loop in Python: the interface of
    ``iceskate_sim.physics.simulation.Simulator`` (``advance``, ``state``, ``events``,
    ``stats``, ``ended``, ``result``; and ``start_state``, ``start_result``) on the oracle's
    automaton and integrators and ``GaitDynamics``' eq. (7) (or the ``dynamics`` given, e.g.
    the native eq. (7) behind the same interface).
    """

    def __init__(self, robot: Robot, config: SimulatorConfig, initial: HybridState,
                 integrator: IntegratorConfig | None = None,
                 dynamics: GaitDynamics | None = None) -> None:
        self.robot = robot
        self.config = config
        params = replace(config.dynamics, mu=config.friction.mu)
        self.dynamics = dynamics if dynamics is not None else GaitDynamics(robot, params)
        self._initial = initial
        #: the integrator: the config's, or one the native simulator does not take (dop853)
        self.integrator = integrator or config.integrator
        self.reset()

    def reset(self) -> None:
        """Return to the initial state; clear the event log and the statistics."""
        self._command = HeldCommand.torque_only(np.zeros(N_COORDINATES))
        self._push: tuple[str, np.ndarray] | None = None
        self._head: tuple[HybridState | None, pin.SE3 | None] = (None, None)
        #: (start_state, start_result) of the last period (None before the first)
        self._start: tuple[HybridState, DynamicsResult] | None = None
        self.events: list[Transition] = []
        self.stats = RunStatistics()
        q, v = self._initial.q.copy(), self._initial.v.copy()
        self.state = replace(self._initial, q=q, v=v)
        if 'hy' in self.state.mode.constraints:  # a pinned heel is held where it stands
            heel = self.dynamics.frame_placement(self.state.contact, q, 'swing_heel')
            self.state = replace(self.state, contact=replace(
                self.state.contact, heel_anchor_y=float(heel.translation[1])))
        self.ended: str | None = None
        self._integrator = Integrator(self.integrator)
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
        self.state, self.ended = state, None
        self.result = self._evaluate(state.q, state.v)

    # -------------------------------------------------------------- accessors
    def observation(self) -> Observation:
        """The controllers' view of the current state, built here in Python from the state (the
        native core builds its own, ``HybridSimulator.observation``): times rounded to whole
        nanoseconds, the pivot 'toe' while the sole is flat (copies of q and v)."""
        s = self.state

        def stamped(t: float) -> float:
            return ns_to_seconds(seconds_to_ns(t)) if math.isfinite(t) else t

        pivot = s.contact.pivot if s.mode.q1_active else 'toe'
        return Observation(stamped(s.t), s.q.copy(), s.v.copy(), s.mode.number, s.contact.side,
                           pivot, s.step_index, stamped(s.t_exchange), s.contact.heel_anchor_y,
                           stamped(s.t_touchdown))

    @property
    def command(self) -> HeldCommand:
        """The input held over the last period (zero torque before the first), in the
        coordinates of the current support foot."""
        return self._command

    def head_placement(self) -> pin.SE3:
        """World placement of the head-top frame in the current state (kept until the state
        changes)."""
        if self._head[0] is not self.state:
            self._head = (self.state, self.dynamics.frame_placement(
                self.state.contact, self.state.q, 'head_top'))
        return self._head[1]

    @property
    def start_state(self) -> HybridState:
        """The state at the start of the last period, after the transitions due then."""
        return self._start[0]

    @property
    def start_result(self) -> DynamicsResult:
        """The dynamics at ``start_state`` under the last period's input."""
        return self._start[1]

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
        """``Simulator.advance`` in Python: one control period holding ``command`` (and
        ``push``); returns the dynamics at its end."""
        self._require_running()
        if not isinstance(command, HeldCommand):
            command = HeldCommand.torque_only(command)
        self._command = command
        self._push = None if push is None else (push[0], np.asarray(push[1], dtype=float))
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
            if self.config.integrator.projection and self.state.mode.constraints:
                residuals = self._project()
            self._check_health(residuals)
        except RunEnded as end:
            self._check_speed(end.state)  # a blow-up is not a physical end
            self.ended = end.reason
            self.state = end.state
        self.stats.control_periods += 1
        return self.result

    def _require_running(self) -> None:
        """:raises SimulationError: once the run has ended (no further period)."""
        if self.ended is not None:
            raise SimulationError(f'the run ended at t={self.state.t:.6f} s in mode '
                                  f'{self.state.mode.number} ({self.ended}); no further '
                                  'period can be simulated')

    def _transition(self, guard: object) -> None:
        t = self.state.t
        if not abs(t - self._instant[0]) <= self.integrator.event_tolerance * 10:
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
        if self.head_placement().translation[2] < self.config.fall_height:
            raise RunEnded(fall_reason(self.config.fall_height), s)

    def _diverged(self, what: str, state: HybridState) -> None:
        raise SimulationError(f'simulation diverged ({what}) at {state.summary()}')


@dataclass
class ReferenceRun:
    """A whole run on the oracle: its simulator (events, stats, end) and, per control period,
    the state it started from (after the transitions due then), as a session's trajectory
    holds it (``q``, ``v`` (periods, 18); ``mode``, ``side`` (periods,), side 0 right)."""

    sim: ReferenceSimulator
    q: np.ndarray
    v: np.ndarray
    mode: np.ndarray
    side: np.ndarray


def run_reference(scene: Scene, robot: Robot,
                  commands: Callable[[Observation], Mapping[str, ControllerCommand]],
                  integrator: IntegratorConfig | None = None) -> ReferenceRun:
    """Run ``scene`` on the oracle with ``commands(observation)`` answering every control
    instant (e.g. ``oracle.commands.stack_commands``), the scene's pushes held as the native loop
    holds them; stops at the scene's duration or the run's end.

    :raises SimulationError: where the physics failed.
    """
    sim = ReferenceSimulator(robot, scene.simulator, scene.initial, integrator)
    rows: list[tuple[np.ndarray, np.ndarray, int, int]] = []
    for _ in range(int(round(scene.duration / scene.simulator.control_period))):
        if sim.ended is not None:
            break
        t = sim.state.t
        push = next(((p.frame, np.array(p.force)) for p in scene.pushes if p.active(t)), None)
        sim.advance(held_of_controllers(commands(sim.observation()).values()), push)
        start = sim.start_state
        rows.append((start.q, start.v, start.mode.number, SIDES.index(start.contact.side)))
    q, v, mode, side = (np.array(column) for column in zip(*rows, strict=True))
    return ReferenceRun(sim, q, v, mode, side)


@dataclass
class ReferenceSample:
    """What the native loop records at one control instant t_k, from the oracle.

    :param state: hybrid state at t_k.
    :param result: dynamics at t_k under the inputs held over [t_k, t_k+1].
    :param efforts: input torque of each source over [t_k, t_k+1] (18-vectors, N m).
    :param head_position: head-top world position (3,) [m]; ``head_rotation`` (3x3).
    :param last_transition: the latest transition of the event log (None: none yet).
    """

    state: HybridState
    result: DynamicsResult
    efforts: dict[str, np.ndarray]
    head_position: np.ndarray
    head_rotation: np.ndarray
    last_transition: Transition | None


def reference_samples(scene: Scene, robot: Robot,
                      commands: Callable[[Observation], Mapping[str, ControllerCommand]],
                      periods: int) -> list[ReferenceSample]:
    """The samples of the first ``periods`` control periods of ``scene`` on the oracle, as the
    native loop records them: the state at t_k after the transitions due then, the dynamics
    under the held commands, each source's effort as its controller reported it, the push's
    generalized force, the head pose at t_k and the latest transition."""
    sim = ReferenceSimulator(robot, scene.simulator, scene.initial)
    samples = []
    for _ in range(periods):
        t = sim.state.t
        placement = sim.head_placement()
        push = next(((p.frame, np.array(p.force)) for p in scene.pushes if p.active(t)), None)
        answers = commands(sim.observation())
        sim.advance(held_of_controllers(answers.values()), push)
        state = sim.start_state
        efforts = {source: tau for c in answers.values()
                   for source, tau in c.source_efforts.items()}
        if push is not None:
            efforts['push'] = sim.dynamics.push_force(state.contact, state.q, push)
        last = next((e for e in reversed(sim.events) if e.t <= state.t), None)
        samples.append(ReferenceSample(state, sim.start_result, efforts,
                                       placement.translation.copy(), placement.rotation.copy(),
                                       last))
    return samples
