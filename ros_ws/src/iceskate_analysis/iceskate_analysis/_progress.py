"""Progress bars (tqdm on stderr) that cost nothing when turned off."""

from __future__ import annotations

import sys
from typing import Any

__all__ = ['progress_bar']


class _NoBar:
    """A stand-in with the two methods the analysis calls."""

    def update(self, n: int = 1) -> None:
        """Do nothing."""

    def close(self) -> None:
        """Do nothing."""


def progress_bar(total: int, desc: str, enabled: bool, unit: str = 'sample') -> Any:
    """Return a tqdm bar over ``total`` items, or a silent stand-in when not ``enabled``."""
    if not enabled:
        return _NoBar()
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, mininterval=0.5, file=sys.stderr,
                leave=False)
