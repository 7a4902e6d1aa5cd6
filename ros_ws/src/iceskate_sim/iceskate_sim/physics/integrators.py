"""The integrator settings of a run (docs/model.md, integrators).

The native simulator (``iceskate_native/src/integrators.cpp``, ``integrators_adaptive.cpp``)
advances the state x = [q (18), v (18)] from t0 towards t_end with fixed inputs and stops at the
first guard whose value crosses zero from below, located by TOMS 748: by re-taking the step
with a shorter size for the fixed-step methods (semi-implicit Euler, implicit Euler, classic
RK4), on the dense output for the adaptive Dormand-Prince 5(4) (``rk45``), so the event time is
as accurate as the method itself.

``implicit_euler`` is semi-implicit Euler with the joint, impedance and soft-stop damping taken
implicitly ((M + h D) a = f - D v, as MuJoCo's implicitfast treats damping): the light, heavily
damped links of this model (pelvis, torso segments, hands: d/I up to ~1e4 1/s) make every
explicit method need steps of ~0.1 ms; this one stays stable at much larger steps.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from iceskate_sim.errors import SimulationError

FIXED_STEP = ('symplectic_euler', 'implicit_euler', 'rk4')
METHODS = (*FIXED_STEP, 'rk45')
GUARD_MARGIN = 1.0e-9  # a guard at most this positive right after a transition is not due


@dataclass(frozen=True)
class IntegratorConfig:
    """Choice and settings of the integrator.

    :param method: 'symplectic_euler', 'implicit_euler', 'rk4' (fixed step) or 'rk45'
        (adaptive).
    :param step: fixed step size [s] (fixed-step methods; max step for adaptive ones).
    :param rtol: relative tolerance (adaptive).
    :param atol: absolute tolerance (adaptive).
    :param event_tolerance: tolerance of the event time [s].
    """

    method: str = 'rk4'
    step: float = 1.0e-4
    rtol: float = 1.0e-8
    atol: float = 1.0e-10
    event_tolerance: float = 1.0e-10
    #: the methods this configuration accepts
    methods: ClassVar[tuple[str, ...]] = METHODS

    def __post_init__(self) -> None:
        """Validate the method and the positive settings."""
        if self.method not in self.methods:
            raise SimulationError(f'integrator method {self.method!r} not in {self.methods}')
        for name in ('step', 'rtol', 'atol', 'event_tolerance'):
            value = getattr(self, name)
            if not (np.isfinite(value) and value > 0.0):
                raise SimulationError(f'integrator {name} must be > 0, got {value!r}')
