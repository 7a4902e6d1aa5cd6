"""The 20 gait modes of the paper's Table 2, as data.

A mode is the product of a support-foot state (which optional coordinates y0 and q1 are
present) and a swing-foot state (which constraints C_hz, C_hy, C_fr act on the swing heel and
sole). One general routine (``iceskate_sim.model.dynamics``) solves every mode from this table.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import N_COORDINATES, Q1, Y0

# Support-foot states (docs/model.md §3.1): code -> (y0 present, q1 present, meaning)
SUPPORT_STATES = {
    'F-S': (False, False, 'sole flat, stuck'),
    'R-S': (False, True, 'tipping about the toe or heel edge, edge stuck'),
    'F-G': (True, False, 'sole flat, gliding along +y'),
    'R-G': (True, True, 'tipping about an edge while gliding'),
}
# Swing-foot states: code -> (active constraints, heel slides with Coulomb friction, meaning)
SWING_STATES = {
    'A': ((), False, 'swing foot in the air'),
    'Hs': (('hz',), True, 'heel touching and sliding'),
    'Hp': (('hz', 'hy'), False, 'heel touching and pinned'),
    'Fs': (('hz', 'fr'), True, 'sole flat and sliding'),
    'Fp': (('hz', 'hy', 'fr'), False, 'sole flat and stuck'),
}
# Multiplier of each swing constraint: C_hz -> f_nz [N], C_hy -> f_ny [N], C_fr -> tau_n [N m]
MULTIPLIER_OF = {'hz': 'f_nz', 'hy': 'f_ny', 'fr': 'tau_n'}
MULTIPLIER_NAMES = ('f_nz', 'f_ny', 'tau_n')

# Table 2 of the paper: number -> (support state, swing state). Coordinates and multipliers
# follow from the two codes; tests check them against the printed table.
TABLE_2 = {
    1: ('F-S', 'A'), 2: ('R-S', 'A'), 3: ('F-G', 'A'), 4: ('R-G', 'A'),
    5: ('F-S', 'Hs'), 6: ('R-S', 'Hs'), 7: ('F-G', 'Hs'), 8: ('R-G', 'Hs'),
    9: ('F-S', 'Hp'), 10: ('R-S', 'Hp'), 11: ('F-G', 'Hp'), 12: ('R-G', 'Hp'),
    13: ('F-S', 'Fs'), 14: ('R-S', 'Fs'), 15: ('F-G', 'Fs'), 16: ('R-G', 'Fs'),
    17: ('F-S', 'Fp'), 18: ('R-S', 'Fp'), 19: ('F-G', 'Fp'), 20: ('R-G', 'Fp'),
}


@dataclass(frozen=True)
class GaitMode:
    """One row of Table 2."""

    number: int
    support: str  # 'F-S', 'R-S', 'F-G' or 'R-G'
    swing: str  # 'A', 'Hs', 'Hp', 'Fs' or 'Fp'
    y0_active: bool
    q1_active: bool
    constraints: tuple[str, ...]  # subset of ('hz', 'hy', 'fr'), in this order
    swing_sliding: bool  # Coulomb friction on the swing heel (Hs, Fs)
    active: np.ndarray  # indices of the active coordinates in the 18-vector

    @property
    def multipliers(self) -> tuple[str, ...]:
        """Names of the Lagrange multipliers, in the order of ``constraints``."""
        return tuple(MULTIPLIER_OF[c] for c in self.constraints)

    @property
    def n_coordinates(self) -> int:
        """Number of generalized coordinates (16, 17 or 18)."""
        return int(self.active.size)


def _make_mode(number: int, support: str, swing: str) -> GaitMode:
    y0_active, q1_active, _ = SUPPORT_STATES[support]
    constraints, sliding, _ = SWING_STATES[swing]
    locked = {Y0} if not y0_active else set()
    if not q1_active:
        locked.add(Q1)
    active = np.array([i for i in range(N_COORDINATES) if i not in locked], dtype=np.intp)
    active.setflags(write=False)
    return GaitMode(number, support, swing, y0_active, q1_active, constraints, sliding, active)


MODES: dict[int, GaitMode] = {n: _make_mode(n, sup, sw) for n, (sup, sw) in TABLE_2.items()}


def get_mode(number: int) -> GaitMode:
    """Return the Table 2 mode ``number`` (a key of ``MODES``); raise SimulationError for
    anything else."""
    mode = MODES.get(number) if isinstance(number, (int, np.integer)) and not isinstance(
        number, bool) else None
    if mode is None:
        raise SimulationError(f'unknown gait mode {number!r}; the mode table has modes '
                              f'1-{len(MODES)}')
    return mode
