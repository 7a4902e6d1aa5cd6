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
