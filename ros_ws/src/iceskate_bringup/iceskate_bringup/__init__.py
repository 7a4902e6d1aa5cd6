"""Bringup of the iceskate stack: scenes, their composition into nodes, run_scene, the graph."""
