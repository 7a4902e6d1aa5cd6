"""Parameter studies of scenes: sweeps over scene keys into one table, and their maps."""
