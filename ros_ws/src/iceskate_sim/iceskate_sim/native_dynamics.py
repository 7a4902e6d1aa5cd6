"""Eq. (7) on the native (C++) kernel: ``GaitDynamics`` with ``evaluate`` and
``implicit_acceleration`` computed by ``iceskate_native.Dynamics``, and the fixed-step
integration of a mode with its guards and event location (``integrate_segment``) too.

The same four support models (sent as Pinocchio archives), the same mode table
(``iceskate_sim.modes``), damping, soft stops and physical options as the Python routine, which
stays the readable reference the native one is tested against (``tests/iceskate_native``). Every
other method (head pose, mass matrix, frames, energy, ...) is inherited. Errors come back as
``SimulationError``: bad input as the kernel's ``ValueError``, a singular or rank-deficient
system as its ``NativeError``.
"""

from __future__ import annotations

import numpy as np

import iceskate_native
from iceskate_sim.command import HeldCommand
from iceskate_sim.dynamics import ContactState, DynamicsParameters, DynamicsResult, GaitDynamics
from iceskate_sim.errors import SimulationError
from iceskate_sim.hybrid import (
    COP_BAND,
    FORCE_BAND,
    MOMENT_BAND,
    TOE_SCUFF,
    FrictionModel,
    HybridState,
    guards_of,
)
from iceskate_sim.integrators import GUARD_MARGIN, IntegratorConfig, Segment
from iceskate_sim.modes import MODES
from iceskate_sim.robot import JOINT_LIMITS, PIVOTS, SIDES, SOLE_HEEL_Y, SOLE_TOE_Y, Robot

#: The guards' dead bands and sole geometry, in the kernel's order.
GUARD_CONSTANTS = (COP_BAND, FORCE_BAND, MOMENT_BAND, TOE_SCUFF, SOLE_TOE_Y, SOLE_HEEL_Y)


def _native_robot(robot: Robot) -> tuple[list, list[dict[str, int]]]:
    """The four support models in the kernel's order (side * 2 + pivot) and their frames."""
    keys = [(side, pivot) for side in SIDES for pivot in PIVOTS]
    models = [iceskate_native.load_model(robot.models[key].model) for key in keys]
    frames = [dict(robot.models[key].frame_ids) for key in keys]
    return models, frames


class NativeGaitDynamics(GaitDynamics):
    """``GaitDynamics`` whose eq. (7) runs natively (one kernel per instance: not thread-safe)."""

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

    def _arguments(self, contact: ContactState, q: np.ndarray, v: np.ndarray, tau: np.ndarray,
                   push: tuple[str, np.ndarray] | None, stiffness: np.ndarray | None,
                   damping: np.ndarray | None) -> tuple:
        if (stiffness is None) != (damping is None):  # a joint impedance needs both
            stiffness = np.zeros(18) if stiffness is None else stiffness
            damping = np.zeros(18) if damping is None else damping
        return (contact.mode.number, SIDES.index(contact.side), PIVOTS.index(contact.pivot),
                contact.heel_anchor_y, contact.support_slide_dir, contact.heel_slide_dir,
                np.asarray(q, dtype=float), np.asarray(v, dtype=float),
                np.asarray(tau, dtype=float),
                None if stiffness is None else np.asarray(stiffness, dtype=float),
                None if damping is None else np.asarray(damping, dtype=float),
                '' if push is None else push[0],
                None if push is None else np.asarray(push[1], dtype=float))

    def evaluate(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                 tau: np.ndarray, push: tuple[str, np.ndarray] | None = None,
                 stiffness: np.ndarray | None = None, damping: np.ndarray | None = None,
                 ) -> DynamicsResult:
        """Eq. (7) of ``contact.mode`` at (q, v) (see ``GaitDynamics.evaluate``), natively."""
        try:
            (qdd, multipliers, wrench, normal, tangential, cop_y, heel_friction, applied, heel,
             heel_velocity, toe_z, passive) = self._kernel.evaluate(
                *self._arguments(contact, q, v, tau, push, stiffness, damping))
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'mode {contact.mode.number} dynamics: {exc}') from None
        return DynamicsResult(qdd, multipliers, wrench, normal, tangential, cop_y,
                              heel_friction, applied, heel, heel_velocity, toe_z, passive)

    def implicit_acceleration(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                              tau: np.ndarray, push: tuple[str, np.ndarray] | None,
                              stiffness: np.ndarray | None, damping: np.ndarray | None,
                              step: float) -> np.ndarray:
        """Accelerations of an implicit step (see ``GaitDynamics.implicit_acceleration``),
        natively."""
        try:
            return self._kernel.implicit_acceleration(
                *self._arguments(contact, q, v, tau, push, stiffness, damping), step)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'mode {contact.mode.number} dynamics: {exc}') from None

    def _guard_arguments(self, mode_number: int, t: float, suppressed: dict[str, float],
                         friction: FrictionModel) -> tuple:
        names = [g.name for g in guards_of(MODES[mode_number])]
        rested = [suppressed.get(name, -np.inf) for name in names]
        return (names, rested, friction.mu, friction.rule == 'ice', GUARD_CONSTANTS,
                GUARD_MARGIN)

    def guard_values(self, state: HybridState, command: HeldCommand,
                     push: tuple[str, np.ndarray] | None, friction: FrictionModel,
                     suppressed: dict[str, float]) -> np.ndarray:
        """Values of the guards of ``state.mode`` (rested ones -1), natively."""
        args = self._arguments(state.contact, state.q, state.v, command.bias, push,
                               command.stiffness, command.damping)
        try:
            return self._kernel.guard_values(
                *args, *self._guard_arguments(state.mode.number, state.t, suppressed, friction),
                state.t)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'mode {state.mode.number} guards: {exc}') from None

    def integrate_segment(self, state: HybridState, command: HeldCommand,
                          push: tuple[str, np.ndarray] | None, integrator: IntegratorConfig,
                          friction: FrictionModel, suppressed: dict[str, float],
                          t_end: float) -> Segment:
        """Integrate ``state`` with a fixed-step method to ``t_end`` or the first guard
        crossing (``Integrator.integrate_segment``'s fixed-step path), natively."""
        (mode, side, pivot, anchor, support_dir, heel_dir, q, v, tau, stiffness, damping,
         frame, force) = self._arguments(state.contact, state.q, state.v, command.bias, push,
                                         command.stiffness, command.damping)
        try:
            t, x, result, fired, steps, evaluations = self._kernel.integrate_segment(
                mode, side, pivot, anchor, support_dir, heel_dir, tau, stiffness, damping,
                frame, force, integrator.method, integrator.step, integrator.event_tolerance,
                *self._guard_arguments(mode, state.t, suppressed, friction), state.t,
                np.concatenate([q, v]), t_end)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'mode {mode} integration: {exc}') from None
        return Segment(t, x, DynamicsResult(*result), None if fired < 0 else fired, steps,
                       evaluations)
