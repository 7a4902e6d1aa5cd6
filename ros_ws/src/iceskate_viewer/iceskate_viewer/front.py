"""The page's front: what a browser reaches of the view.

viser accepts a WebSocket from any origin, so a page of any site open in a browser of this
machine could read the scene and drive the controls (and, by DNS rebinding, so could a site
whose name it points at this machine). viser therefore listens on a free port of a loopback
address drawn at random (``inner_host``: one of 127.0.0.0/8's 16 million on Linux, where a
page cannot find it by trying ports of 127.0.0.1), and ``Front`` serves the page on the
host and port asked for: a request whose ``Host`` does not name this server, or a WebSocket
whose ``Origin`` is not the page's own (``http://`` and that ``Host``), is refused with HTTP
403 before anything of viser's is read; other GETs are forwarded to viser, and an accepted
WebSocket is joined to one of viser's, message for message both ways, until either side
closes.
"""

from __future__ import annotations

import asyncio
import errno
import http
import http.client
import ipaddress
import logging
import secrets
import socket
import threading
import urllib.parse

from websockets.asyncio.client import ClientConnection, connect
from websockets.asyncio.server import ServerConnection, serve
from websockets.datastructures import Headers
from websockets.exceptions import ConnectionClosed, InvalidHandshake
from websockets.http11 import Request, Response
from websockets.typing import Subprotocol

from iceskate_sim.errors import InputRefused, SimulationError

#: Deadline [s] of viser's answer to a forwarded request or WebSocket, and of the front's
#: start and stop.
DEADLINE_S = 10.0
#: Largest message [bytes] a browser may send (viser's own limit).
MAX_MESSAGE = 50 * 1024 * 1024
#: Ports tried from the one asked for, the first busy.
PORT_TRIES = 1000
#: Names of this machine on the loopback interface.
LOOPBACK_NAMES = frozenset({'127.0.0.1', 'localhost', '::1'})
#: Hosts that serve on every address of this machine.
WILDCARDS = frozenset({'0.0.0.0', '::', ''})
#: Response headers of viser's that concern one connection only (not forwarded).
HOP_BY_HOP = frozenset({'connection', 'keep-alive', 'transfer-encoding', 'upgrade'})

#: The front's log (requests refused or broken off): not printed, a port scanner's probe is
#: no news to the user.
LOG = logging.getLogger('iceskate_viewer.front')
LOG.addHandler(logging.NullHandler())
LOG.propagate = False


def bind(host: str, port: int) -> socket.socket:
    """A listening socket on ``host``:``port`` (0: any free port; a busy port: the next free
    one, ``PORT_TRIES`` at the most).

    :raises InputRefused: naming the host and port in one sentence.
    """
    family = socket.AF_INET6 if ':' in host else socket.AF_INET
    ports = range(port, 65536)[:PORT_TRIES] if port else range(1)
    for candidate in ports:
        try:
            return socket.create_server((host, candidate), family=family)
        except OSError as exc:
            if exc.errno != errno.EADDRINUSE:
                where = f'{host} port {candidate}' if candidate else host
                raise InputRefused(f'cannot serve the view on {where}: '
                                   f'{exc.strerror or exc}') from None
    raise InputRefused(f'cannot serve the view on {host}: ports {ports[0]}..{ports[-1]} '
                       'are all busy')


def inner_host() -> str:
    """A loopback address for viser, drawn at random from 127.1.0.0 to 127.255.255.254
    (every address of 127.0.0.0/8 is this machine's on Linux); 127.0.0.1 where another cannot
    be bound."""
    address = str(ipaddress.IPv4Address(int(ipaddress.IPv4Address('127.1.0.0'))
                                        + secrets.randbelow(2**24 - 2**16 - 1)))
    try:
        socket.create_server((address, 0)).close()
    except OSError:
        return '127.0.0.1'
    return address


