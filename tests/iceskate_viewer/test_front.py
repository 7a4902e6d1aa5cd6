"""The page's front, with a real WebSocket client (``websockets``): a page of another origin, a
request naming another host (DNS rebinding) or a WebSocket with no origin is refused with HTTP
403 before anything of viser's is sent; the page's own origin gets viser's messages, both
ways; GETs are forwarded; stopping the server closes every connection and leaves no thread."""

from __future__ import annotations

import asyncio
import contextlib
import signal
import subprocess
import sys
import threading
import time
import urllib.error
import urllib.request

import msgspec
import pytest
import viser
from websockets.asyncio.client import connect
from websockets.exceptions import ConnectionClosed, InvalidStatus

from iceskate_viewer.page import serve, stop_server, url_of

#: Deadline [s] of every exchange with the server.
DEADLINE_S = 10.0
#: viser's subprotocol (its client's version).
SUBPROTOCOL = f'viser-v{viser.__version__}'


@pytest.fixture
def server():
    """A page server on 127.0.0.1 with a checkbox, stopped at the end."""
    server = serve('127.0.0.1', 0)
    server.gui.add_checkbox('Pause', False)
    try:
        yield server
    finally:
        stop_server(server)


async def _first_message(uri: str, origin: str | None, **tcp: object) -> bytes:
    """The first message viser sends a client of ``origin`` at ``uri``."""
    async with connect(uri, origin=origin, subprotocols=[SUBPROTOCOL], proxy=None,
                       open_timeout=DEADLINE_S, **tcp) as client:
        return await asyncio.wait_for(client.recv(), DEADLINE_S)


def _ws(server: viser.ViserServer) -> str:
    return url_of(server).replace('http://', 'ws://') + '/'


@pytest.mark.timeout(60)
@pytest.mark.parametrize('origin', ['http://evil.example.com', 'null', None, 'own:other port',
                                    'https:own'])
def test_a_websocket_of_another_origin_is_refused_before_any_data(server, origin):
    own = url_of(server)
    origin = {'own:other port': own.rsplit(':', 1)[0] + ':1',
              'https:own': own.replace('http://', 'https://')}.get(origin, origin)
    with pytest.raises(InvalidStatus) as refused:
        asyncio.run(_first_message(_ws(server), origin))
    assert refused.value.response.status_code == 403
    assert b'viser' not in refused.value.response.body
    assert server.get_clients() == {}


@pytest.mark.timeout(60)
@pytest.mark.parametrize('name', ['evil.example.com', '127.0.0.2', '[::2]'])
def test_a_host_that_is_not_the_servers_is_refused(server, name):
    """DNS rebinding: a site's name pointed at 127.0.0.1, its page's origin that name."""
    port = server.get_port()
    foreign = f'{name}:{port}'
    with pytest.raises(InvalidStatus) as refused:
        asyncio.run(_first_message(f'ws://{foreign}/', f'http://{foreign}', host='127.0.0.1',
                                   port=port))
    assert refused.value.response.status_code == 403
    request = urllib.request.Request(url_of(server) + '/', headers={'Host': foreign})
    with pytest.raises(urllib.error.HTTPError) as refused_get:
        urllib.request.urlopen(request, timeout=DEADLINE_S)
    assert refused_get.value.code == 403


@pytest.mark.timeout(60)
@pytest.mark.parametrize('name', ['127.0.0.1', 'localhost'])
def test_the_pages_own_origin_gets_viser_both_ways(server, name):
    """Through the front: viser's messages reach the client, and the camera the client
    reports (msgpack, as viser's client sends it) reaches the server, which then counts the
    client as connected."""
    port = server.get_port()
    own = f'{name}:{port}'
    camera = {'type': 'ViewerCameraMessage', 'wxyz': (1.0, 0.0, 0.0, 0.0),
              'position': (3.0, -1.0, 1.5), 'fov': 1.0, 'near': 0.01, 'far': 100.0,
              'image_height': 500, 'image_width': 800, 'look_at': (0.0, 0.5, 0.8),
              'up_direction': (0.0, 0.0, 1.0)}

    async def report_camera() -> bytes:
        async with connect(f'ws://{own}/', origin=f'http://{own}', subprotocols=[SUBPROTOCOL],
                           proxy=None, open_timeout=DEADLINE_S, host='127.0.0.1',
                           port=port) as client:
            first = await asyncio.wait_for(client.recv(), DEADLINE_S)
            await client.send(msgspec.msgpack.encode(camera))
            deadline = time.monotonic() + DEADLINE_S
            while not server.get_clients() and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
            (client_handle,) = server.get_clients().values()
            assert tuple(client_handle.camera.position) == camera['position']
            return first

    assert isinstance(asyncio.run(report_camera()), bytes)


@pytest.mark.timeout(60)
def test_viser_itself_is_not_on_127_0_0_1(server):
    """viser (which checks no origin) listens on a loopback address drawn at random, not on
    127.0.0.1, where a page could find it by trying ports; its port there is closed."""
    import ipaddress
    import socket
    inner, port = viser.ViserServer.get_host(server), viser.ViserServer.get_port(server)
    assert ipaddress.IPv4Address(inner) in ipaddress.IPv4Network('127.0.0.0/8')
    assert inner != '127.0.0.1'
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(('127.0.0.1', port), timeout=DEADLINE_S).close()
    assert asyncio.run(_first_message(_ws(server), url_of(server)))  # the page still gets it


