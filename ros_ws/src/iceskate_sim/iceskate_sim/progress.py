"""Progress bars of the command-line tools: tqdm on stderr, off when not wanted or when stderr
is no terminal (a log file would keep a frozen bar: the notes are then plain lines), quiet once
stderr is gone (a closed terminal)."""

from __future__ import annotations

import contextlib
import sys
from typing import Any


class ProgressBar:
    """A bar over ``total`` items (``unit``) named ``desc``; does nothing when not ``enabled``,
    draws no bar when stderr is no terminal (its notes are then plain lines), and stops drawing
    at the first write to stderr that fails. ``leave``: keep the finished bar on the screen."""

    def __init__(self, total: int, desc: str, unit: str, enabled: bool = True,
                 leave: bool = True) -> None:
        self._bar: Any = None
        self._lines = enabled and not _terminal()  # notes as plain lines, no bar
        if enabled and not self._lines:
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
        """One line above the bar (without a bar: the line alone)."""
        with contextlib.suppress(OSError, ValueError):
            if self._bar is not None:
                self._bar.write(text, file=sys.stderr)
            elif self._lines:
                print(text, file=sys.stderr, flush=True)

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


def _terminal() -> bool:
    """Whether stderr is a terminal (False once it is closed)."""
    try:
        return sys.stderr.isatty()
    except (OSError, ValueError, AttributeError):
        return False
