"""The shipped guard table (``iceskate_sim.physics.hybrid.GUARDS``, docs/model.md §6) against the
paper's Table 2: every guard once, each applying to the modes of the spec.
"""

import pytest

from iceskate_sim.model.modes import MODES, get_mode
from iceskate_sim.physics.hybrid import GUARDS, guards_of

# Table 2 rows by number: q1 present for R-S/R-G, y0 for F-G/R-G; swing code by block of four
Q1_MODES = {2, 4, 6, 8, 10, 12, 14, 16, 18, 20}
Y0_MODES = {3, 4, 7, 8, 11, 12, 15, 16, 19, 20}
SWING_OF_MODE = {n: ('A', 'Hs', 'Hp', 'Fs', 'Fp')[(n - 1) // 4] for n in range(1, 21)}


# ----------------------------------------------------------------------- guards table
EXPECTED_APPLIES = {
    'E1': lambda n: n not in Q1_MODES, 'E2': lambda n: n not in Q1_MODES,
    'E3': lambda n: n in Q1_MODES, 'E4': lambda n: n not in Y0_MODES,
    'E5': lambda n: n in Y0_MODES, 'E6': lambda n: True,
    'S1': lambda n: SWING_OF_MODE[n] == 'A', 'S7': lambda n: SWING_OF_MODE[n] == 'A',
    'S2': lambda n: SWING_OF_MODE[n] in ('Hs', 'Fs'),
    'S3': lambda n: SWING_OF_MODE[n] in ('Hp', 'Fp'),
    'S4': lambda n: SWING_OF_MODE[n] in ('Hs', 'Hp'),
    'S5': lambda n: SWING_OF_MODE[n] in ('Fs', 'Fp'),
    'S6': lambda n: SWING_OF_MODE[n] != 'A',
}


def test_every_guard_of_the_spec_exists_once():
    names = [g.name for g in GUARDS]
    assert sorted(names) == sorted(EXPECTED_APPLIES)
    assert len(set(names)) == len(names)


@pytest.mark.parametrize('number', sorted(MODES))
def test_guards_apply_to_the_modes_of_the_spec(number):
    mode = get_mode(number)
    expected = {name for name, applies in EXPECTED_APPLIES.items() if applies(number)}
    assert {g.name for g in guards_of(mode)} == expected
    for g in GUARDS:
        assert g.applies(mode) == (g.name in expected), (g.name, number)
    # the table's own codes agree with Table 2 as written above
    assert mode.q1_active == (number in Q1_MODES)
    assert mode.y0_active == (number in Y0_MODES)
    assert mode.swing == SWING_OF_MODE[number]
