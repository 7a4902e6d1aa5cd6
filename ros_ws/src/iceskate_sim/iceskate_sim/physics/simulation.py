"""The hybrid simulation seen from Python: ``Simulator``, a facade over the native simulator.

``advance`` integrates one control period with the input held (zero-order hold); many periods
with the controllers run as one call of the native control loop (``control_loop``,
``run_loop``, ``hold_period``). Divergence raises ``SimulationError`` naming the time, mode and
state; a fall, flight or toe-first touchdown ends the run (``Simulator.ended``).
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

import iceskate_native
from iceskate_sim.errors import InputRefused, SimulationError
from iceskate_sim.model.command import CommandValues, HeldCommand
from iceskate_sim.model.dynamics import (
    ContactState,
    DynamicsParameters,
    DynamicsResult,
    ModelTerms,
)
from iceskate_sim.model.modes import MODES, get_mode
from iceskate_sim.model.observation import Observation
from iceskate_sim.model.robot import N_COORDINATES, PIVOTS, SIDES, Robot
from iceskate_sim.physics.hybrid import (
    CAUSES,
    FLIGHT,
    TOE_FIRST,
    FrictionModel,
    HybridState,
    Transition,
    fall_reason,
    guards_of,
    resolved_cause,
)
from iceskate_sim.physics.integrators import FIXED_STEP, GUARD_MARGIN, IntegratorConfig
from iceskate_sim.physics.native import GUARD_CONSTANTS, NativeGaitDynamics


@dataclass(frozen=True)
class SimulatorConfig:
    """Settings of a simulation run.

    :param control_period: period of the zero-order-hold inputs [s]; an integer multiple of
        the fixed step for fixed-step integrators.
    :param integrator: the integrator and its tolerances.
    :param friction: floor friction rule and coefficient.
    :param dynamics: joint damping, soft stops, Baumgarte constant (its mu is replaced by the
        friction model's).
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
    """

    control_period: float = 1.0e-3
    integrator: IntegratorConfig = field(default_factory=IntegratorConfig)
    friction: FrictionModel = field(default_factory=FrictionModel)
    dynamics: DynamicsParameters = field(default_factory=DynamicsParameters)
    residual_bound: float = 1.0e-3
    fall_height: float = 1.2
    max_speed: float = 200.0
    max_instant_transitions: int = 20
    zeno_window: float = 1.0e-6
    chatter_dwell: float = 0.005

    def __post_init__(self) -> None:
        """Check the control period against the integrator step."""
        if not (np.isfinite(self.control_period) and self.control_period > 0.0):
            raise InputRefused(f'control_period must be > 0 s, got {self.control_period!r}')
        if self.integrator.method in FIXED_STEP:
            ratio = self.control_period / self.integrator.step
            if abs(ratio - round(ratio)) > 1e-9 * ratio or round(ratio) < 1:
                raise InputRefused(
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


class StateQueries:
    """What a simulator answers about its current ``state``: the time."""

    state: HybridState
    dynamics: ModelTerms

    @property
    def time(self) -> float:
        """Simulation time [s]."""
        return self.state.t


#: Guard causes for the event log, by name.


def _hybrid_state(state: dict) -> HybridState:
    """The kernel's state (``HybridSimulator.state``: HybridState's fields by name, the
    contact's flattened) as a HybridState."""
    contact = ContactState(MODES[state['mode']], SIDES[state['side']], PIVOTS[state['pivot']],
                           state['heel_anchor_y'], state['support_slide_dir'],
                           state['heel_slide_dir'])
    return HybridState(state['t'], state['q'], state['v'], contact, state['step_index'],
                       state['t_exchange'], state['t_touchdown'])


class Simulator(StateQueries):
    """A hybrid simulation of the humanoid from an initial state: a facade over ``kernel``, the
    native ``iceskate_native.HybridSimulator``, whose state, new events, counters and end it
    mirrors after every call (the dynamics only when asked).

    :param robot: the robot model. :param config: the run's settings.
    :param initial: the initial state.
    :raises InputRefused: for settings or an initial state the kernel refuses.
    """

    def __init__(self, robot: Robot, config: SimulatorConfig, initial: HybridState) -> None:
        self.robot = robot
        self.config = config
        self.dynamics = NativeGaitDynamics(robot, replace(config.dynamics, mu=config.friction.mu))
        self._fall = fall_reason(config.fall_height)
        guards = [[g.name for g in guards_of(MODES[n])] for n in sorted(MODES)]
        try:
            self.kernel = iceskate_native.HybridSimulator(
                self.dynamics.kernel, initial, config, GUARD_CONSTANTS, GUARD_MARGIN, guards)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise InputRefused(f'native simulator: {exc} (initial state: '
                               f'{initial.summary()})') from None
        self.reset()

    def reset(self) -> None:
        """Return to the initial state; clear the event log and the statistics."""
        self.events: list[Transition] = []
        self.stats = RunStatistics()
        try:
            self.kernel.reset()
        except iceskate_native.NativeError as exc:
            raise SimulationError(f'native simulator: {exc} (initial state)') from None
        self._mirror()

    def set_state(self, state: HybridState) -> None:
        """Continue from ``state`` (the event log, counters and rested guards kept; a run that
        had ended goes on), as after a period that ended there under the current command."""
        try:
            self.kernel.set_state(state)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'native simulator: {exc} ({state.summary()})') from None
        self._mirror()

    @property
    def result(self) -> DynamicsResult:
        """The dynamics at the current state under the last input."""
        return DynamicsResult(*self.kernel.result)

    def observation(self) -> Observation:
        """The controllers' view of the current state, as the native loop gives it to them
        (``HybridSimulator.observation``): what a GaitState message carries, times at whole
        nanoseconds and the pivot 'toe' while the sole is flat."""
        return Observation.of_native(self.kernel.observation())

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
            command = HeldCommand.torque_only(command)
        try:
            self.kernel.advance(command.bias, command.stiffness, command.damping,
                                 '' if push is None else push[0],
                                 None if push is None else np.asarray(push[1], dtype=float))
        except (iceskate_native.NativeError, ValueError, TypeError) as exc:
            raise self.failure(exc) from None
        finally:
            self._mirror()
        return self.result

    def control_loop(self, kinematics: iceskate_native.Kinematics | None,
                     controllers: list[iceskate_native.Controller], pushes: tuple,
                     head_origin: np.ndarray, inbox: tuple[tuple[str, ...], ...] = (),
                     ) -> NativeControlLoop:
        """The native loop of many control periods on this simulator (see
        ``NativeControlLoop``; advance it with ``run_loop`` or, for the commands of its
        ``inbox``, ``hold_period``)."""
        return NativeControlLoop(self, kinematics, controllers, pushes, head_origin, inbox)

    def hold_period(self, loop: NativeControlLoop, clear: bool = True) -> None:
        """One control period of ``loop`` holding the commands it received
        (``iceskate_native.ControlLoop.hold``: the sample stays in its block; ``clear``: forget
        the commands afterwards), then mirror the kernel.

        :raises SimulationError: where the physics failed, as ``advance``.
        """
        self._require_running()
        try:
            if not loop.kernel.hold(clear):
                try:
                    loop.kernel.raise_error()
                except Exception as exc:  # noqa: BLE001 - the kernel's failure, in our words
                    raise self.failure(exc) from None
        finally:
            self._mirror()

    def run_loop(self, loop: NativeControlLoop, periods: int) -> tuple[dict, Exception | None]:
        """Up to ``periods`` control periods of ``loop``, then mirror the kernel: their samples
        (as ``iceskate_native.ControlLoop.run`` returns them) and what stopped the block early
        or None: a failure of the physics as the ``SimulationError`` that ``advance`` raises, a
        controller's own error (e.g. a non-finite command) as it was raised."""
        self._require_running()
        try:
            block, error = loop.kernel.run(periods), None
            if loop.kernel.failed:
                try:
                    loop.kernel.raise_error()
                except Exception as exc:  # noqa: BLE001 - handed back beside the samples taken
                    error = self.failure(exc) if loop.kernel.physics_failed else exc
            return block, error
        finally:
            self._mirror()

    def failure(self, exc: Exception) -> SimulationError:
        """The SimulationError of a period that raised ``exc`` (the kernel's state is where it
        failed): divergence and chattering with the state, a kernel failure with the period's
        start, bad input as the kernel said it."""
        state = _hybrid_state(self.kernel.state).summary()
        if isinstance(exc, iceskate_native.DivergenceError):
            return SimulationError(f'simulation diverged ({exc}) at {state}', end='diverged')
        if isinstance(exc, iceskate_native.ChatteringError):
            return SimulationError(f'{exc} ({state})', end='diverged')
        if isinstance(exc, iceskate_native.NativeError):
            return SimulationError(f'{exc} (during the period from {state})', end='diverged')
        return SimulationError(f'native simulator: {exc}')

    def _require_running(self) -> None:
        """:raises SimulationError: once the run has ended (no further period)."""
        if self.ended is not None:
            raise SimulationError(f'the run ended at t={self.state.t:.6f} s in mode '
                                  f'{self.state.mode.number} ({self.ended}); no further '
                                  'period can be simulated')

    def _mirror(self) -> None:
        """Take the kernel's state, new events, counters and end."""
        kernel = self.kernel
        self.state = _hybrid_state(kernel.state)
        self.events.extend(
            Transition(t, from_mode, to_mode, event,
                       resolved_cause(guard) if event == 'R' else CAUSES[event],
                       tuple(impulse), step_index, SIDES[side])
            for t, from_mode, to_mode, event, guard, impulse, step_index, side
            in kernel.events_since(len(self.events)))
        s = self.stats
        (s.steps, s.evaluations, s.control_periods, s.max_constraint_residual,
         s.max_constraint_drift, s.suppressed_cycles, s.resolved_cycles) = kernel.statistics
        self.ended: str | None = (None, FLIGHT, TOE_FIRST, self._fall)[kernel.ended]


