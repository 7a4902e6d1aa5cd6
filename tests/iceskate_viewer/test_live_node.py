"""The live view of a run through the ROS graph (``run_scene --ros --view``): its frames are
the simulator's states (forward kinematics of ``gait_state``, the head target of visual
lifting), and the page's pace and pause hold the simulator itself."""

from __future__ import annotations

import json
import pathlib
import threading
import time

import numpy as np
import pytest

pytest.importorskip('rclpy')
pytestmark = pytest.mark.slow

FAST_SKATE = pathlib.Path(__file__).resolve().parents[1] / 'data' / 'fast_skate.yaml'
#: Deadline [s] of each phase of the run watched.
PHASE_S = 60.0


class Watcher:
    """Records the frames a run's ``LiveView`` is offered: (wall time [s], frame)."""

    def __init__(self) -> None:
        self.live = None
        self.frames: list[tuple[float, object]] = []
        self.lock = threading.Lock()

    def wrap(self, live_view):
        def opened(*args, **kwargs):
            live = live_view(*args, **kwargs)
            offer = live.offer

            def recorded(frame):
                with self.lock:
                    self.frames.append((time.monotonic(), frame))
                offer(frame)
            live.offer = recorded
            self.live = live
            return live
        return opened

    def latest(self) -> tuple[float, object] | None:
        with self.lock:
            return self.frames[-1] if self.frames else None

    def wait_for(self, condition, what: str) -> None:
        deadline = time.monotonic() + PHASE_S
        while not condition():
            assert time.monotonic() < deadline, what
            time.sleep(0.05)


def _pace(watcher: Watcher, seconds: float) -> float:
    """Simulated seconds per wall second of the frames offered over ``seconds`` of wall time."""
    first = watcher.latest()
    time.sleep(seconds)
    last = watcher.latest()
    return (last[1].t - first[1].t) / (last[0] - first[0]) if last[0] > first[0] else 0.0


def test_the_page_paces_and_pauses_the_simulator(tmp_path, ros_domain_id, monkeypatch):
    import iceskate_bringup.graph as graph
    from iceskate_bringup.watch import Watch
    watcher = Watcher()
    monkeypatch.setattr(graph, 'live_view', watcher.wrap(graph.live_view))
    seen: dict[str, object] = {}

    def drive() -> None:  # the person at the page
        try:
            watcher.wait_for(lambda: watcher.latest() is not None and watcher.latest()[1].t > 0.05,
                             'no frame of the run')
            seen['paced'] = _pace(watcher, 1.5)
            watcher.live._pause.value = True
            time.sleep(0.5)  # the pause reaches the simulator
            seen['paused'] = _pace(watcher, 1.0)
            watcher.live._pace.value = 0.08  # the simulator's parameter, then go on
            watcher.live._pause.value = False
            time.sleep(0.3)
            seen['slower'] = _pace(watcher, 1.0)
            watcher.live._pace.value = 0.0  # then as fast as it goes, to the end
        except BaseException as exc:  # noqa: BLE001 (reported by the test below)
            seen['error'] = exc
            watcher.live._pace.value = 0.0
            watcher.live._pause.value = False

    thread = threading.Thread(target=drive)
    thread.start()
    metrics = graph.run_graph(str(FAST_SKATE), tmp_path / 'run', domain_id=ros_domain_id,
                              timeout=240.0, duration=1.0, watch=Watch(0.2, '127.0.0.1', 0))
    thread.join(timeout=PHASE_S)
    assert 'error' not in seen, seen.get('error')
    assert metrics['failure'] is None and metrics['sim_time_s'] == pytest.approx(1.0)
    assert seen['paced'] == pytest.approx(0.2, rel=0.3)
    assert seen['paused'] == 0.0
    assert seen['slower'] == pytest.approx(0.08, rel=0.4)
    frames = [frame for _, frame in watcher.frames]
    assert len(frames) >= 10
    assert np.all(np.diff([f.t for f in frames]) > 0)  # the newest state, in order
    # visual lifting's target, from its commands (none yet at the first states)
    assert all(np.all(np.isfinite(f.head_target)) for f in frames if f.t >= 0.01)


def test_a_frame_is_the_state_the_simulator_recorded(tmp_path, ros_domain_id, monkeypatch):
    """Each frame's coordinates, support and mode are the trajectory's sample at its time
    (the run's own record)."""
    import iceskate_bringup.graph as graph
    from iceskate_bringup.watch import Watch
    from iceskate_viewer.pose import ViewFrame
    from iceskate_viewer.replay import load_run
    watcher = Watcher()
    monkeypatch.setattr(graph, 'live_view', watcher.wrap(graph.live_view))
    graph.run_graph(str(FAST_SKATE), tmp_path / 'run', domain_id=ros_domain_id, timeout=240.0,
                    duration=0.6, watch=Watch(0.0, '127.0.0.1', 0))
    run = load_run(tmp_path / 'run')
    events = json.loads((tmp_path / 'run' / 'events.json').read_text())
    assert len(watcher.frames) >= 2
    for _, frame in watcher.frames:
        k = int(np.argmin(np.abs(run.t - frame.t)))
        assert run.t[k] == pytest.approx(frame.t, abs=1e-9)
        recorded = ViewFrame.of_columns(run.columns, k)
        np.testing.assert_array_equal(recorded.q, frame.q)
        assert (recorded.side, recorded.step_index) == (frame.side, frame.step_index)
        # a transition decided at t_k itself (once the commands of t_k are in) is in the
        # sample, not yet in the state the controllers (and the page) were sent
        assert frame.mode in {recorded.mode} | {
            e['from_mode'] for e in events if abs(e['t'] - frame.t) < 1e-9}


class _Page:
    """The page's controls as the node reads them."""

    def __init__(self) -> None:
        self.paused, self.pace, self.on_control = False, 1.0, None


class _Future:
    def add_done_callback(self, callback) -> None:
        pass


def test_controls_before_the_connection_are_sent_once_connected(ros_context):
    """The page's controls changed while the graph starts are not lost: nothing is sent
    before the node connects (the simulator's services may not be up, or a controller's
    commands not yet matched), then the page's state as it is then, and later only what
    changed."""
    from iceskate_viewer.live_node import LiveViewNode
    page = _Page()
    node = LiveViewNode(page, 2, context=ros_context)
    sent: list[tuple[str, object]] = []
    try:
        for name in ('_pause', '_resume'):
            client = getattr(node, name)
            client.call_async = lambda request, name=name: sent.append((name, None)) or _Future()
            client.service_is_ready = lambda: True
        node._parameters.set_parameters = (
            lambda ps: sent.append(('pace', ps[0].value)) or _Future())
        page.pace = 0.5
        page.on_control(page.paused, page.pace)  # the page's thread, before the connection
        page.paused = True
        page.on_control(page.paused, page.pace)
        page.paused = False
        page.on_control(page.paused, page.pace)
        assert sent == []
        node._states.get_publisher_count = lambda: 1
        node._commands_in.get_publisher_count = lambda: 1  # one of the two controllers
        node._connect()
        assert sent == []
        node._commands_in.get_publisher_count = lambda: 2
        node._connect()
        assert sent == [('_resume', None), ('pace', 0.5)]
        page.paused = True
        page.on_control(page.paused, page.pace)
        assert sent[2:] == [('_pause', None)]  # the pace unchanged: not sent again
    finally:
        node.destroy_node()
