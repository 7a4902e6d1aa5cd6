"""Room on disk kept for a run's last writes (its metrics, a bag's summary): a file allocated
when the run starts and given back just before they are written, so that a full disk still
leaves them room."""

from __future__ import annotations

import errno
import os
import pathlib


def reserve(path: pathlib.Path, size: int) -> None:
    """Allocate ``size`` bytes [B] to a new file ``path`` (on a file system that cannot allocate
    ahead, e.g. some network ones, nothing is kept); ``path.unlink`` gives them back.

    :raises OSError: when the disk has less room (``path`` is then removed).
    """
    fd = os.open(path, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.posix_fallocate(fd, 0, size)
    except OSError as exc:
        if exc.errno not in (errno.EOPNOTSUPP, errno.EINVAL):
            path.unlink(missing_ok=True)
            raise
    finally:
        os.close(fd)
