"""The live view never holds the simulation back: ``offer`` returns at once however slow the
page is (frames not yet drawn are replaced), the display thread draws at most ``DISPLAY_HZ``
frames a second, and ``keep_pace`` waits only for the pace and the page's pause, never past a
stop request."""

import threading
import time

import numpy as np
import pytest

from iceskate_sim.model.robot import load_robot
from iceskate_sim.shutdown import StopRequest
from iceskate_viewer.live import DISPLAY_HZ, LiveView
from iceskate_viewer.pose import BodyPose, ViewFrame


def _frame(t: float) -> ViewFrame:
    return ViewFrame(t, np.zeros(18), 1, 'right', 'toe', 0, np.array([0.0, 1.7]))


@pytest.fixture
def live():
    view = LiveView(BodyPose(load_robot()), 'test', '127.0.0.1', 0, pace=0.0)
    try:
        yield view
    finally:
        view.close()


def test_offer_never_waits_for_a_slow_page(live):
    release = threading.Event()
    live.page.show = lambda k, frame: release.wait(5.0)  # a page stuck drawing
    started = time.perf_counter()
    for k in range(10_000):
        live.offer(_frame(k * 1e-3))
    spent = time.perf_counter() - started
    release.set()
    assert live.dropped >= 10_000 - 2  # all but the one drawn and the one queued
    assert spent < 2.0, spent  # a put into a queue of one: microseconds each, not 5 s


def test_the_page_draws_at_most_the_display_rate(live):
    drawn = []
    live.page.show = lambda k, frame: drawn.append(time.perf_counter())
    deadline = time.perf_counter() + 1.0
    k = 0
    while time.perf_counter() < deadline:
        live.offer(_frame(k * 1e-3))
        k += 1
        time.sleep(0.001)
    gaps = np.diff(drawn)
    assert len(drawn) >= 5 and np.min(gaps) >= 0.9 / DISPLAY_HZ, gaps


def test_keep_pace_holds_simulated_time_to_the_pace(live):
    live._pace.value = 2.0
    stop = StopRequest()
    started = time.perf_counter()
    for k in range(31):
        live.keep_pace(k * 0.02, stop)  # 0.6 s simulated at twice real time: >= 0.3 s
    assert time.perf_counter() - started >= 0.3 - 0.02


def test_pause_holds_the_run_until_resumed_or_stopped(live):
    stop = StopRequest()
    live._pause.value = True
    threading.Timer(0.3, lambda: setattr(live._pause, 'value', False)).start()
    started = time.perf_counter()
    live.keep_pace(0.0, stop)
    assert time.perf_counter() - started >= 0.25
    live._pause.value = True
    stop.signum = 2  # a stop request ends the wait at once
    started = time.perf_counter()
    live.keep_pace(0.0, stop)
    assert time.perf_counter() - started < 1.0


def test_a_frame_the_page_fails_is_said_once_and_the_next_is_drawn(live, capsys):
    drawn, failed = [], threading.Event()

    def flaky(k: int, frame: ViewFrame) -> None:
        if not failed.is_set():
            failed.set()
            raise RuntimeError('deque mutated during iteration')
        drawn.append(frame.t)
    live.page.show = flaky
    live.offer(_frame(0.25))
    assert failed.wait(5.0)
    deadline = time.monotonic() + 5.0
    while not drawn and time.monotonic() < deadline:
        live.offer(_frame(0.5))
        time.sleep(0.05)
    assert drawn and drawn[0] == 0.5 and live._thread.is_alive()
    err = capsys.readouterr().err
    assert err == ('run_scene: the live view missed a frame at t=0.250 s: RuntimeError: deque '
                   'mutated during iteration\n')


def test_a_page_that_keeps_failing_stops_drawing_and_the_loop_goes_on(live, capsys):
    def broken(k: int, frame: ViewFrame) -> None:
        raise RuntimeError('the socket is gone')
    live.page.show = broken
    deadline = time.monotonic() + 10.0
    k = 0
    while live._thread.is_alive() and time.monotonic() < deadline:
        live.offer(_frame(k * 1e-3))  # never waits
        k += 1
        time.sleep(0.01)
    assert not live._thread.is_alive()
    for j in range(100):
        live.offer(_frame(j * 1e-3))  # still never waits
    lines = capsys.readouterr().err.splitlines()
    assert len(lines) == 2, lines
    assert 'missed a frame' in lines[0] and 'RuntimeError: the socket is gone' in lines[0]
    assert 'stopped drawing' in lines[1] and 'Traceback' not in ''.join(lines)
