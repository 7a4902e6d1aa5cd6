"""Fixtures of the oracle's own tests: the robot, a dynamics object, seeded randomness and the
approximate-comparison helper, shared with tests/iceskate_sim (``oracle.fixtures``)."""

from oracle.fixtures import assert_close, dynamics, random_state, rng, robot

#: the shared fixtures this folder uses (a conftest's names are its fixtures)
__all__ = ['assert_close', 'dynamics', 'random_state', 'rng', 'robot']
