"""``PaceClock``: simulated time is due at the pace, counted from the first question after a
(re)start; no pace: everything is due at once."""

import time

import pytest

from iceskate_sim.run.pace import PaceClock


def test_no_pace_has_everything_due():
    clock = PaceClock(0.0)
    assert clock.wait(1e6) == 0.0
    assert clock.due(0.0, 1e-3, 7) == 7


def test_time_is_due_at_the_pace_from_the_first_question():
    clock = PaceClock(2.0)
    assert clock.wait(10.0) == 0.0  # the origin: simulated 10 s is due now
    assert clock.wait(10.2) == pytest.approx(0.1, abs=0.02)  # 0.2 s simulated at 2x
    time.sleep(0.1)
    assert clock.wait(10.2) == pytest.approx(0.0, abs=0.02)
    assert 4 <= clock.due(10.0, 0.05, 100) <= 8  # >= 0.2 s simulated: >= 4 periods of 50 ms


def test_a_new_pace_or_a_restart_counts_anew():
    clock = PaceClock(1.0)
    clock.wait(0.0)
    time.sleep(0.1)
    assert clock.due(0.0, 0.01, 100) >= 9
    clock.restart()  # e.g. after a pause: no catching up
    assert clock.due(0.0, 0.01, 100) == 0
    clock.pace = 0.5
    assert clock.wait(5.0) == 0.0 and clock.wait(5.1) == pytest.approx(0.2, abs=0.02)


@pytest.mark.parametrize('pace', [-1.0, float('nan'), float('inf')])
def test_a_bad_pace_is_refused(pace):
    with pytest.raises(ValueError, match='pace must be >= 0'):
        PaceClock(pace)
