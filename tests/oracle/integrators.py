"""Test oracle: integrators with event location in Python, the readable formulation the native
segments (``iceskate_native/src/integrators.cpp``) are checked against.

The state is x = [q (18), v (18)]. ``integrate_segment`` advances x from t0 towards t_end with
fixed inputs and stops at the first guard whose value crosses zero from below, located by
Brent's method: on the dense output for the adaptive embedded Runge-Kutta methods (scipy's
``RK45`` = Dormand-Prince 5(4) and ``DOP853``, the tight reference of the accuracy tests), and
by re-taking the step with a shorter size for the fixed-step methods (semi-implicit Euler,
classic RK4), so the event time is as accurate as the method itself.

``implicit_euler`` is semi-implicit Euler with the joint, impedance and soft-stop damping taken
implicitly ((M + h D) a = f - D v, as MuJoCo's implicitfast treats damping).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
from scipy import integrate as sp_integrate
from scipy import optimize

from iceskate_native.parameters import setting
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import DynamicsResult
from iceskate_sim.physics.integrators import (
    FIXED_STEP,
    GUARD_MARGIN,
    METHODS,
    IntegratorConfig,
)


@dataclass
class Segment:
    """Outcome of ``integrate_segment`` (this oracle's and the native probe's).

    :ivar t: time reached [s]. :ivar x: state there. :ivar result: dynamics at (t, x).
    :ivar fired: index of the guard that fired at ``t`` (None: reached t_end).
    :ivar steps: accepted steps. :ivar evaluations: right-hand-side evaluations.
    """

    t: float
    x: np.ndarray
    result: DynamicsResult
    fired: int | None
    steps: int
    evaluations: int


#: rhs(t, x, implicit_step=0.0) -> (xdot, dynamics); an implicit step's dynamics may be None
Rhs = Callable[..., tuple[np.ndarray, DynamicsResult | None]]
GuardFn = Callable[[float, np.ndarray, DynamicsResult], np.ndarray]


@dataclass(frozen=True)
class ReferenceIntegratorConfig(IntegratorConfig):
    """``IntegratorConfig`` that also takes 'dop853' (scipy's DOP853), the oracle's tight
    reference method, and any largest step of the adaptive methods."""

    method: str = setting('rk4', 'integration method', choices=(*METHODS, 'dop853'))
    step: float = setting(1e-4, 'fixed step (largest step of the adaptive methods)', unit='s',
                          low=0.0, open_low=True)


def _remembered(at: Callable[[float], tuple]) -> Callable[[float], tuple]:
    """``at(s)`` that computes each offset once: the event search asks again for the zero it
    found (to move onto its due side) and for the state there."""
    seen: dict[float, tuple] = {}

    def remembered(s: float) -> tuple:
        found = seen.get(s)
        if found is None:
            found = seen[s] = at(s)
        return found
    return remembered


def _crossed(g0: np.ndarray, g1: np.ndarray) -> np.ndarray:
    return np.flatnonzero((g0 <= GUARD_MARGIN) & (g1 > GUARD_MARGIN))


class Integrator:
    """One integrator; keeps the last adaptive step size between segments."""

    def __init__(self, config: IntegratorConfig) -> None:
        self.config = config
        self._last_step: float | None = None

    def integrate_segment(self, rhs: Rhs, guards: GuardFn, t0: float, x0: np.ndarray,
                          t_end: float, start: tuple[np.ndarray, DynamicsResult] | None = None,
                          ) -> Segment:
        """Advance from (t0, x0) to t_end, or to the first guard crossing before it.

        :param start: (xdot, result) at (t0, x0) if already known (saves one evaluation).
        """
        if self.config.method in FIXED_STEP:
            return self._fixed(rhs, guards, t0, x0, t_end, start)
        return self._adaptive(rhs, guards, t0, x0, t_end, start)

    # --------------------------------------------------------------- fixed step
    def _step(self, rhs: Rhs, t: float, x: np.ndarray, h: float, f0: np.ndarray,
              ) -> tuple[np.ndarray, int]:
        n = x.size // 2
        if self.config.method == 'symplectic_euler':
            v1 = x[n:] + h * f0[n:]
            return np.concatenate([x[:n] + h * v1, v1]), 0
        if self.config.method == 'implicit_euler':
            v1 = x[n:] + h * rhs(t, x, h)[0][n:]
            return np.concatenate([x[:n] + h * v1, v1]), 1
        k1 = f0
        k2 = rhs(t + 0.5 * h, x + 0.5 * h * k1)[0]
        k3 = rhs(t + 0.5 * h, x + 0.5 * h * k2)[0]
        k4 = rhs(t + h, x + h * k3)[0]
        return x + (h / 6.0) * (k1 + 2.0 * k2 + 2.0 * k3 + k4), 3

    def _fixed(self, rhs: Rhs, guards: GuardFn, t0: float, x0: np.ndarray, t_end: float,
               start: tuple[np.ndarray, DynamicsResult] | None) -> Segment:
        h_nominal = self.config.step
        t, x = t0, x0
        f0, r0 = start if start is not None else rhs(t0, x0)
        evaluations = 0 if start is not None else 1
        g0 = guards(t, x, r0)
        steps = 0
        while t_end - t > 1e-12 * max(1.0, abs(t_end)):
            h = min(h_nominal, t_end - t)
            x1, extra = self._step(rhs, t, x, h, f0)
            f1, r1 = rhs(t + h, x1)
            evaluations += extra + 1
            steps += 1
            g1 = guards(t + h, x1, r1)
            crossed = _crossed(g0, g1)
            if crossed.size:
                @_remembered
                def at(s: float, t=t, x=x, f0=f0) -> tuple[np.ndarray, DynamicsResult]:
                    xs = self._step(rhs, t, x, s, f0)[0] if s > 0.0 else x
                    return xs, rhs(t + s, xs)[1]
                def guard_at(s: float, t=t, at=at) -> np.ndarray:
                    return guards(t + s, *at(s))
                s_hit, index, count = self._locate(guard_at, g0, crossed, h)
                evaluations += count * 4
                xs, rs = at(s_hit)
                return Segment(t + s_hit, xs, rs, index, steps, evaluations)
            t, x, f0, r0, g0 = t + h, x1, f1, r1, g1
        return Segment(t_end, x, r0, None, steps, evaluations)

    def _locate(self, guard_at: Callable[[float], np.ndarray], g0: np.ndarray,
                crossed: np.ndarray, h: float) -> tuple[float, int, int]:
        """Earliest zero in [0, h] among the crossed guards: (offset, guard index, calls).

        The offset returned is the due side of the bracket (guard > margin there, within the
        event tolerance of the zero), so the transition is applied where it is due.
        """
        best_s, best_i, calls = np.inf, -1, 0
        tol = self.config.event_tolerance
        for i in crossed:  # g0[i] <= margin < g1[i]
            def phi(s: float, i: int = i) -> float:
                return float(guard_at(s)[i]) - GUARD_MARGIN
            s, info = optimize.brentq(phi, 0.0, h, xtol=tol, rtol=4 * np.finfo(float).eps,
                                      full_output=True)
            calls += info.function_calls
            step = tol
            while phi(s) <= 0.0 and s < h:  # move onto the due side of the zero
                s = min(h, s + step)
                step *= 2.0
                calls += 1
            if s < best_s:
                best_s, best_i = s, int(i)
        return best_s, best_i, calls

    # ----------------------------------------------------------------- adaptive
    def _adaptive(self, rhs: Rhs, guards: GuardFn, t0: float, x0: np.ndarray, t_end: float,
                  start: tuple[np.ndarray, DynamicsResult] | None) -> Segment:
        cfg = self.config
        solver_class = sp_integrate.DOP853 if cfg.method == 'dop853' else sp_integrate.RK45
        counter = [0]

        def fun(t: float, x: np.ndarray) -> np.ndarray:
            counter[0] += 1
            return rhs(t, x)[0]

        first = min(self._last_step, t_end - t0) if self._last_step else None
        solver = solver_class(fun, t0, x0, t_end, rtol=cfg.rtol, atol=cfg.atol,
                              max_step=cfg.step, first_step=first)
        r0 = start[1] if start is not None else rhs(t0, x0)[1]
        g0 = guards(t0, x0, r0)
        steps = 0
        while solver.status == 'running':
            message = solver.step()
            if solver.status == 'failed':
                raise SimulationError(f'{cfg.method} failed at t={solver.t:.6f} s: {message}')
            steps += 1
            if solver.step_size:
                self._last_step = solver.step_size
            t1, x1 = solver.t, solver.y
            f1, r1 = rhs(t1, x1)
            counter[0] += 1
            g1 = guards(t1, x1, r1)
            crossed = _crossed(g0, g1)
            if crossed.size:
                dense = solver.dense_output()
                t_prev = solver.t_old

                @_remembered
                def at(s: float, dense=dense, t_prev=t_prev) -> tuple[np.ndarray,
                                                                     DynamicsResult]:
                    xs = dense(t_prev + s)
                    return xs, rhs(t_prev + s, xs)[1]

                def guard_at(s: float, t_prev=t_prev, at=at) -> np.ndarray:
                    return guards(t_prev + s, *at(s))
                s_hit, index, calls = self._locate(guard_at, g0, crossed, t1 - t_prev)
                x_hit, r_hit = at(s_hit)
                return Segment(t_prev + s_hit, x_hit, r_hit, index, steps,
                               counter[0] + calls + 1)
            g0 = g1
            r0 = r1
        return Segment(solver.t, solver.y.copy(), r0, None, steps, counter[0])
