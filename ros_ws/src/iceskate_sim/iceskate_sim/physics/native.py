"""Eq. (7) in the native (C++) kernel, seen from Python (``NativeGaitDynamics``); the periods
run in ``simulation.Simulator``. Errors come back as ``SimulationError``.
"""

from __future__ import annotations

from dataclasses import dataclass
import functools

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.dynamics import DynamicsParameters, ModelTerms
from iceskate_sim.model.modes import MODES
from iceskate_sim.model.robot import JOINT_LIMITS, PIVOTS, SIDES, SOLE_HEEL_Y, SOLE_TOE_Y, Robot
from iceskate_sim.physics.hybrid import COP_BAND, FORCE_BAND, MOMENT_BAND, TOE_SCUFF


@dataclass(frozen=True)
class GuardConstants:
    """The guards' dead bands and the sole's geometry, as the kernels read them (by name)."""

    cop_band: float  #: [m] the support CoP passes a sole edge by this much (E1, E2)
    force_band: float  #: [N] friction excess, contact force below zero (E4, E6, S3, S6)
    moment_band: float  #: [N m] swing-sole moment below zero (S5)
    toe_scuff: float  #: [m] a swing toe this far below the floor is a scuff (S7)
    sole_toe_y: float  #: [m] toe edge relative to the ankle
    sole_heel_y: float  #: [m] heel edge relative to the ankle


GUARD_CONSTANTS = GuardConstants(cop_band=COP_BAND, force_band=FORCE_BAND,
                                 moment_band=MOMENT_BAND, toe_scuff=TOE_SCUFF,
                                 sole_toe_y=SOLE_TOE_Y, sole_heel_y=SOLE_HEEL_Y)
#: Table 2 as the kernels take it: (number, y0 active, q1 active, swing sliding, active
#: coordinates, constraints) per mode.
MODE_ROWS = [(m.number, m.y0_active, m.q1_active, m.swing_sliding, [int(i) for i in m.active],
              list(m.constraints)) for m in MODES.values()]


#: The support models' keys in the kernels' order (side * 2 + pivot).
MODEL_KEYS = tuple((side, pivot) for side in SIDES for pivot in PIVOTS)


@functools.lru_cache(maxsize=4)
def _native_models(robot: Robot) -> tuple[iceskate_native.RobotModel, ...]:
    """The C++ copies of ``robot``'s four support models, made once per robot (they are
    immutable, so every kernel made from ``robot`` shares them)."""
    return tuple(iceskate_native.load_model(robot.models[key].model) for key in MODEL_KEYS)


def native_robot(robot: Robot) -> tuple[list, list[dict[str, int]]]:
    """The four support models in the kernels' order (side * 2 + pivot) and their frames."""
    return (list(_native_models(robot)),
            [dict(robot.models[key].frame_ids) for key in MODEL_KEYS])


class NativeGaitDynamics(ModelTerms):
    """Eq. (7) in C++ (``kernel``: ``iceskate_native.Dynamics``, which the ``Simulator``
    integrates) beside the model terms (one kernel per instance: not thread-safe)."""

    def __init__(self, robot: Robot, params: DynamicsParameters | None = None) -> None:
        super().__init__(robot, params)
        p = self.params
        models, frames = native_robot(robot)
        limits = [(i, lo, hi) for i, (lo, hi) in sorted(JOINT_LIMITS.items())]
        try:
            self.kernel = iceskate_native.Dynamics(
                models, frames, MODE_ROWS, robot.damping, robot.total_mass, limits,
                (p.mu, p.baumgarte, p.joint_limits, p.limit_stiffness, p.limit_damping,
                 p.damping))
        except ValueError as exc:
            raise SimulationError(f'native dynamics: {exc}') from None
