"""The pages in a real browser: Debian's headless chromium, driven by playwright, loads the
replay page and the live page of ``run_scene --view`` from 127.0.0.1. In its screenshots the
robot's pixels (the red right side, the blue left side) are there, they move when the slider
moves and as the live run advances, two runs show two robots (the page's own camera), the live
view keeps the robot in its middle as it goes, and the page asks nothing of any other
machine. The set-up installs chromium where it can (root with apt-get); without it these
tests skip, unless ICESKATE_REQUIRE_BROWSER=1 (CI), where they fail."""

from __future__ import annotations

from collections.abc import Iterator
import io
import os
import re
import shutil
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

CHROMIUM = shutil.which('chromium')
pytestmark = [
    pytest.mark.slow,
    pytest.mark.skipif(CHROMIUM is None and os.environ.get('ICESKATE_REQUIRE_BROWSER') != '1',
                       reason='no chromium (the set-up installs it as root: apt-get install '
                              'chromium)'),
]
#: The browser window [px].
VIEWPORT = {'width': 800, 'height': 500}
#: Deadline [s] of a page's first screenshot (software WebGL compiles its shaders first: ~20 s).
FIRST_SHOT_S = 120
#: CSS for a screenshot of the WebGL canvas alone (the panels, notices and labels hidden).
ONLY_THE_CANVAS = '* { visibility: hidden !important; } canvas { visibility: visible !important; }'
#: Pixels of the robot's colours that make a robot on the screen.
ROBOT_PIXELS = 150
#: Deadline [s] for a robot to move on the screen (a loaded machine draws late).
MOVE_S = 30
#: Wall time [s] the live run goes on before the view is checked to have followed it.
FOLLOWED_S = 10


@pytest.fixture(scope='module')
def browser() -> Iterator[object]:
    """Headless chromium (software WebGL), with no way to reach another machine's names."""
    from playwright.sync_api import sync_playwright
    assert CHROMIUM is not None, 'ICESKATE_REQUIRE_BROWSER=1 but there is no chromium'
    with sync_playwright() as playwright:
        browser = playwright.chromium.launch(executable_path=CHROMIUM, args=[
            '--no-sandbox', '--enable-unsafe-swiftshader', '--use-angle=swiftshader',
            '--host-resolver-rules=MAP * ~NOTFOUND, EXCLUDE 127.0.0.1'])
        try:
            yield browser
        finally:
            browser.close()


class Tab:
    """A browser page on ``url``; ``requests``: the address of everything it asked for."""

    def __init__(self, browser: object, url: str) -> None:
        self.page = browser.new_page(viewport=VIEWPORT)
        self.requests: list[str] = []
        self.page.on('request', lambda request: self.requests.append(request.url))
        self.page.on('websocket', lambda socket: self.requests.append(socket.url))
        self.page.goto(url, timeout=FIRST_SHOT_S * 1000)
        self.page.wait_for_selector('text=Connected', timeout=FIRST_SHOT_S * 1000)
        self.shot(timeout=FIRST_SHOT_S)  # the first one waits for the shaders

    def shot(self, timeout: float = 30.0) -> np.ndarray:
        """The 3D view's pixels (H, W, 3): the page without its panels and labels, the axes
        corner blanked."""
        import imageio.v3 as iio
        png = self.page.screenshot(timeout=timeout * 1000, animations='disabled',
                                   style=ONLY_THE_CANVAS)
        pixels = iio.imread(io.BytesIO(png))[..., :3].astype(int)
        pixels[-100:, :100] = 255  # the axes (red, green, blue) in the corner
        return pixels

    def local_only(self) -> bool:
        """Everything the page asked for came from 127.0.0.1."""
        return all(re.match(r'(https?|wss?)://127\.0\.0\.1:\d+/', url + '/')
                   or url.startswith(('data:', 'blob:')) for url in self.requests)


def _robot(pixels: np.ndarray) -> np.ndarray:
    """Where the robot's red (right) or blue (left) side is (H, W) bool."""
    r, g, b = pixels[..., 0], pixels[..., 1], pixels[..., 2]
    return ((r > g + 60) & (r > b + 60)) | ((b > r + 80) & (b > g + 40))


def _columns_with_robot(mask: np.ndarray) -> np.ndarray:
    return np.flatnonzero(mask.sum(axis=0) > 2)


