"""Nothing listens beyond loopback: every socket of a ``run_scene --ros`` run's processes (the
launcher and its nodes) and of a node started by hand is bound to 127.0.0.1."""

from __future__ import annotations

import os
from pathlib import Path
import subprocess
import sys
import time

import pytest

TINY = Path(__file__).resolve().parents[1] / 'integration' / 'data' / 'tiny_stand.yaml'


def _family_tree(pid: int) -> set[int]:
    """``pid`` and every process below it."""
    parents: dict[int, int] = {}
    for entry in Path('/proc').iterdir():
        if entry.name.isdigit():
            try:
                fields = (entry / 'stat').read_text().rsplit(')', 1)[1].split()
            except OSError:
                continue
            parents[int(entry.name)] = int(fields[1])
    tree, grown = {pid}, True
    while grown:
        below = {child for child, parent in parents.items() if parent in tree} - tree
        tree |= below
        grown = bool(below)
    return tree


def _bound(pids: set[int]) -> set[tuple[str, str]]:
    """(protocol, local address:port) of every UDP socket and listening TCP socket of
    ``pids``."""
    inodes = set()
    for pid in pids:
        try:
            for fd in Path(f'/proc/{pid}/fd').iterdir():
                link = os.readlink(fd)
                if link.startswith('socket:['):
                    inodes.add(link[8:-1])
        except OSError:
            continue
    found = set()
    for proto in ('udp', 'udp6', 'tcp', 'tcp6'):
        for line in Path(f'/proc/net/{proto}').read_text().splitlines()[1:]:
            cols = line.split()
            if cols[9] in inodes and (proto.startswith('udp') or cols[3] == '0A'):
                found.add((proto, cols[1]))
    return found


def _loopback(local: str) -> bool:
    """A local address:port of /proc/net/* (hex, host byte order per 32-bit word) on
    loopback."""
    address = local.split(':')[0]
    if len(address) == 8:
        return bytes.fromhex(address)[::-1][0] == 127
    return address == '00000000000000000000000001000000'  # ::1


def _sockets_while(process: subprocess.Popen, seconds: float) -> set[tuple[str, str]]:
    """The sockets of ``process``'s tree, looked at every 0.2 s for ``seconds``."""
    seen: set[tuple[str, str]] = set()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and process.poll() is None:
        seen |= _bound(_family_tree(process.pid))
        time.sleep(0.2)
    return seen


def test_a_ros_run_binds_nothing_beyond_loopback(tmp_path, ros_env):
    run = subprocess.Popen([sys.executable, '-m', 'iceskate_bringup.runner', str(TINY), '--ros',
                            '--duration', '3', '--out', str(tmp_path / 'run'), '--quiet'],
                           env=ros_env, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                           text=True)
    try:
        seen = _sockets_while(run, 60.0)
        assert run.wait(timeout=60) == 0, run.stderr.read()
    finally:
        run.kill()
        run.wait(timeout=10)
    udp = {s for s in seen if s[0].startswith('udp')}
    assert len(udp) >= 6, seen  # the three nodes' discovery and data sockets were seen
    assert {s for s in seen if not _loopback(s[1])} == set()


@pytest.mark.parametrize('range_', ['LOCALHOST', 'SUBNET', None])
def test_a_node_started_by_hand_binds_nothing_beyond_loopback(tmp_path, ros_env, range_):
    """Whatever discovery range the shell has (or none: no env.sh), the node keeps DDS on
    loopback itself."""
    env = {key: value for key, value in ros_env.items()
           if key not in ('ROS_AUTOMATIC_DISCOVERY_RANGE', 'FASTRTPS_DEFAULT_PROFILES_FILE',
                          'FASTDDS_DEFAULT_PROFILES_FILE')}
    if range_ is not None:
        env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = range_
    node = subprocess.Popen([sys.executable, '-m', 'visual_lifting.visual_lifting_node'],
                            env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        seen = _sockets_while(node, 4.0)
    finally:
        node.terminate()
        node.wait(timeout=20)
    assert len(seen) >= 2, seen
    assert {s for s in seen if not _loopback(s[1])} == set()
