"""The one exception type of iceskate_study."""

from __future__ import annotations


class StudyError(RuntimeError):
    """A sweep that cannot go on, in one line: a bad SPEC (naming its key) or scene it makes,
    an output folder or results table that cannot be used, a table that cannot be plotted."""
