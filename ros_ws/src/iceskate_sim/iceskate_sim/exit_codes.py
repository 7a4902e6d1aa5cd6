"""The exit status of every executable of the project (docs/usage.md, 'Exit status'):

* ``DONE`` (0): the job was done; a run that ended in a fall, or with another recorded ``end``,
  is a done run;
* ``FAILED`` (1): the job failed while working (a ``SimulationError`` once it had started, an
  output that could not be written, an unexpected error);
* ``REFUSED`` (2): input refused before anything ran (``InputRefused``: a bad argument, value,
  file, scene, key or parameter), the status argparse gives a usage error too;
* 128 + N: ended by signal N (``RunInterrupted.exit_code``).
"""

from __future__ import annotations

from iceskate_sim.errors import InputRefused, RunInterrupted
from iceskate_sim.shutdown import say

DONE = 0
FAILED = 1
REFUSED = 2


def exit_code_of(exc: BaseException) -> int:
    """The exit status of an executable that ends on ``exc``."""
    if isinstance(exc, RunInterrupted):
        return exc.exit_code
    return REFUSED if isinstance(exc, InputRefused) else FAILED


def error_exit(prog: str, exc: BaseException, reason: str | None = None) -> int:
    """Say ``prog: error: REASON`` in one line on stderr (``reason``; None: ``exc``'s message)
    and return the exit status of ``exc``."""
    say(f'{prog}: error: {exc if reason is None else reason}')
    return exit_code_of(exc)