@pytest.mark.timeout(60)
def test_the_page_itself_is_forwarded(server):
    with urllib.request.urlopen(url_of(server) + '/', timeout=DEADLINE_S) as answer:
        assert answer.status == 200 and b'<html' in answer.read().lower()
    with pytest.raises(urllib.error.HTTPError) as missing:
        urllib.request.urlopen(url_of(server) + '/../../etc/passwd', timeout=DEADLINE_S)
    assert missing.value.code == 404
    import socket  # a path no page sends (bytes past ASCII): 400, not a broken answer
    host, port = url_of(server).removeprefix('http://').rsplit(':', 1)
    with socket.create_connection((host, int(port)), timeout=DEADLINE_S) as raw:
        raw.sendall(f'GET /\xe9 HTTP/1.1\r\nHost: {host}:{port}\r\n\r\n'.encode('latin-1'))
        assert raw.recv(64).startswith(b'HTTP/1.1 400')


@pytest.mark.timeout(60)
def test_stopping_closes_open_connections_and_leaves_no_thread():
    before = set(threading.enumerate())
    server = serve('127.0.0.1', 0)
    uri, own = _ws(server), url_of(server)
    closed = threading.Event()

    async def hold() -> None:
        async with connect(uri, origin=own, subprotocols=[SUBPROTOCOL], proxy=None,
                           open_timeout=DEADLINE_S) as client:
            await asyncio.wait_for(client.recv(), DEADLINE_S)
            opened.set()
            try:
                while True:
                    await asyncio.wait_for(client.recv(), DEADLINE_S)
            except ConnectionClosed:
                closed.set()

    opened = threading.Event()
    holder = threading.Thread(target=asyncio.run, args=(hold(),))
    holder.start()
    assert opened.wait(DEADLINE_S)
    started = time.monotonic()
    stop_server(server)
    assert time.monotonic() - started < 5.0
    holder.join(DEADLINE_S)
    assert closed.is_set()
    time.sleep(0.2)  # viser's worker pool winds down (its stop does not wait for it)
    left = [t for t in set(threading.enumerate()) - before if t.is_alive()
            and not t.name.startswith('ThreadPoolExecutor')]
    assert left == []
    with pytest.raises(OSError):
        urllib.request.urlopen(own, timeout=DEADLINE_S)


@pytest.mark.timeout(60)
def test_a_wildcard_host_takes_this_machines_addresses_only():
    server = serve('0.0.0.0', 0)
    try:
        port = server.get_port()
        for name, allowed in [('127.0.0.1', True), ('0.0.0.0', True),
                              ('evil.example.com', False), ('192.0.2.1', False)]:
            request = urllib.request.Request(f'http://127.0.0.1:{port}/',
                                             headers={'Host': f'{name}:{port}'})
            try:
                with urllib.request.urlopen(request, timeout=DEADLINE_S) as answer:
                    status = answer.status
            except urllib.error.HTTPError as refused:
                status = refused.code
            assert status == (200 if allowed else 403), name
    finally:
        stop_server(server)


@pytest.mark.timeout(120)
def test_ctrl_c_ends_view_with_a_page_connected(skate_run):
    """``view``, a client of the page's own origin connected through the front: Ctrl-C ends it
    at once, closing the client's connection (going away), with no traceback."""
    view = subprocess.Popen([sys.executable, '-m', 'iceskate_viewer.replay', str(skate_run),
                             '--port', '0'], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        line = view.stdout.readline()  # (the URL line comes in seconds; the timeout bounds it)
        url = line.split()[1]
        opened, codes = threading.Event(), []

        async def hold() -> None:
            async with connect(url.replace('http://', 'ws://') + '/', origin=url,
                               subprotocols=[SUBPROTOCOL], proxy=None,
                               open_timeout=DEADLINE_S) as client:
                await asyncio.wait_for(client.recv(), DEADLINE_S)
                opened.set()
                with contextlib.suppress(ConnectionClosed):
                    while True:
                        await asyncio.wait_for(client.recv(), 3 * DEADLINE_S)
                codes.append(client.close_code)

        holder = threading.Thread(target=asyncio.run, args=(hold(),))
        holder.start()
        assert opened.wait(DEADLINE_S)
        started = time.monotonic()
        view.send_signal(signal.SIGINT)
        _, err = view.communicate(timeout=3 * DEADLINE_S)
        holder.join(DEADLINE_S)
    finally:
        if view.poll() is None:
            view.kill()
            view.communicate()
    assert time.monotonic() - started < 5.0
    assert view.returncode == 0 and err == ''
    assert codes == [1001]


@pytest.mark.timeout(120)
def test_a_connection_that_is_not_http_leaves_no_traceback(skate_run):
    """A port probe (connect and close, or a line that is not HTTP, as ``printf 'hello\\n' | nc``
    sends) is closed without an answer and without a word on ``view``'s stderr; the page is
    still served."""
    import socket
    view = subprocess.Popen([sys.executable, '-m', 'iceskate_viewer.replay', str(skate_run),
                             '--port', '0'], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    try:
        url = view.stdout.readline().split()[1]
        address = ('127.0.0.1', int(url.rsplit(':', 1)[1]))
        socket.create_connection(address, timeout=DEADLINE_S).close()
        for probe in (b'hello\n', b'\x16\x03\x01\x00\x05hello', b'GET / HTTP/1.1\r\nHost: x'):
            with socket.create_connection(address, timeout=DEADLINE_S) as sock:
                sock.sendall(probe)
                sock.shutdown(socket.SHUT_WR)
                assert b'viser' not in sock.recv(65536)
        with urllib.request.urlopen(url + '/', timeout=DEADLINE_S) as answer:
            assert answer.status == 200
        time.sleep(1.0)  # anything the probes made it say, said
        view.send_signal(signal.SIGINT)
        _, err = view.communicate(timeout=3 * DEADLINE_S)
    finally:
        if view.poll() is None:
            view.kill()
            view.communicate()
    assert view.returncode == 0 and 'Traceback' not in err and err == ''
