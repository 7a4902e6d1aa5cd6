"""The native (C++) kernel seen from Python: eq. (7) (``NativeGaitDynamics``: the kernel
``iceskate_native.Dynamics`` beside the model terms of ``ModelTerms``), whole control periods
with their integration, event location, transitions, projection and health checks
(``NativePeriods``) and many periods with the controllers (``NativeControlLoop``). The kernel's
single calls (one solve, one segment) are test tools (``tests/oracle/native_probes.py``).

The kernel gets the four support models (sent as Pinocchio archives), the mode table
(``iceskate_sim.model.modes``), the guard table (``iceskate_sim.physics.hybrid``), damping, soft
stops and the physical options; the test oracle's Python formulation (``tests/oracle``) is checked
against it. Errors come back as ``SimulationError``: bad input as the kernel's ``ValueError``, a
singular or rank-deficient system as its ``NativeError``.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import CommandValues, HeldCommand
from iceskate_sim.model.dynamics import (
    ContactState,
    DynamicsParameters,
    DynamicsResult,
    ModelTerms,
)
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import JOINT_LIMITS, PIVOTS, SIDES, SOLE_HEEL_Y, SOLE_TOE_Y, Robot
from iceskate_sim.physics.hybrid import (
    COP_BAND,
    FLIGHT,
    FORCE_BAND,
    GUARDS,
    MOMENT_BAND,
    TOE_FIRST,
    TOE_SCUFF,
    FrictionModel,
    HybridState,
    Transition,
    fall_reason,
    guards_of,
    resolved_cause,
)
from iceskate_sim.physics.integrators import GUARD_MARGIN, IntegratorConfig

#: The guards' dead bands and sole geometry, in the kernel's order.
GUARD_CONSTANTS = (COP_BAND, FORCE_BAND, MOMENT_BAND, TOE_SCUFF, SOLE_TOE_Y, SOLE_HEEL_Y)


def _native_robot(robot: Robot) -> tuple[list, list[dict[str, int]]]:
    """The four support models in the kernel's order (side * 2 + pivot) and their frames."""
    keys = [(side, pivot) for side in SIDES for pivot in PIVOTS]
    models = [iceskate_native.load_model(robot.models[key].model) for key in keys]
    frames = [dict(robot.models[key].frame_ids) for key in keys]
    return models, frames


class NativeGaitDynamics(ModelTerms):
    """Eq. (7) in C++ (``iceskate_native.Dynamics``, which ``NativePeriods`` integrates) beside
    the model terms (one kernel per instance: not thread-safe)."""

    def __init__(self, robot: Robot, params: DynamicsParameters | None = None) -> None:
        super().__init__(robot, params)
        p = self.params
        models, frames = _native_robot(robot)
        modes = [(m.number, m.y0_active, m.q1_active, m.swing_sliding,
                  [int(i) for i in m.active], list(m.constraints)) for m in MODES.values()]
        limits = [(i, lo, hi) for i, (lo, hi) in sorted(JOINT_LIMITS.items())]
        try:
            self._kernel = iceskate_native.Dynamics(
                models, frames, modes, robot.damping, robot.total_mass, limits,
                (p.mu, p.baumgarte, p.joint_limits, p.limit_stiffness, p.limit_damping,
                 p.damping))
        except ValueError as exc:
            raise SimulationError(f'native dynamics: {exc}') from None


#: Guard causes for the event log, by name.
_CAUSES = {guard.name: guard.cause for guard in GUARDS}


def _state_row(state: HybridState) -> tuple:
    """A HybridState as the kernel's state tuple."""
    c = state.contact
    return (state.t, state.q, state.v, c.mode.number, SIDES.index(c.side),
            PIVOTS.index(c.pivot), c.heel_anchor_y, c.support_slide_dir, c.heel_slide_dir,
            state.step_index, state.t_exchange, state.t_touchdown)


def _hybrid_state(row: tuple) -> HybridState:
    """The kernel's state tuple as a HybridState."""
    (t, q, v, mode, side, pivot, anchor, support_dir, heel_dir, step_index, t_exchange,
     t_touchdown) = row
    contact = ContactState(MODES[mode], SIDES[side], PIVOTS[pivot], anchor, support_dir,
                           heel_dir)
    return HybridState(t, q, v, contact, step_index, t_exchange, t_touchdown)


