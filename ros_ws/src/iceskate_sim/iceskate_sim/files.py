"""A user's file, checked before it is opened: only a regular file is read (opening a named
pipe blocks until a writer comes, and a device never ends)."""

from __future__ import annotations

import os
import pathlib
import stat

from iceskate_sim.errors import InputRefused

#: What a path that is not a regular file is, by its ``stat.S_IS*`` test.
_KINDS = ((stat.S_ISFIFO, 'a named pipe (FIFO)'), (stat.S_ISCHR, 'a character device'),
          (stat.S_ISBLK, 'a block device'), (stat.S_ISSOCK, 'a socket'),
          (stat.S_ISDIR, 'a directory'))


def regular_file(path: str | pathlib.Path, what: str) -> os.stat_result:
    """The status of ``path`` (its links followed), a regular file.

    :raises InputRefused: naming ``what`` (e.g. 'bag file'), the path and why it is not
        read (it cannot be looked at, or it is a FIFO, a device, a socket or a directory).
    """
    try:
        info = os.stat(path)
    except OSError as exc:
        raise InputRefused(f'cannot read {what} {path}: {exc.strerror or exc}') from None
    if not stat.S_ISREG(info.st_mode):
        kind = next((name for test, name in _KINDS if test(info.st_mode)), 'of an unknown kind')
        raise InputRefused(f'{what} {path} is {kind}, not a regular file, and is not read')
    return info
