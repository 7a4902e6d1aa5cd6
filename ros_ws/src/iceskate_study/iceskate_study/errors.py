"""The one exception type of iceskate_study."""

from __future__ import annotations


class StudyError(RuntimeError):
    """Raised for a sweep that cannot go on: a bad SPEC (the message names its key), a scene
    it generates that fails validation, an output folder that cannot hold the results, a
    results table of another SPEC, a table that cannot be plotted."""
