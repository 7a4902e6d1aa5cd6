"""The one exception type of visual_lifting."""

from __future__ import annotations


class VisualLiftingError(ValueError):
    """Raised for bad visual-lifting parameters or inputs; the message names the key."""
