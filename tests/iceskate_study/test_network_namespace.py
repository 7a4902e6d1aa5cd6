"""``loopback_only``: the calling thread in a new network namespace of loopback alone (up), and
back in its own afterwards; refused without the privilege, nothing changed."""

import os
from pathlib import Path
import socket

import pytest

from iceskate_study.network import loopback_only


def _namespace() -> str:
    return os.readlink('/proc/thread-self/ns/net')


def _interfaces() -> set[str]:
    lines = Path('/proc/thread-self/net/dev').read_text().splitlines()[2:]
    return {line.split(':')[0].strip() for line in lines}


def test_inside_only_loopback_is_there_and_up_and_the_thread_comes_back():
    before = _namespace()
    with loopback_only() as refused:
        if refused is not None:
            assert _namespace() == before
            pytest.skip(f'no network namespace here (needs root, as in CI): {refused}')
        assert _namespace() != before and _interfaces() == {'lo'}
        with socket.create_server(('0.0.0.0', 0)) as server:  # every interface: loopback
            port = server.getsockname()[1]
            with socket.create_connection(('127.0.0.1', port), timeout=5.0):
                pass
    assert _namespace() == before and len(_interfaces()) >= 1


def test_without_root_the_command_starts_again_in_namespaces_of_its_own(monkeypatch):
    """Not root: the process is replaced by the same command under ``unshare --user
    --map-root-user --net`` (where it is root and may make its loopback), once; root, or
    started so already: nothing happens."""
    import sys

    from iceskate_study import network
    started: list[list[str]] = []
    monkeypatch.setattr(network.os, 'execvp', lambda file, args: started.append([file, *args]))
    monkeypatch.setenv(network.OWN_NAMESPACES, '')  # restored (unset) after the test
    monkeypatch.setattr(network.os, 'geteuid', lambda: 0)
    network.run_in_own_namespaces('iceskate_study.sweep', ['spec.yaml', '--ray', 'local'])
    assert started == []  # root makes its namespace itself
    monkeypatch.setattr(network.os, 'geteuid', lambda: 1000)
    network.run_in_own_namespaces('iceskate_study.sweep', ['spec.yaml', '--ray', 'local'])
    if not started:  # the probe `unshare --user --map-root-user --net true` failed here
        pytest.skip('no unprivileged user namespaces here')
    assert started == [['unshare', 'unshare', '--user', '--map-root-user', '--net',
                        sys.executable, '-m', 'iceskate_study.sweep', 'spec.yaml', '--ray',
                        'local']]
    assert os.environ[network.OWN_NAMESPACES] == '1'
    network.run_in_own_namespaces('iceskate_study.sweep', ['spec.yaml'])  # started so already
    assert len(started) == 1