class NativePeriods:
    """Whole control periods in C++ (``iceskate_native.HybridSimulator``): the integration
    (fixed-step methods, or rk45: Dormand-Prince 5(4) with its step-size control, events on its
    dense output), event location, transitions, projection and health checks of
    ``Simulator.advance``, with no Python in between. ``Simulator`` runs every period on it and
    mirrors its state, events and counters.

    :param dynamics: the native kernel it integrates (its workspace is shared: one thread).
    :param initial: the initial state. The other parameters are ``SimulatorConfig``'s.
    :ivar robot: the robot simulated (``dynamics.robot``).
    """

    def __init__(self, dynamics: NativeGaitDynamics, initial: HybridState, *,
                 control_period: float, integrator: IntegratorConfig, friction: FrictionModel,
                 projection: bool, residual_bound: float, fall_height: float, max_speed: float,
                 max_instant_transitions: int, zeno_window: float,
                 chatter_dwell: float) -> None:
        self.robot = dynamics.robot
        self._fall = fall_reason(fall_height)
        guards = [[g.name for g in guards_of(MODES[n])] for n in sorted(MODES)]
        try:
            self._kernel = iceskate_native.HybridSimulator(
                dynamics._kernel, _state_row(initial), control_period, integrator.method,
                integrator.step, integrator.rtol, integrator.atol, integrator.event_tolerance,
                friction.mu, friction.rule == 'ice',
                GUARD_CONSTANTS, GUARD_MARGIN, guards, projection, residual_bound, fall_height,
                max_speed, max_instant_transitions, zeno_window, chatter_dwell)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'native simulator: {exc} (initial state: '
                                  f'{initial.summary()})') from None

    def reset(self) -> None:
        """Back to the initial state (the log and counters cleared)."""
        try:
            self._kernel.reset()
        except iceskate_native.NativeError as exc:
            raise SimulationError(f'native simulator: {exc} (initial state)') from None

    def set_state(self, state: HybridState) -> None:
        """Continue from ``state`` (the event log, counters and rested guards kept)."""
        try:
            self._kernel.set_state(_state_row(state))
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'native simulator: {exc} ({state.summary()})') from None

    def advance(self, command: HeldCommand, push: tuple[str, np.ndarray] | None) -> None:
        """One control period holding ``command`` (and ``push``).

        :raises SimulationError: naming the time, mode and state where the physics failed.
        """
        try:
            self._kernel.advance(command.bias, command.stiffness, command.damping,
                                 '' if push is None else push[0],
                                 None if push is None else push[1])
        except (iceskate_native.NativeError, ValueError, TypeError) as exc:
            raise self.failure(exc) from None

    def failure(self, exc: Exception) -> SimulationError:
        """The SimulationError of a period that raised ``exc`` (the kernel's state is where it
        failed): divergence and chattering with the state, a kernel failure with the period's
        start, bad input as the kernel said it."""
        if isinstance(exc, iceskate_native.DivergenceError):
            return SimulationError(f'simulation diverged ({exc}) at {self.state().summary()}')
        if isinstance(exc, iceskate_native.ChatteringError):
            return SimulationError(f'{exc} ({self.state().summary()})')
        if isinstance(exc, iceskate_native.NativeError):
            return SimulationError(f'{exc} (during the period from {self.state().summary()})')
        return SimulationError(f'native simulator: {exc}')

    def state(self) -> HybridState:
        """The current state."""
        return _hybrid_state(self._kernel.state)

    def start(self) -> tuple[HybridState, DynamicsResult]:
        """The state at the start of the last period (after the transitions due then) and its
        dynamics under the period's input."""
        return _hybrid_state(self._kernel.start_state), DynamicsResult(*self._kernel.start_result)

    def result(self) -> DynamicsResult:
        """The dynamics at the current state under the last input."""
        return DynamicsResult(*self._kernel.result)

    def events_since(self, first: int) -> list[Transition]:
        """The event log from entry ``first`` on."""
        return [Transition(t, from_mode, to_mode, event,
                           resolved_cause(guard) if event == 'R' else _CAUSES[event],
                           tuple(impulse), step_index, SIDES[side])
                for t, from_mode, to_mode, event, guard, impulse, step_index, side
                in self._kernel.events_since(first)]

    def statistics(self) -> tuple[int, int, int, float, float, int, int]:
        """(steps, evaluations, control_periods, max_constraint_residual,
        max_constraint_drift, suppressed_cycles, resolved_cycles)."""
        return self._kernel.statistics

    def ended(self) -> str | None:
        """Why the run ended physically (None: it goes on)."""
        return (None, FLIGHT, TOE_FIRST, self._fall)[self._kernel.ended]