class Front:
    """The page on ``sock`` (bound to ``host``), viser on ``inner_host``:``inner_port``
    (loopback), served by a thread of its own until ``stop``.

    :raises SimulationError: when the front does not start within ``DEADLINE_S``.
    """

    def __init__(self, sock: socket.socket, host: str, inner_host: str, inner_port: int
                 ) -> None:
        self.host, self.port = host, int(sock.getsockname()[1])
        self._inner_host, self._inner = inner_host, inner_port
        self._names = LOOPBACK_NAMES | {host.strip('[]').lower()}
        self._anywhere = host.strip('[]') in WILDCARDS
        self._loop = asyncio.new_event_loop()
        self._stopping = asyncio.Event()
        self._started = threading.Event()
        self._serving = False
        self._thread = threading.Thread(target=self._run, args=(sock,), name='view-front',
                                        daemon=True)
        self._thread.start()
        if not self._started.wait(DEADLINE_S) or not self._serving:
            self.stop()
            raise SimulationError(f'the view could not be served on {host} port {self.port}')

    def stop(self) -> None:
        """Close the page's port and every browser's connection (and so viser's side of it);
        returns within ``DEADLINE_S`` (more, a stop too late: the thread is a daemon)."""
        if self._thread.is_alive():
            try:
                self._loop.call_soon_threadsafe(self._stopping.set)
            except RuntimeError:  # the loop just ended
                pass
            self._thread.join(2 * DEADLINE_S)

    def _run(self, sock: socket.socket) -> None:
        try:
            self._loop.run_until_complete(self._serve(sock))
            self._loop.run_until_complete(self._loop.shutdown_default_executor())
        except Exception as exc:  # said by __init__ (not started) or logged (stopping)
            LOG.error('the front failed: %s', exc)
        finally:
            self._started.set()
            self._loop.close()
            sock.close()

    async def _serve(self, sock: socket.socket) -> None:
        server = await serve(self._join, sock=sock, process_request=self._check,
                             select_subprotocol=_viser_subprotocol, compression=None,
                             max_size=MAX_MESSAGE, server_header=None, logger=LOG,
                             open_timeout=DEADLINE_S, close_timeout=DEADLINE_S / 4)
        self._serving = True
        self._started.set()
        await self._stopping.wait()
        server.close()
        try:
            await asyncio.wait_for(server.wait_closed(), DEADLINE_S)
        except TimeoutError:
            LOG.warning('connections still open when the view stopped')

    def names_this_server(self, netloc: str) -> bool:
        """``netloc`` (a ``Host`` header: name[:port], IPv6 in brackets) names this server:
        its port, and a loopback name, the host asked for, or (served on every address) an
        address of this machine or its host name."""
        try:
            split = urllib.parse.urlsplit(f'//{netloc}')
            name, port = split.hostname, split.port or 80
        except ValueError:
            return False
        if split.netloc != netloc or split.username is not None or not name \
                or port != self.port:
            return False
        return name in self._names or self._anywhere and (
            name == socket.gethostname().lower() or _local_address(name))

    async def _check(self, connection: ServerConnection, request: Request) -> Response | None:
        """Refuse (403) a request that does not name this server or comes from a page of
        another origin (a WebSocket without an ``Origin``: from no page, refused too); forward
        a GET; let a WebSocket of the page's own origin through (``_join``)."""
        hosts, origins = request.headers.get_all('Host'), request.headers.get_all('Origin')
        if len(hosts) != 1 or not self.names_this_server(hosts[0]):
            return connection.respond(http.HTTPStatus.FORBIDDEN,
                                      'The view answers only requests for its own address.\n')
        upgrade = bool(request.headers.get_all('Upgrade'))  # (websockets checks the rest)
        if (upgrade or origins) and [origin.lower() for origin in origins] != [
                f'http://{hosts[0]}'.lower()]:
            return connection.respond(http.HTTPStatus.FORBIDDEN,
                                      'The view is open only to its own page.\n')
        return None if upgrade else await asyncio.to_thread(self._forward, request)

    def _forward(self, request: Request) -> Response:
        """viser's answer to the GET ``request`` (400: a path or header that is not ASCII
        text, as a page's are; 502: no answer in ``DEADLINE_S``)."""
        if not request.path.isascii() or not all(value.isascii()
                                                 for value in request.headers.values()):
            return Response(http.HTTPStatus.BAD_REQUEST, 'Bad Request', Headers(), b'')
        viser = http.client.HTTPConnection(self._inner_host, self._inner, timeout=DEADLINE_S)
        try:
            encoding = request.headers.get_all('Accept-Encoding')
            viser.request('GET', request.path,
                          headers={'Accept-Encoding': encoding[0]} if encoding else {})
            answer = viser.getresponse()
            body = answer.read()
        except (OSError, http.client.HTTPException) as exc:
            LOG.warning('viser did not answer %s: %s', request.path, exc)
            return Response(http.HTTPStatus.BAD_GATEWAY, 'Bad Gateway', Headers(), b'')
        finally:
            viser.close()
        headers = Headers([(name, value) for name, value in answer.getheaders()
                           if name.lower() not in HOP_BY_HOP])
        return Response(answer.status, answer.reason, headers, body)

    async def _join(self, browser: ServerConnection) -> None:
        """Join ``browser``'s WebSocket to one of viser's (the same path and subprotocol)
        until either closes; the other is closed with its code."""
        subprotocol = browser.subprotocol
        try:
            async with connect(f'ws://{self._inner_host}:{self._inner}{browser.request.path}',
                               subprotocols=[subprotocol] if subprotocol else None,
                               compression=None, max_size=None, proxy=None, logger=LOG,
                               open_timeout=DEADLINE_S, close_timeout=DEADLINE_S / 4
                               ) as viser:
                await _both_ways(browser, viser)
        except (OSError, TimeoutError, InvalidHandshake) as exc:
            LOG.warning('viser did not accept a WebSocket: %s', exc)
            await browser.close(1011, 'the view is not answering')