def test_the_replay_page_shows_two_runs_that_move_with_the_slider(browser, skate_run, tmp_path):
    from iceskate_sim.model.robot import load_robot
    from iceskate_viewer.page import RunPage, serve, stop_server, url_of
    from iceskate_viewer.pose import BodyPose
    from iceskate_viewer.replay import Replay, load_run
    server = serve('127.0.0.1', 0)
    try:
        replay = Replay(RunPage(server, BodyPose(load_robot()), ['one', 'two']),
                        [load_run(skate_run), load_run(skate_run)])
        tab = Tab(browser, url_of(server))  # the page's own camera: no robot hides the other
        before, deadline = _robot(tab.shot()), time.monotonic() + FIRST_SHOT_S
        while before.sum() < 2 * ROBOT_PIXELS and time.monotonic() < deadline:  # a busy machine
            time.sleep(0.5)  # draws the moved camera late: wait for it, to a deadline
            before = _robot(tab.shot())
        columns = _columns_with_robot(before)
        assert before.sum() >= 2 * ROBOT_PIXELS
        gaps = np.flatnonzero(np.diff(columns) > 10)
        assert len(gaps) == 1, f'two robots, one gap between them: {columns}'
        replay.slider.value = 1.0
        moved, deadline = 0, time.monotonic() + MOVE_S
        while moved < ROBOT_PIXELS and time.monotonic() < deadline:
            time.sleep(1.0)
            after = _robot(tab.shot())
            assert after.sum() >= 2 * ROBOT_PIXELS
            moved = (before ^ after).sum()
        assert moved >= ROBOT_PIXELS, f'the robots did not move in {MOVE_S} s'
        assert tab.local_only(), tab.requests
        tab.page.screenshot(path=tmp_path / 'replay.png')
    finally:
        stop_server(server)


@pytest.mark.parametrize('transport', [[], ['--ros']], ids=['headless', 'ros'])
def test_the_live_page_follows_the_run_and_ctrl_c_ends_it(browser, tmp_path, transport,
                                                          ros_env):
    from iceskate_viewer.replay import load_run
    out = tmp_path / 'live'
    scene = os.path.join(os.path.dirname(__file__), '..', 'data', 'fast_skate.yaml')
    run = subprocess.Popen(
        [sys.executable, '-m', 'iceskate_bringup.runner', scene, '--out', str(out), '--view',
         '--view-port', '0', '--pace', '0.5', '--duration', '60', '--quiet', *transport],
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=ros_env)
    try:
        url = None
        deadline = time.monotonic() + 60
        while url is None and time.monotonic() < deadline:
            line = run.stderr.readline()
            assert line or run.poll() is None, 'run_scene ended before it served the page'
            if found := re.search(r'http://127\.0\.0\.1:\d+', line):
                url = found.group(0)
        assert url is not None
        tab = Tab(browser, url)
        first, moved, blank = None, 0, 0  # robot pixels changed since the first shot with it
        deadline = time.monotonic() + MOVE_S
        while moved < ROBOT_PIXELS and time.monotonic() < deadline:
            shot = _robot(tab.shot())
            if shot.sum() < ROBOT_PIXELS:  # a page redrawing its scene (its socket back)
                blank += 1
                tab.page.screenshot(path=tmp_path / f'blank_{blank}.png')
            elif first is None:
                first = shot
            else:
                moved = (first ^ shot).sum()
            time.sleep(1.0)
        time.sleep(FOLLOWED_S)  # far along the ice: the view follows it, the robot in the middle
        rows, columns = np.nonzero(_robot(tab.shot()))
        tab.page.screenshot(path=tmp_path / 'followed.png')
        middle = np.array([rows.mean() / VIEWPORT['height'], columns.mean() / VIEWPORT['width']])
        assert len(rows) >= ROBOT_PIXELS and np.all(np.abs(middle - 0.5) < 0.15), (
            f'the robot is at {middle} of the view (0.5: its middle), in {tmp_path}')
        assert tab.local_only(), tab.requests
        run.send_signal(signal.SIGINT)  # with the page open
        _, err = run.communicate(timeout=60)
    finally:
        if run.poll() is None:
            run.kill()
            run.communicate()
    assert moved >= ROBOT_PIXELS, (f'the robot did not move in {MOVE_S} s ({blank} shots '
                                   f'without it, in {tmp_path}); run_scene said: {err}')
    assert run.returncode == 130, err
    assert 'Traceback' not in err
    assert 0.0 < load_run(out).t[-1] < 60.0  # the outputs of the part that ran