class NativeControlLoop:
    """Many control periods in one C++ call (``iceskate_native.ControlLoop``): at each control
    instant the native ``controllers`` answer the observation through ``kinematics``, the sum of
    their commands and the active push are held over the period, and ``periods`` advances; the
    samples come back as arrays (``Session.run_periods``: the headless runner's
    ``ControlStack`` answers in C++, without Python in between).

    Without controllers it holds the commands of controller nodes received from outside (the
    ROS graph): ``receive`` each node's command, ``hold`` one period (its sample kept in the
    block), ``take_block`` the samples held; ``live`` is the live view of the current state.
    A sample holds what the recording encodes, among it the /tf transforms of the URDF's links
    (``Robot.tf_frames``).

    :param periods: the native periods it advances (a ``Simulator``'s, which mirrors them after
        each block).
    :param kinematics: the controllers' view of the robot (``native_control.native_kinematics``;
        None without controllers).
    :param controllers: the native laws, in summing order.
    :param pushes: the scene's pushes (``start``, ``duration``, ``frame``, ``force``).
    :param head_origin: psi at t = 0, the head target recorded while no controller steers one.
    :param inbox: the sources of each controller node whose commands ``receive`` takes, in
        summing order.
    :raises SimulationError: for an unknown push frame or a non-finite value.
    """

    def __init__(self, periods: NativePeriods, kinematics: iceskate_native.Kinematics | None,
                 controllers: list[iceskate_native.Controller], pushes: tuple,
                 head_origin: np.ndarray, inbox: tuple[tuple[str, ...], ...] = ()) -> None:
        self._periods = periods
        rows = [(p.start, p.duration, p.frame, np.asarray(p.force, dtype=float)) for p in pushes]
        try:
            self._kernel = iceskate_native.ControlLoop(
                periods._kernel, kinematics, list(controllers), rows,
                np.asarray(head_origin, dtype=float), periods.robot.tf_frames,
                [list(s) for s in inbox])
        except (ValueError, TypeError) as exc:
            raise SimulationError(f'native control loop: {exc}') from None

    def run(self, periods: int) -> tuple[dict, Exception | None]:
        """Up to ``periods`` control periods: (their samples as ``iceskate_native.ControlLoop.run``
        returns them, what stopped the block early or None). A failure of the physics comes as
        the ``SimulationError`` that ``NativePeriods.advance`` raises; a controller's own error
        (e.g. a non-finite command) as it was raised."""
        block = self._kernel.run(periods)
        error: Exception | None = None
        if self._kernel.failed:
            try:
                self._kernel.raise_error()
            except Exception as exc:  # noqa: BLE001 - handed back beside the samples taken
                error = self._periods.failure(exc) if self._kernel.physics_failed else exc
        return block, error

    def receive(self, index: int, values: CommandValues) -> None:
        """Keep the command ``values`` of the inbox's controller node ``index`` for the next
        ``hold`` (its sources' efforts in the inbox's order).

        :raises SimulationError: naming the field with a wrong size, a non-finite value or a
            negative gain (the command is not kept).
        """
        try:
            self._kernel.receive(index, *values[:6])
        except (ValueError, TypeError) as exc:
            raise SimulationError(f'command: {exc}') from None

    def hold(self, clear: bool = True) -> None:
        """One control period holding the commands received (``iceskate_native.ControlLoop.hold``;
        ``clear``: forget them afterwards).

        :raises SimulationError: where the physics failed (``NativePeriods.failure``).
        """
        if not self._kernel.hold(clear):
            try:
                self._kernel.raise_error()
            except Exception as exc:  # noqa: BLE001 - the kernel's failure, in our words
                raise self._periods.failure(exc) from None

    def forget(self) -> None:
        """Drop the commands received (none is held until the next ``receive``)."""
        self._kernel.forget()

    @property
    def block_size(self) -> int:
        """Samples held and not taken yet."""
        return self._kernel.block_size

    def take_block(self) -> dict:
        """The samples held since the last call, as ``run`` returns them."""
        return self._kernel.take_block()

    def live(self) -> dict:
        """The live view of the current state, what the simulator publishes at t_k before the
        commands of t_k exist: one sample with ``take_block``'s keys (one row), its dynamics
        under the inputs held over the last period, the held input's generalized force at the
        state as the one source ``held`` and that period's head target."""
        return self._kernel.live()

    def live_fill(self) -> tuple[int, int, int]:
        """Take ``live``'s sample in the loop for ``live_messages``; its (mode, index of the
        latest transition or -1, sources present)."""
        return self._kernel.live_fill()

    def live_messages(self, columns: Sequence[str],
                      programs: Sequence[iceskate_native.CdrProgram]) -> list[bytes]:
        """The bytes of one message per program (``cdr.Layout.program``, numbering
        ``columns``) of the sample ``live_fill`` took."""
        return self._kernel.live_messages(list(columns), list(programs))
