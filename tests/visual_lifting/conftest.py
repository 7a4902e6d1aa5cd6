"""Fixtures of the visual_lifting tests: the robot's dynamics and an Observation factory."""

from collections.abc import Callable
import math

import numpy as np
import pytest

from iceskate_sim.dynamics import GaitDynamics
from iceskate_sim.observation import Observation
from iceskate_sim.robot import load_robot

#: Bent-knee standing posture of model-spec 13.1 (a = 0.05 rad), [y0, q1..q17].
BENT = np.zeros(18)
BENT[2:8] = (-0.05, 0.10, -0.05, 0.05, -0.10, 0.05)


@pytest.fixture(scope='session')
def dynamics() -> GaitDynamics:
    """GaitDynamics of the shipped URDF (one per test session)."""
    return GaitDynamics(load_robot())


@pytest.fixture
def make_obs() -> Callable[..., Observation]:
    """Return a factory of Observations; defaults: bent-knee stance, mode 1, right support."""

    def make(t: float = 0.0, q: np.ndarray | None = None, v: np.ndarray | None = None,
             mode: int = 1, side: str = 'right', pivot: str = 'toe', step_index: int = 0,
             t_exchange: float = 0.0, heel_anchor_y: float = 0.0,
             t_touchdown: float = math.nan) -> Observation:
        return Observation(t, BENT.copy() if q is None else np.asarray(q, dtype=float),
                           np.zeros(18) if v is None else np.asarray(v, dtype=float), mode,
                           side, pivot, step_index, t_exchange, heel_anchor_y, t_touchdown)

    return make
