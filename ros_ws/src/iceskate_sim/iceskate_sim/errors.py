"""The one exception type of iceskate_sim."""

from __future__ import annotations


class SimulationError(RuntimeError):
    """Raised for every failure of the simulator: bad input, bad scene, divergence, rank loss.

    The message names the problem (the offending key, value, coordinate or event) and, for a
    failure during a run, the simulation time, the gait mode and a summary of the state.
    """
