"""``view RUN_DIR ...``: runs loaded from trajectory.npz or the bag, one sentence for a folder
it cannot open, and the page's controls (slider, play, speed, next exchange) on a real server
(no browser: tests/iceskate_viewer/test_browser.py looks at the pixels)."""

import shutil

import numpy as np
import pytest

from iceskate_sim.errors import SimulationError
from iceskate_sim.model.robot import load_robot
from iceskate_viewer.page import RunPage, serve, stop_server
from iceskate_viewer.pose import BodyPose
from iceskate_viewer.replay import COLUMNS, Replay, load_run, main


def test_a_run_loads_from_its_trajectory_and_from_its_bag_alone(skate_run, tmp_path):
    from_npz = load_run(skate_run)
    bag_only = tmp_path / 'bag_only'
    shutil.copytree(skate_run / 'bag', bag_only / 'bag')
    from_bag = load_run(bag_only)
    every = 4  # the bag's 250 Hz of the 1 kHz samples
    np.testing.assert_allclose(from_bag.t, from_npz.t[::every], rtol=0, atol=1e-9)  # ns
    for name in ('q', 'mode', 'side', 'pivot', 'step_index'):
        np.testing.assert_array_equal(from_bag.columns[name], from_npz.columns[name][::every])
    assert np.all(np.isnan(from_bag.columns['head_target']))  # the bag has no head target
    assert np.all(np.isfinite(from_npz.columns['head_target']))


@pytest.mark.parametrize('case, expected', [
    ('missing', 'no such directory'),
    ('empty', 'neither trajectory.npz nor bag/'),
    ('corrupt', 'cannot be read'),
    ('columns', 'lacks the columns'),
    ('file', 'no such directory'),
])
def test_a_folder_it_cannot_open_gets_one_sentence(tmp_path, capsys, case, expected):
    run_dir = tmp_path / case
    if case == 'empty':
        run_dir.mkdir()
    elif case == 'corrupt':
        run_dir.mkdir()
        (run_dir / 'trajectory.npz').write_bytes(b'PK\x03\x04 not a zip')
    elif case == 'columns':
        run_dir.mkdir()
        np.savez(run_dir / 'trajectory.npz', t=np.zeros(3))
    elif case == 'file':
        run_dir.write_text('x')
    with pytest.raises(SimulationError, match=expected):
        load_run(run_dir)
    assert main([str(run_dir), '--port', '0']) == 2
    err = capsys.readouterr().err
    assert expected in err and 'Traceback' not in err and len(err.strip().splitlines()) == 1


def test_next_exchange_and_time_lookup(skate_run):
    run = load_run(skate_run)
    steps = run.columns['step_index']
    exchanges = run.t[1:][np.diff(steps) > 0]
    assert len(exchanges) >= 2
    assert run.next_exchange(0.0) == exchanges[0]
    assert run.next_exchange(exchanges[0]) == exchanges[1]
    assert run.next_exchange(run.t[-1]) is None
    assert run.index_at(-1.0) == 0 and run.index_at(run.t[-1] + 5) == len(run.t) - 1
    assert run.t[run.index_at(0.5)] <= 0.5 < run.t[run.index_at(0.5) + 1]


@pytest.fixture
def replay(skate_run):
    """The replay page of the run twice (two robots) on a server of its own."""
    server = serve('127.0.0.1', 0)
    runs = [load_run(skate_run), load_run(skate_run)]
    try:
        yield Replay(RunPage(server, BodyPose(load_robot()), ['a', 'b']), runs)
    finally:
        stop_server(server)


def test_the_controls_move_every_robot_in_step(replay):
    shown = []
    show = replay.page.show
    replay.page.show = lambda k, frame: (shown.append((k, frame.t)), show(k, frame))
    replay.slider.value = 0.5
    assert [k for k, _ in shown] == [0, 1] and shown[0][1] == shown[1][1] <= 0.5
    shown.clear()
    replay.next_exchange()
    assert replay.slider.value == replay.runs[0].next_exchange(0.5)
    replay.playing.value = True
    replay.speed.value = 2.0
    start = replay.slider.value
    replay.advance(0.1)
    assert replay.slider.value == pytest.approx(start + 0.2)
    replay.advance(100.0)  # to the end: stops there
    assert replay.slider.value == replay.slider.max and not replay.playing.value


def test_the_server_is_on_loopback_and_offers_no_share_link(capsys):
    server = serve('127.0.0.1', 0)
    try:
        assert server.get_host() == '127.0.0.1'
        assert server.request_share_url() is None
    finally:
        stop_server(server)
    assert capsys.readouterr().err == ''
    stop_server(serve('0.0.0.0', 0))
    assert 'reachable from other machines' in capsys.readouterr().err


@pytest.mark.parametrize('host', ['192.0.2.1', 'no-such-host.invalid'])
def test_a_host_it_cannot_serve_on_is_one_sentence(host):
    with pytest.raises(SimulationError, match=f'cannot serve the view on {host}'):
        serve(host, 0)


@pytest.mark.timeout(60)
@pytest.mark.parametrize('port', ['70000', '65536', '-5'])
def test_a_port_out_of_range_is_one_sentence_and_no_hang(skate_run, capsys, port):
    """`view --port 70000` used to leave a traceback in viser's thread and hang: refused in one
    line before anything is served, exit 2."""
    assert main([str(skate_run), '--port', port]) == 2
    err = capsys.readouterr().err
    assert err.strip() == f'view: error: --port must be 0..65535 (0: any free port), got {port}'
    with pytest.raises(SimulationError, match='port must be 0..65535'):
        serve('127.0.0.1', 70000)


def test_columns_are_those_trajectory_npz_writes(skate_run):
    with np.load(skate_run / 'trajectory.npz') as data:
        assert set(COLUMNS) <= set(data.files)