class NativeControlLoop:
    """Many control periods in one C++ call (``kernel``: ``iceskate_native.ControlLoop``, see
    docs/architecture.md, 'One run: many periods per native call'), advanced by
    ``Simulator.run_loop`` with the native ``controllers``; without them, by
    ``Simulator.hold_period`` with the commands of controller nodes received from outside
    (``receive``). The ``kernel``'s own methods give the samples held (``take_block``,
    ``block_size``), drop the commands (``forget``) and the live view of the current state
    (``live``, ``live_fill``, ``live_messages``).

    :param simulator: the simulator it advances.
    :param kinematics: the controllers' view of the robot (``native_control.native_kinematics``;
        None without controllers).
    :param controllers: the native laws, in summing order.
    :param pushes: the scene's pushes (``start``, ``duration``, ``frame``, ``force``).
    :param head_origin: psi at t = 0, the head target recorded while no controller steers one.
    :param inbox: the sources of each controller node whose commands ``receive`` takes, in
        summing order.
    :raises SimulationError: for an unknown push frame or a non-finite value.
    """

    def __init__(self, simulator: Simulator, kinematics: iceskate_native.Kinematics | None,
                 controllers: list[iceskate_native.Controller], pushes: tuple,
                 head_origin: np.ndarray, inbox: tuple[tuple[str, ...], ...] = ()) -> None:
        rows = [(p.start, p.duration, p.frame, np.asarray(p.force, dtype=float)) for p in pushes]
        try:
            self.kernel = iceskate_native.ControlLoop(
                simulator.kernel, kinematics, list(controllers), rows,
                np.asarray(head_origin, dtype=float), simulator.robot.tf_frames,
                [list(s) for s in inbox])
        except (ValueError, TypeError) as exc:
            raise SimulationError(f'native control loop: {exc}') from None

    def receive(self, index: int, values: CommandValues) -> None:
        """Keep the command ``values`` of the inbox's controller node ``index`` for the next
        ``Simulator.hold_period`` (its sources' efforts in the inbox's order).

        :raises SimulationError: naming the field with a wrong size, a non-finite value or a
            negative gain (the command is not kept).
        """
        try:
            self.kernel.receive(index, *values[:6])
        except (ValueError, TypeError) as exc:
            raise SimulationError(f'command: {exc}') from None


def initial_state(q: np.ndarray, mode: int, side: str = 'right', pivot: str = 'toe',
                  v: np.ndarray | None = None, t: float = 0.0) -> HybridState:
    """A HybridState at rest (or with velocity ``v``) in Table 2 ``mode``."""
    gait_mode = get_mode(mode)
    q = np.asarray(q, dtype=float).copy()
    v = np.zeros(N_COORDINATES) if v is None else np.asarray(v, dtype=float).copy()
    if q.shape != (N_COORDINATES,) or v.shape != (N_COORDINATES,):
        raise SimulationError(f'initial q and v need {N_COORDINATES} entries')
    contact = ContactState(gait_mode, side, pivot)
    touchdown = t if gait_mode.swing != 'A' else float('nan')  # a foot already down counts
    return HybridState(t, q, v, contact, t_touchdown=touchdown)
