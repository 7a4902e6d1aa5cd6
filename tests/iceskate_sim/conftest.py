"""Fixtures of the ROS-free dynamics-core tests: the robot, a dynamics object, seeded randomness
(shared with tests/oracle, from ``oracle.fixtures``), the formulation of eq. (7) and native runs.
"""

from collections.abc import Callable

import pytest

from iceskate_sim.model.dynamics import DynamicsParameters
from iceskate_sim.model.robot import Robot
from oracle.dynamics import GaitDynamics
from oracle.fixtures import assert_close, dynamics, random_state, rng, robot

#: the shared fixtures this folder uses (a conftest's names are its fixtures)
__all__ = ['assert_close', 'dynamics', 'random_state', 'rng', 'robot']


@pytest.fixture(params=['python', 'native'])
def formulation(request: pytest.FixtureRequest) -> str:
    """Where eq. (7) is solved: as written in Python (``GaitDynamics``), then by the native
    kernel (the physics tests that take this fixture run against both)."""
    return request.param


@pytest.fixture
def make_dynamics(formulation: str, robot: Robot) -> Callable[..., GaitDynamics]:
    """``make_dynamics(params)`` -> the dynamics routine of the test's formulation."""
    def make(params: DynamicsParameters | None = None) -> GaitDynamics:
        if formulation == 'native':
            from oracle.native_probes import NativeProbes
            return NativeProbes(robot, params)
        return GaitDynamics(robot, params)
    return make


@pytest.fixture(scope='session')
def native_blocks() -> Callable:
    """``native_blocks(scene, periods)``: a headless run of ``scene`` on the native loop in
    blocks of ``periods`` periods; returns (its blocks as ``Session._record_block`` takes them,
    the event log, the session)."""
    from iceskate_bringup.composition import ControlStack
    from iceskate_sim.run.session import Session

    def run(scene, periods: int) -> tuple[list[dict], list, Session]:
        session = Session(scene)
        stack = ControlStack(scene, session.robot, session.observation())
        blocks = []
        record_block = session._record_block
        session._record_block = lambda block, first: (blocks.append(block),
                                                      record_block(block, first))
        while not session.done:
            session.run_periods(stack, periods)
        assert session.error is None
        return blocks, list(session.sim.events), session

    return run


@pytest.fixture(scope='session')
def native_loop_run() -> Callable:
    """``native_loop_run(scene, periods)``: ``periods`` periods of ``scene``'s controllers on a
    native loop of its own; returns (its block, the loop, the simulator)."""
    from iceskate_bringup.composition import ControlStack
    from iceskate_sim.run.session import Session

    def run(scene, periods: int) -> tuple[dict, object, object]:
        session = Session(scene)
        stack = ControlStack(scene, session.robot, session.observation())
        sim = session.sim
        loop = sim.control_loop(stack.kinematics, list(stack.controllers.values()),
                                scene.pushes, session.psi_initial)
        block, error = sim.run_loop(loop, periods)
        assert error is None and len(block['t']) == periods
        return block, loop, sim

    return run
