"""Writing a run's last files on a full disk: ``Room`` keeps disk for them from the start of the
run, ``write_atomically`` replaces a file whole or not at all."""

from __future__ import annotations

import errno
import os
import pathlib


class Room:
    """Disk kept in the file ``path`` (allocated now) for a later write of up to ``size``
    bytes [B]; on a file system that cannot allocate ahead (some network ones) nothing is kept.

    :raises OSError: when the disk has less room (``path`` is then removed).
    """

    def __init__(self, path: pathlib.Path, size: int) -> None:
        self.path = path
        self.size = 0
        fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
        os.close(fd)
        try:
            self.grow(size)
        except OSError:
            path.unlink(missing_ok=True)
            raise

    def grow(self, size: int) -> None:
        """Keep ``size`` bytes [B] (at least what is kept already).

        :raises OSError: when the disk has no room for them.
        """
        if size <= self.size or not self.path.exists():
            return
        fd = os.open(self.path, os.O_WRONLY)
        try:
            os.posix_fallocate(fd, 0, size)
        except OSError as exc:
            if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):
                raise
        finally:
            os.close(fd)
        self.size = size

    def write(self, target: pathlib.Path, data: bytes) -> None:
        """Write ``data`` as the file ``target``, whole or not at all: into the room kept when
        it fits (its disk is then ``target``'s), else after giving the room back. Once only;
        later writes of the same file: ``write_atomically``.

        :raises OSError: when the disk has no room for it (``target`` is then as before).
        """
        if len(data) > self.size or not self.path.exists():
            self.release()
            write_atomically(target, data)
            return
        with self.path.open('r+b') as stream:
            stream.write(data)
            stream.truncate(len(data))
        os.replace(self.path, target)
        self.size = 0

    def release(self) -> None:
        """Give the room back to the disk."""
        self.path.unlink(missing_ok=True)
        self.size = 0


def write_atomically(target: pathlib.Path, data: bytes) -> None:
    """Write ``data`` as the file ``target``, whole or not at all (through a hidden file beside
    it, renamed over it).

    :raises OSError: when it cannot be written (``target`` is then as before).
    """
    staged = target.with_name(f'.{target.name}.partial')
    try:
        staged.write_bytes(data)
        os.replace(staged, target)
    except OSError:
        staged.unlink(missing_ok=True)
        raise
