"""The exception types of iceskate_study."""

from __future__ import annotations

from iceskate_sim.errors import InputRefused


class StudyError(RuntimeError):
    """A sweep that cannot go on, in one line: a bad SPEC (naming its key) or scene it makes,
    an output folder or results table that cannot be used, a table that cannot be plotted,
    Ray not reached or its runs lost."""


class StudyRefused(StudyError, InputRefused):
    """A ``StudyError`` of input refused before any run (exit status 2): a SPEC, option, output
    folder or results table."""
