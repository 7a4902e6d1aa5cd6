"""The integrator settings of a run: ``IntegratorConfig`` (step and tolerances in s) and the
methods ``FIXED_STEP``, ``ADAPTIVE`` (Dormand-Prince 5(4) ``rk45``, the Rosenbrock-W method
``ros34pw2``), ``METHODS``; the integrators run in C++. See docs/model.md §8.1 and §6.4.
"""

from __future__ import annotations

from dataclasses import dataclass

from iceskate_native.parameters import checked, setting
from iceskate_sim.errors import InputRefused

FIXED_STEP = ('symplectic_euler', 'implicit_euler', 'rk4')
ADAPTIVE = ('rk45', 'ros34pw2')
METHODS = (*FIXED_STEP, *ADAPTIVE)
GUARD_MARGIN = 1.0e-9  # a guard at most this positive right after a transition is not due


@dataclass(frozen=True)
class IntegratorConfig:
    """Choice and settings of the integrator, and the drift projection (a scene's
    ``integrator``)."""

    method: str = setting('rk4', 'integration method: fixed step, or rk45 or ros34pw2 '
                          '(adaptive)', choices=METHODS)
    step: float = setting(1e-4, 'fixed step (largest step of an adaptive method)', unit='s',
                          low=1e-6)
    rtol: float = setting(1e-8, 'relative tolerance (adaptive methods)', low=0.0, open_low=True,
                          high=1.0)
    atol: float = setting(1e-10, 'absolute tolerance (adaptive methods)', low=0.0,
                          open_low=True, high=1.0)
    event_tolerance: float = setting(1e-10, 'tolerance of an event time', unit='s', low=0.0,
                                     open_low=True, high=1e-3)
    projection: bool = setting(True, 'project positions and velocities onto the active swing '
                               'constraints after every control period (drift control)')
    __post_init__ = checked(InputRefused)
