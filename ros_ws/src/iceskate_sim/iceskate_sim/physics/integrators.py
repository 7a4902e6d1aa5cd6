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

from iceskate_sim.errors import SimulationError
from iceskate_sim.parameters import check_fields, setting

FIXED_STEP = ('symplectic_euler', 'implicit_euler', 'rk4')
METHODS = (*FIXED_STEP, 'rk45')
GUARD_MARGIN = 1.0e-9  # a guard at most this positive right after a transition is not due


@dataclass(frozen=True)
class IntegratorConfig:
    """Choice and settings of the integrator, and the drift projection (a scene's
    ``integrator``)."""

    method: str = setting('rk4', 'integration method: fixed step or rk45 (adaptive)',
                          choices=METHODS)
    step: float = setting(1e-4, 'fixed step (largest step of rk45)', unit='s', low=0.0,
                          open_low=True)
    rtol: float = setting(1e-8, 'relative tolerance (rk45)', low=0.0, open_low=True, high=1.0)
    atol: float = setting(1e-10, 'absolute tolerance (rk45)', low=0.0, open_low=True, high=1.0)
    event_tolerance: float = setting(1e-10, 'tolerance of an event time', unit='s', low=0.0,
                                     open_low=True, high=1e-3)
    projection: bool = setting(True, 'project positions and velocities onto the active swing '
                               'constraints after every control period (drift control)')

    def __post_init__(self) -> None:
        """Check the fields."""
        check_fields(self, SimulationError)
