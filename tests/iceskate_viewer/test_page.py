"""The page's scene on a real server (no browser: the camera is checked by projecting the robots
with the camera the server gives a browser): the status lines name their runs and count steps
from 1, the default camera frames every run with none hiding another, and following keeps the
robot in the middle of the view, however far it goes, from a browser's default camera too."""

from __future__ import annotations

import asyncio
import time

import msgspec
import numpy as np
import pytest
import viser
from websockets.asyncio.client import connect

from iceskate_sim.model.robot import load_robot
from iceskate_viewer.page import RUN_SPACING, VIEW_ASPECT, RunPage, serve, stop_server
from iceskate_viewer.pose import BodyPose, ViewFrame
from iceskate_viewer.replay import load_run

#: Deadline [s] of every exchange with the server.
DEADLINE_S = 10.0


@pytest.fixture(scope='module')
def body() -> BodyPose:
    """The robot's model, shared by the tests."""
    return BodyPose(load_robot())


@pytest.fixture
def server():
    """A page server on 127.0.0.1, stopped at the end."""
    server = serve('127.0.0.1', 0)
    try:
        yield server
    finally:
        stop_server(server)


def _frame(y0: float) -> ViewFrame:
    """The robot standing with its support foot at ``y0`` [m] along the ice."""
    q = np.zeros(18)
    q[0] = y0
    return ViewFrame(y0, q, 1, 'right', 'toe', 0, np.full(2, np.nan))


def _project(points: np.ndarray, position: np.ndarray, look_at: np.ndarray, fov: float,
             aspect: float) -> np.ndarray:
    """``points`` (N, 3) [m] in a camera at ``position`` looking at ``look_at`` (+z up) of
    vertical field of view ``fov`` [rad] and width/height ``aspect``: (N, 2), -1..1 across
    the view (x rightwards, y upwards), 0 its centre."""
    forward = (look_at - position) / np.linalg.norm(look_at - position)
    right = np.cross(forward, [0.0, 0.0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    d = points - position
    depth = d @ forward
    assert np.all(depth > 0), 'a point behind the camera'
    half = np.tan(fov / 2)
    return np.stack([d @ right / (depth * half * aspect), d @ up / (depth * half)], axis=1)


def _robot_points(page: RunPage, k: int, frame: ViewFrame) -> np.ndarray:
    """Where run ``k``'s shapes are [m] once the page shows it at ``frame``."""
    page.show(k, frame)
    return np.array([m.translation for m in page.body.geometry.oMg]) + (k * RUN_SPACING, 0, 0)


def test_each_status_line_names_its_run_and_steps_count_from_one(server, body, skate_run):
    run = load_run(skate_run)
    page = RunPage(server, body, ['run_a', 'run_b'])
    steps = run.columns['step_index']
    first, later = 0, int(np.flatnonzero(steps == steps[0] + 2)[0])
    assert steps[first] == 0
    page.show(0, ViewFrame.of_columns(run.columns, first))
    page.show(1, ViewFrame.of_columns(run.columns, later))
    line_a, line_b = page.status.content.split('  \n')
    assert line_a.startswith('**run_a** · ') and line_a.endswith(' · step 1')
    assert line_b.startswith('**run_b** · ') and line_b.endswith(' · step 3')


@pytest.mark.parametrize('runs', [1, 2, 5])
def test_the_default_camera_frames_every_run_and_none_hides_another(server, body, runs):
    page = RunPage(server, body, [f'run{k}' for k in range(runs)])
    camera = server.initial_camera
    extents = []
    for k in range(runs):
        seen = _project(_robot_points(page, k, _frame(0.0)), camera.position, camera.look_at,
                        camera.fov, VIEW_ASPECT)
        assert np.all(np.abs(seen) < 0.9), f'run {k} is not all in the view: {seen}'
        extents.append((seen[:, 0].min(), seen[:, 0].max()))
    extents.sort()
    for (_, right), (left, _) in zip(extents[:-1], extents[1:], strict=True):
        assert right < left, f'one robot hides another: {extents}'


def test_following_keeps_the_robot_centred_from_the_browsers_default_camera_on(server, body):
    """A browser reports its own default camera before it takes the page's: following moves
    the page's view (not that camera) to the robot; once the browser reports the page's view,
    the angle and distance its user then chooses are kept."""
    page = RunPage(server, body, ['skate'])
    port = server.get_port()
    own = f'127.0.0.1:{port}'
    fov, aspect = 1.0, 1.6

    def report(position, look_at) -> bytes:
        return msgspec.msgpack.encode({
            'type': 'ViewerCameraMessage', 'wxyz': (1.0, 0.0, 0.0, 0.0),
            'position': tuple(map(float, position)), 'fov': fov, 'near': 0.01, 'far': 100.0,
            'image_height': 500, 'image_width': 800, 'look_at': tuple(map(float, look_at)),
            'up_direction': (0.0, 0.0, 1.0)})

    def robot_in_view(y0: float) -> np.ndarray:
        """Where the middle of the robot at ``y0`` [m] is in the browser's view."""
        points = _robot_points(page, 0, _frame(y0))
        assert points[:, 1].mean() == pytest.approx(y0, abs=0.2)
        (client,) = server.get_clients().values()
        return _project(points.mean(axis=0)[None], client.camera.position,
                        client.camera.look_at, fov, aspect)[0]

    async def browse() -> None:
        async with connect(f'ws://{own}/', origin=f'http://{own}',
                           subprotocols=[f'viser-v{viser.__version__}'], proxy=None,
                           open_timeout=DEADLINE_S) as client:
            await client.send(report((3.0, 3.0, 3.0), (0.0, 0.0, 0.0)))  # its default
            deadline = time.monotonic() + DEADLINE_S
            while not server.get_clients() and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
            (handle,) = server.get_clients().values()
            for y0 in (5.0, 20.0, 40.0):
                assert np.all(np.abs(robot_in_view(y0)) < 0.15), y0
            page_view = handle.camera.position - handle.camera.look_at
            assert np.linalg.norm(page_view) > 2.0 and page_view[1] < 0  # from behind
            # the browser took the page's view, then its user came closer from the side
            await client.send(report(handle.camera.position, handle.camera.look_at))
            chosen = np.array([2.0, 0.0, 0.5])
            await client.send(report(handle.camera.look_at + chosen, handle.camera.look_at))
            deadline = time.monotonic() + DEADLINE_S
            while (not np.allclose(handle.camera.position - handle.camera.look_at, chosen)
                   and time.monotonic() < deadline):
                await asyncio.sleep(0.05)
            assert np.all(np.abs(robot_in_view(60.0)) < 0.15)
            np.testing.assert_allclose(handle.camera.position - handle.camera.look_at, chosen)

    asyncio.run(browse())
