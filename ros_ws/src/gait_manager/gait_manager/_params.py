"""Small helpers shared by the gait_manager torque sources (private): the coordinate count, a
fresh torque vector and the phase readings of eq. (10).

Parameter validation lives in ``iceskate_sim.parameters``.
"""

from __future__ import annotations

import math

import numpy as np

N_COORDINATES = 18
PHASE_READINGS = ('A', 'B', 'B_clipped')


def zeros() -> np.ndarray:
    """A fresh 18-vector of zeros (one entry per coordinate [y0, q1..q17])."""
    return np.zeros(N_COORDINATES)


def phase(reading: str, t: float, t_exchange: float, period: float) -> float:
    """Phase Phi [rad] of eq. (10): 'A' 2(t - t_e)/T (literal), 'B' 2 pi (t - t_e)/T,
    'B_clipped' reading B clipped to [0, pi] (docs/model.md, torso yaw)."""
    dt = t - t_exchange
    if reading == 'A':
        return 2.0 * dt / period
    phi = 2.0 * math.pi * dt / period
    if reading == 'B_clipped':
        return min(max(phi, 0.0), math.pi)
    return phi
