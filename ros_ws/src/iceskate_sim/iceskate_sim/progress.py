"""Progress bars of the command-line tools: tqdm on stderr, off when not wanted, quiet once
stderr is gone (a closed terminal)."""

from __future__ import annotations

import contextlib
import sys
from typing import Any


class ProgressBar:
    """A bar over ``total`` items (``unit``) named ``desc``; does nothing when not ``enabled``,
    and stops drawing at the first write to stderr that fails. ``leave``: keep the finished
    bar on the screen."""

    def __init__(self, total: int, desc: str, unit: str, enabled: bool = True,
                 leave: bool = True) -> None:
        self._bar: Any = None
        if enabled:
            from tqdm import tqdm
            self._bar = tqdm(total=total, desc=desc, unit=unit, mininterval=0.5,
                             file=sys.stderr, leave=leave, dynamic_ncols=True)

    def update(self, n: int = 1, postfix: str | None = None) -> None:
        """``n`` more items done; ``postfix``: the text after the bar."""
        if self._bar is None:
            return
        try:
            if postfix is not None:
                self._bar.set_postfix_str(postfix, refresh=False)
            self._bar.update(n)
        except (OSError, ValueError):
            self._bar = None

    def note(self, text: str) -> None:
        """One line above the bar."""
        if self._bar is not None:
            with contextlib.suppress(OSError, ValueError):
                self._bar.write(text, file=sys.stderr)

    def close(self) -> None:
        """Finish the bar."""
        if self._bar is not None:
            with contextlib.suppress(OSError, ValueError):
                self._bar.close()
            self._bar = None

    def __enter__(self) -> ProgressBar:
        """Context manager: closed on exit."""
        return self

    def __exit__(self, *exc: object) -> None:
        """Close."""
        self.close()
