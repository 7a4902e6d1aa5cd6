"""A network of loopback alone for a local Ray instance: ``loopback_only``, and, without root,
``run_in_own_namespaces`` to get the privilege it needs.

Ray's servers bind their ports to every interface whatever its node address. Started from a
thread inside a network namespace of its own, whose one interface is loopback, nothing they
open can be reached from another machine, and they still reach each other on 127.0.0.1.
"""

from __future__ import annotations

from collections.abc import Iterator
import contextlib
import ctypes
import fcntl
import os
import shutil
import socket
import struct
import subprocess
import sys

#: unshare(2)/setns(2): the network namespace.
CLONE_NEWNET = 0x40000000
#: netdevice(7): read and set an interface's flags; the flag of an interface that is up.
SIOCGIFFLAGS, SIOCSIFFLAGS, IFF_UP = 0x8913, 0x8914, 0x1
#: Set in the environment of a command started again by ``run_in_own_namespaces``.
OWN_NAMESPACES = 'ICESKATE_OWN_NAMESPACES'
#: util-linux's unshare(1): user namespace with this user as its root, a network namespace.
_UNSHARE = ('unshare', '--user', '--map-root-user', '--net')
#: struct ifreq with ifr_flags: the name (16 bytes), the flags, the rest of the 40-byte union.
_IFREQ = struct.Struct('16sh22x')


@contextlib.contextmanager
def loopback_only() -> Iterator[str | None]:
    """Move the calling thread, and the threads and processes it starts from then on, into a
    new network namespace whose only interface is loopback (brought up); back to the thread's
    own namespace on exit, which must happen on the same thread (what was started inside
    stays there).

    Yields None, or why the namespace could not be made (it needs CAP_SYS_ADMIN: root), in
    which case nothing changed.

    :raises OSError: when the thread cannot return to its namespace.
    """
    libc = ctypes.CDLL(None, use_errno=True)
    own = os.open('/proc/thread-self/ns/net', os.O_RDONLY | os.O_CLOEXEC)

    def back() -> None:
        if libc.setns(own, CLONE_NEWNET) != 0:
            error = ctypes.get_errno()
            raise OSError(error, f'cannot return to the network namespace: '
                                 f'{os.strerror(error)}')
    try:
        if libc.unshare(CLONE_NEWNET) != 0:
            yield os.strerror(ctypes.get_errno())
            return
        try:
            _bring_up('lo')
        except OSError as exc:  # e.g. CAP_SYS_ADMIN without CAP_NET_ADMIN: as if refused
            back()
            yield f'loopback cannot be brought up: {exc.strerror or exc}'
            return
        try:
            yield None
        finally:
            back()
    finally:
        os.close(own)


def _bring_up(interface: str) -> None:
    """Set the up flag of ``interface`` (of the calling thread's network namespace)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        name = interface.encode()
        flags = _IFREQ.unpack(fcntl.ioctl(probe.fileno(), SIOCGIFFLAGS,
                                          _IFREQ.pack(name, 0)))[1]
        fcntl.ioctl(probe.fileno(), SIOCSIFFLAGS, _IFREQ.pack(name, flags | IFF_UP))


def run_in_own_namespaces(module: str, arguments: list[str]) -> None:
    """Without root, replace this process with ``python -m module arguments`` run inside user
    and network namespaces of its own (``unshare --user --map-root-user --net``), where it is
    root and ``loopback_only`` is permitted. Returns, changing nothing, when this process is
    root or was started so already, or where unprivileged user namespaces are not allowed.

    Only for a command's own process (it is replaced): files it writes stay the user's.
    """
    if os.geteuid() == 0 or os.environ.get(OWN_NAMESPACES) or shutil.which(_UNSHARE[0]) is None:
        return
    try:
        probe = subprocess.run([*_UNSHARE, 'true'], capture_output=True, timeout=10.0)
    except (OSError, subprocess.SubprocessError):
        return
    if probe.returncode != 0:
        return
    sys.stdout.flush()
    sys.stderr.flush()
    os.environ[OWN_NAMESPACES] = '1'
    os.execvp(_UNSHARE[0], [*_UNSHARE, sys.executable, '-m', module, *arguments])
