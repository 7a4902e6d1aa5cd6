"""One run of a scene: the scene and its schema (``scene``), the session that owns the simulator,
the trajectory and the bag (``session``), the metrics (``metrics``).
"""
