"""What a controller sees of the hybrid state: the input of every control law.

The native core builds it from the simulator state (``Simulator.observation``, the one the
native loop gives its controllers); the ROS nodes read it from ``gait_state`` (which holds the
whole hybrid state). Control laws are pure functions of an
``Observation`` (plus their parameters), so both paths give the same torques.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

import iceskate_native
from iceskate_sim.errors import SimulationError
from iceskate_sim.model.command import all_finite
from iceskate_sim.model.dynamics import ContactState
from iceskate_sim.model.modes import GaitMode, get_mode
from iceskate_sim.model.robot import N_COORDINATES, PIVOTS, SIDES


@dataclass(frozen=True)
class Observation:
    """The state a control law acts on.

    :param t: simulation time of the state [s].
    :param q: coordinates [y0, q1..q17] (m, rad), length 18 (locked entries held).
    :param v: velocities, length 18 (locked entries 0).
    :param mode: Table 2 mode number (1-20).
    :param side: support side, 'right' (a = 0) or 'left' (a = 1).
    :param pivot: support pivot edge, 'toe' or 'heel'.
    :param step_index: number of support exchanges so far (the paper's step k is
        ``step_index + 1``).
    :param t_exchange: t_e, time of the last support exchange [s] (0 before the first).
    :param heel_anchor_y: y_h* of a pinned swing heel [m].
    :param t_touchdown: time of the swing heel strike of the current step [s]; nan while the
        swing foot has not touched down since the last exchange.
    """

    t: float
    q: np.ndarray
    v: np.ndarray
    mode: int
    side: str
    pivot: str
    step_index: int
    t_exchange: float
    heel_anchor_y: float = 0.0
    t_touchdown: float = float('nan')

    def __post_init__(self) -> None:
        """Validate shapes, finiteness and the discrete fields."""
        for name in ('q', 'v'):
            x = np.asarray(getattr(self, name), dtype=float)
            if x.shape != (N_COORDINATES,) or not all_finite(x):
                raise SimulationError(f'observation {name} must be {N_COORDINATES} finite values')
            object.__setattr__(self, name, x)
        get_mode(self.mode)
        if self.side not in SIDES:
            raise SimulationError(f'observation side {self.side!r} not in {SIDES}')
        if self.pivot not in PIVOTS:
            raise SimulationError(f'observation pivot {self.pivot!r} not in {PIVOTS}')
        if not math.isfinite(self.t) or not math.isfinite(self.t_exchange):
            raise SimulationError('observation times must be finite')

    @classmethod
    def of_native(cls, obs: iceskate_native.Observation) -> Observation:
        """The native laws' observation ``obs`` (side and pivot as indices) as this one."""
        return cls(obs.t, obs.q, obs.v, obs.mode, SIDES[obs.side], PIVOTS[obs.pivot],
                   obs.step_index, obs.t_exchange, obs.heel_anchor_y, obs.t_touchdown)

    @property
    def gait_mode(self) -> GaitMode:
        """The Table 2 row of ``mode``."""
        return get_mode(self.mode)

    @property
    def a(self) -> int:
        """The paper's support flag a: 0 when the right foot supports, 1 for the left."""
        return SIDES.index(self.side)

    def contact(self) -> ContactState:
        """The ContactState for the dynamics routines (slide directions: ice, +1)."""
        return ContactState(self.gait_mode, self.side, self.pivot, self.heel_anchor_y)
