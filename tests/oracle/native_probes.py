"""The native kernel's eq. (7), guards and segments called one at a time from Python, for the
tests and benchmarks that set them beside the oracle's formulation (``oracle.dynamics``,
``oracle.integrators``). A run never calls them: its periods run whole inside
``iceskate_native.HybridSimulator`` (``iceskate_sim.physics.simulation.Simulator``)."""

from __future__ import annotations

import numpy as np

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import HeldCommand
from iceskate_sim.model.dynamics import ContactState, DynamicsResult
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import PIVOTS, SIDES
from iceskate_sim.physics.hybrid import FrictionModel, HybridState, guards_of
from iceskate_sim.physics.integrators import GUARD_MARGIN, IntegratorConfig
from iceskate_sim.physics.native import GUARD_CONSTANTS, NativeGaitDynamics
from oracle.integrators import Segment


class NativeProbes(NativeGaitDynamics):
    """``NativeGaitDynamics`` with its kernel's single calls: ``evaluate``,
    ``implicit_acceleration``, ``linearize``, ``guard_values``,
    ``integrate_segment``."""

    @classmethod
    def of(cls, dynamics: NativeGaitDynamics) -> NativeProbes:
        """The probes of ``dynamics``' own kernel (e.g. a ``Simulator``'s: its workspace, which
        the periods share, is the one the calls change)."""
        probes = cls.__new__(cls)
        probes.__dict__.update(vars(dynamics))
        return probes

    def _arguments(self, contact: ContactState, q: np.ndarray, v: np.ndarray, tau: np.ndarray,
                   push: tuple[str, np.ndarray] | None, stiffness: np.ndarray | None,
                   damping: np.ndarray | None) -> tuple:
        if (stiffness is None) != (damping is None):  # a joint impedance needs both
            stiffness = np.zeros(18) if stiffness is None else stiffness
            damping = np.zeros(18) if damping is None else damping
        if contact.side not in SIDES or contact.pivot not in PIVOTS:
            raise SimulationError(f'unknown support side/pivot {(contact.side, contact.pivot)}; '
                                  f'sides {SIDES}, pivots {PIVOTS}')
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
        """Eq. (7) of ``contact.mode`` at (q, v) natively: the accelerations, multipliers and
        support wrench (docs/model.md §4)."""
        try:
            (qdd, multipliers, wrench, normal, tangential, zmp_y, heel_friction, applied, heel,
             heel_velocity, toe_z, passive) = self.kernel.evaluate(
                *self._arguments(contact, q, v, tau, push, stiffness, damping))
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'mode {contact.mode.number} dynamics: {exc}') from None
        return DynamicsResult(qdd, multipliers, wrench, normal, tangential, zmp_y,
                              heel_friction, applied, heel, heel_velocity, toe_z, passive)

    def implicit_acceleration(self, contact: ContactState, q: np.ndarray, v: np.ndarray,
                              tau: np.ndarray, push: tuple[str, np.ndarray] | None,
                              stiffness: np.ndarray | None, damping: np.ndarray | None,
                              step: float) -> np.ndarray:
        """Accelerations of an implicit step ((M + h D) a = f - D v, D the joint, impedance
        and soft-stop damping), natively.

        The periods run inside ``HybridSimulator`` (``Simulator.kernel``), which takes its implicit
        steps without this call."""
        try:
            return self.kernel.implicit_acceleration(
                *self._arguments(contact, q, v, tau, push, stiffness, damping), step)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'mode {contact.mode.number} dynamics: {exc}') from None

    def linearize(self, contact: ContactState, q: np.ndarray, v: np.ndarray, tau: np.ndarray,
                  stiffness: np.ndarray | None = None, damping: np.ndarray | None = None,
                  lookahead: float = 0.0) -> tuple[np.ndarray, int, int, np.ndarray,
                                                   np.ndarray]:
        """Eq. (7) at (q, v) as the linear system ``ros34pw2`` steps with: (matrix, n, nc,
        stiffness, damping), natively."""
        return self.kernel.linearize(
            *self._arguments(contact, q, v, tau, None, stiffness, damping), lookahead)

    def _guard_arguments(self, mode_number: int, t: float, suppressed: dict[str, float],
                         friction: FrictionModel) -> tuple:
        names = [g.name for g in guards_of(MODES[mode_number])]
        rested = [suppressed.get(name, -np.inf) for name in names]
        return (names, rested, friction.mu, friction.rule == 'ice', GUARD_CONSTANTS,
                GUARD_MARGIN)

    def guard_values(self, state: HybridState, command: HeldCommand,
                     push: tuple[str, np.ndarray] | None, friction: FrictionModel,
                     suppressed: dict[str, float]) -> np.ndarray:
        """Values of the guards of ``state.mode`` (rested ones -1), natively.

        The periods run inside ``HybridSimulator`` (``Simulator.kernel``), which evaluates its
        guards without this call."""
        args = self._arguments(state.contact, state.q, state.v, command.bias, push,
                               command.stiffness, command.damping)
        try:
            return self.kernel.guard_values(
                *args, *self._guard_arguments(state.mode.number, state.t, suppressed, friction),
                state.t)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'mode {state.mode.number} guards: {exc}') from None

    def integrate_segment(self, state: HybridState, command: HeldCommand,
                          push: tuple[str, np.ndarray] | None, integrator: IntegratorConfig,
                          friction: FrictionModel, suppressed: dict[str, float],
                          t_end: float) -> Segment:
        """Integrate ``state`` to ``t_end`` or the first guard crossing with a fixed-step
        method, rk45 or ros34pw2 (``Integrator.integrate_segment``'s counterpart, natively; the
        adaptive methods start with ``integrator.step`` and keep no step history between
        calls).

        The periods run inside ``HybridSimulator`` (``Simulator.kernel``), which integrates its
        segments without this call."""
        (mode, side, pivot, anchor, support_dir, heel_dir, q, v, tau, stiffness, damping,
         frame, force) = self._arguments(state.contact, state.q, state.v, command.bias, push,
                                         command.stiffness, command.damping)
        try:
            t, x, result, fired, steps, evaluations = self.kernel.integrate_segment(
                mode, side, pivot, anchor, support_dir, heel_dir, tau, stiffness, damping,
                frame, force, integrator.method, integrator.step, integrator.rtol,
                integrator.atol, integrator.event_tolerance,
                *self._guard_arguments(mode, state.t, suppressed, friction), state.t,
                np.concatenate([q, v]), t_end)
        except (ValueError, TypeError, iceskate_native.NativeError) as exc:
            raise SimulationError(f'mode {mode} integration: {exc}') from None
        return Segment(t, x, DynamicsResult(*result), None if fired < 0 else fired, steps,
                       evaluations)
