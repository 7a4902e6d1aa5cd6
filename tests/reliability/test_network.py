"""Nothing listens beyond loopback: every socket of a ``run_scene --ros`` run's processes (the
launcher and its nodes) and of a node started by hand is bound to 127.0.0.1; a ``--ray local``
sweep's Ray processes bind every interface of a network namespace that has loopback alone."""

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


def _bound(pids: set[int], namespaces: bool = False) -> set[tuple]:
    """(protocol, local address:port) of every UDP socket and listening TCP socket of
    ``pids``, each read in its process's own network namespace (``namespaces``: with that
    namespace and its interfaces as third and fourth items)."""
    found = set()
    for pid in pids:
        try:
            inodes = {link[8:-1] for link in (os.readlink(fd) for fd in
                                              Path(f'/proc/{pid}/fd').iterdir())
                      if link.startswith('socket:[')}
            tables = {proto: Path(f'/proc/{pid}/net/{proto}').read_text()
                      for proto in ('udp', 'udp6', 'tcp', 'tcp6')}
            interfaces = frozenset(line.split(':')[0].strip() for line in
                                   Path(f'/proc/{pid}/net/dev').read_text().splitlines()[2:])
            namespace = os.readlink(f'/proc/{pid}/ns/net')
        except OSError:  # gone meanwhile
            continue
        for proto, table in tables.items():
            for line in table.splitlines()[1:]:
                cols = line.split()
                if cols[9] in inodes and (proto.startswith('udp') or cols[3] == '0A'):
                    found.add((proto, cols[1], namespace, interfaces) if namespaces
                              else (proto, cols[1]))
    return found


def _loopback(local: str) -> bool:
    """A local address:port of /proc/net/* (hex, host byte order per 32-bit word) on
    loopback."""
    address = local.split(':')[0]
    if len(address) == 8:
        return bytes.fromhex(address)[::-1][0] == 127
    return address == '00000000000000000000000001000000'  # ::1


def _sockets_while(process: subprocess.Popen, seconds: float, namespaces: bool = False
                   ) -> set[tuple]:
    """The sockets of ``process``'s tree, looked at every 0.2 s for ``seconds`` (``_bound``)."""
    seen: set[tuple] = set()
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline and process.poll() is None:
        seen |= _bound(_family_tree(process.pid), namespaces)
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


def test_a_local_ray_sweep_binds_nothing_beyond_loopback(tmp_path, ros_env):
    """Ray's servers bind ``*``; the local instance runs in a network namespace of its own
    whose one interface is loopback, so each socket is on loopback or in that namespace."""
    pytest.importorskip('ray')
    spec = tmp_path / 'spec.yaml'
    spec.write_text('study: tiny\nscene: stand\noverrides:\n  duration: 4.0\n'
                    '  record.bag: false\naxes:\n  floor.mu: [0.005, 0.006, 0.007, 0.008]\n')
    sweep = subprocess.Popen([sys.executable, '-m', 'iceskate_study.sweep', str(spec), '--out',
                              str(tmp_path / 'out'), '--ray', 'local', '--workers', '2',
                              '--quiet', '--no-maps'], env=ros_env, stdout=subprocess.DEVNULL,
                             stderr=subprocess.PIPE, text=True)
    try:
        seen = _sockets_while(sweep, 120.0, namespaces=True)
        assert sweep.wait(timeout=60) == 0
        stderr = sweep.stderr.read()
    finally:
        sweep.kill()
        sweep.wait(timeout=10)
    if 'a network of loopback alone was refused' in stderr:
        pytest.skip(f'no network namespace here (needs root, as in CI): {stderr.strip()}')
    assert 'Traceback' not in stderr and stderr.count('\n') == 2, stderr  # the summary lines
    assert len({s for s in seen if s[0].startswith('tcp')}) >= 5, seen  # Ray's servers seen
    ours = os.readlink('/proc/self/ns/net')
    assert {s for s in seen if not _loopback(s[1]) and (s[2] == ours or s[3] != {'lo'})} \
        == set(), seen
