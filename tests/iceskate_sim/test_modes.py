"""The mode table against the paper's Table 2 (docs/model.md §3), and its error handling."""

import numpy as np
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.modes import MODES, get_mode
from iceskate_sim.model.robot import COORDINATE_NAMES
from oracle.automaton import mode_for

# Table 2 as printed (docs/model.md §3.3): number -> (support, swing, coordinates, multipliers,
# n, n_c, DOF). 'q2..' stands for q2...q17.
TABLE_2 = {
    1: ('F-S', 'A', 'q2..', (), 16, 0, 16),
    2: ('R-S', 'A', 'q1 q2..', (), 17, 0, 17),
    3: ('F-G', 'A', 'y0 q2..', (), 17, 0, 17),
    4: ('R-G', 'A', 'y0 q1 q2..', (), 18, 0, 18),
    5: ('F-S', 'Hs', 'q2..', ('f_nz',), 16, 1, 15),
    6: ('R-S', 'Hs', 'q1 q2..', ('f_nz',), 17, 1, 16),
    7: ('F-G', 'Hs', 'y0 q2..', ('f_nz',), 17, 1, 16),
    8: ('R-G', 'Hs', 'y0 q1 q2..', ('f_nz',), 18, 1, 17),
    9: ('F-S', 'Hp', 'q2..', ('f_nz', 'f_ny'), 16, 2, 14),
    10: ('R-S', 'Hp', 'q1 q2..', ('f_nz', 'f_ny'), 17, 2, 15),
    11: ('F-G', 'Hp', 'y0 q2..', ('f_nz', 'f_ny'), 17, 2, 15),
    12: ('R-G', 'Hp', 'y0 q1 q2..', ('f_nz', 'f_ny'), 18, 2, 16),
    13: ('F-S', 'Fs', 'q2..', ('f_nz', 'tau_n'), 16, 2, 14),
    14: ('R-S', 'Fs', 'q1 q2..', ('f_nz', 'tau_n'), 17, 2, 15),
    15: ('F-G', 'Fs', 'y0 q2..', ('f_nz', 'tau_n'), 17, 2, 15),
    16: ('R-G', 'Fs', 'y0 q1 q2..', ('f_nz', 'tau_n'), 18, 2, 16),
    17: ('F-S', 'Fp', 'q2..', ('f_nz', 'f_ny', 'tau_n'), 16, 3, 13),
    18: ('R-S', 'Fp', 'q1 q2..', ('f_nz', 'f_ny', 'tau_n'), 17, 3, 14),
    19: ('F-G', 'Fp', 'y0 q2..', ('f_nz', 'f_ny', 'tau_n'), 17, 3, 14),
    20: ('R-G', 'Fp', 'y0 q1 q2..', ('f_nz', 'f_ny', 'tau_n'), 18, 3, 15),
}
CONSTRAINT_OF = {'f_nz': 'hz', 'f_ny': 'hy', 'tau_n': 'fr'}


def _coordinates(spec: str) -> tuple[str, ...]:
    names = []
    for token in spec.split():
        names += [f'q{i}' for i in range(2, 18)] if token == 'q2..' else [token]
    return tuple(names)


def test_there_are_exactly_20_modes_16_touching_and_4_in_the_air():
    assert sorted(MODES) == list(range(1, 21))
    assert sum(m.swing == 'A' for m in MODES.values()) == 4
    assert len({(m.support, m.swing) for m in MODES.values()}) == 20


@pytest.mark.parametrize('number', sorted(TABLE_2))
def test_mode_matches_table_2(number):
    support, swing, coords, multipliers, n, n_c, dof = TABLE_2[number]
    mode = get_mode(number)
    assert mode.number == number
    assert (mode.support, mode.swing) == (support, swing)
    assert tuple(COORDINATE_NAMES[i] for i in mode.active) == _coordinates(coords)
    assert mode.n_coordinates == n == len(_coordinates(coords))
    assert len(mode.constraints) == n_c
    assert mode.n_coordinates - len(mode.constraints) == dof == n - n_c  # degrees of freedom
    assert mode.multipliers == multipliers
    assert mode.constraints == tuple(CONSTRAINT_OF[m] for m in multipliers)
    assert mode.y0_active == ('y0' in coords) == support.endswith('G')
    assert mode.q1_active == ('q1' in coords) == support.startswith('R')
    assert mode.swing_sliding == (swing in ('Hs', 'Fs'))
    # active indices are the positions of the names in [y0, q1, ..., q17], in order
    names = ('y0',) + tuple(f'q{i}' for i in range(1, 18))
    np.testing.assert_array_equal(mode.active, [names.index(c) for c in _coordinates(coords)])
    assert mode_for(support, swing) is mode


def test_active_indices_are_read_only():
    with pytest.raises(ValueError):
        get_mode(4).active[0] = 5


@pytest.mark.parametrize('bad', [0, 21, -1, 'seventeen', None, 1000])
def test_get_mode_rejects_unknown_numbers_naming_them(bad):
    with pytest.raises(SimulationError, match=f'unknown gait mode {bad!r}'):
        get_mode(bad)


@pytest.mark.parametrize('number', [2.5, True, '3'])
def test_get_mode_rejects_non_integer_numbers(number):
    with pytest.raises(SimulationError, match='unknown gait mode'):
        get_mode(number)