async def _both_ways(browser: ServerConnection, viser: ClientConnection) -> None:
    """Copy messages both ways until one side closes, then close the other with its code."""
    copies = [asyncio.create_task(_copy(browser, viser)),
              asyncio.create_task(_copy(viser, browser))]
    try:
        await asyncio.wait(copies, return_when=asyncio.FIRST_COMPLETED)
    finally:
        for copy in copies:
            copy.cancel()
        await asyncio.gather(*copies, return_exceptions=True)
    first = viser if viser.close_code is not None else browser
    code, reason = first.close_code, first.close_reason or ''
    if code is None or not (1000 <= code <= 1003 or 1007 <= code <= 1014
                            or 3000 <= code <= 4999):  # not one a peer may send
        code, reason = 1000, ''
    await asyncio.gather(browser.close(code, reason), viser.close(code, reason))


async def _copy(source: ServerConnection | ClientConnection,
                target: ServerConnection | ClientConnection) -> None:
    """Send ``target`` every message of ``source`` (text or binary, as it came)."""
    try:
        async for message in source:
            await target.send(message)
    except ConnectionClosed:
        pass


def _viser_subprotocol(_: ServerConnection, offered: list[Subprotocol]) -> Subprotocol | None:
    """The browser's viser version (``viser-v...``): viser refuses another one."""
    return next((p for p in offered if p.startswith('viser-v')), None)


def _local_address(name: str) -> bool:
    """``name`` is an IP address of this machine (one a socket can be bound to)."""
    try:
        address = ipaddress.ip_address(name)
    except ValueError:
        return False
    family = socket.AF_INET6 if address.version == 6 else socket.AF_INET
    try:
        with socket.create_server((name, 0), family=family):
            return True
    except OSError:
        return False
