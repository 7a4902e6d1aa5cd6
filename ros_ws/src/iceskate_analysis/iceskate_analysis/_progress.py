"""Progress bars (tqdm on stderr) that do nothing when turned off."""

from __future__ import annotations

import sys
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from tqdm import tqdm

__all__ = ['progress_bar']


def progress_bar(total: int, desc: str, enabled: bool, unit: str = 'sample') -> tqdm:
    """A tqdm bar over ``total`` items, inert (no output) when not ``enabled``."""
    from tqdm import tqdm
    return tqdm(total=total, desc=desc, unit=unit, mininterval=0.5, file=sys.stderr,
                leave=False, disable=not enabled)
