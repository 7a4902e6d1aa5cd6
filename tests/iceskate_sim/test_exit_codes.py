"""Every executable's exit status (``iceskate_sim.exit_codes``; docs/usage.md, "Exit status");
each executable is checked against it in tests/reliability/test_inputs.py."""

import signal

import pytest

from iceskate_sim.errors import InputRefused, RunInterrupted, SimulationError
from iceskate_sim.exit_codes import DONE, FAILED, REFUSED, error_exit, exit_code_of


def test_the_statuses_are_the_documented_ones():
    assert (DONE, FAILED, REFUSED) == (0, 1, 2)  # 2: argparse's own for a usage error


@pytest.mark.parametrize(('exc', 'status'), [
    (InputRefused("scene key 'floor.mu': must be in [0, 2], got 2.5"), 2),
    (SimulationError('simulation diverged', end='diverged'), 1),
    (SimulationError('cannot write metrics.json', end='io_error'), 1),
    (OSError(28, 'No space left on device'), 1),
    (KeyError('a bug'), 1),
    (RunInterrupted(signal.SIGINT), 130), (RunInterrupted(signal.SIGTERM), 143),
    (RunInterrupted(signal.SIGHUP), 129),
])
def test_an_exception_gives_its_exit_status(exc, status):
    assert exit_code_of(exc) == status


def test_error_exit_says_one_line_and_gives_the_status(capsys):
    assert error_exit('prog', InputRefused('--rate 0 is outside 0.01 to 100')) == 2
    assert error_exit('prog', OSError(28, 'No space left on device'),
                      'cannot write out/summary.png: No space left on device') == 1
    assert capsys.readouterr().err == ('prog: error: --rate 0 is outside 0.01 to 100\n'
                                       'prog: error: cannot write out/summary.png: No space '
                                       'left on device\n')
