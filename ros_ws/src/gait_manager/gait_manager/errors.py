"""The one exception type of gait_manager."""

from __future__ import annotations


class GaitManagerError(ValueError):
    """Raised for bad gait-manager parameters or inputs; the message names the key."""
