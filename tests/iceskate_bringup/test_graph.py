"""The ROS-free parts of the graph launcher: real-time scheduling of the nodes."""

import os

import pytest

from iceskate_bringup.graph import realtime_scheduling
from iceskate_sim.errors import SimulationError


def test_priority_zero_leaves_the_scheduling_as_it_is():
    before = (os.sched_getscheduler(0), os.sched_getparam(0))
    with realtime_scheduling(0):
        assert (os.sched_getscheduler(0), os.sched_getparam(0)) == before


@pytest.mark.parametrize('priority', [-1, 100])
def test_a_priority_out_of_range_is_refused_naming_the_range(priority):
    with pytest.raises(SimulationError, match=rf'0 \(off\) or 1\.\.99, got {priority}'), \
            realtime_scheduling(priority):
        pytest.fail('the block ran')


def test_missing_permission_is_a_clear_error(monkeypatch):
    def refuse(pid, policy, param):
        raise PermissionError(1, 'Operation not permitted')
    monkeypatch.setattr(os, 'sched_setscheduler', refuse)
    with pytest.raises(SimulationError, match='rt_priority 10: real-time scheduling') as info, \
            realtime_scheduling(10):
        pytest.fail('the block ran')
    assert 'Operation not permitted' in str(info.value) and 'rtprio' in str(info.value)


def test_the_block_runs_under_sched_fifo_and_the_old_policy_comes_back(needs_fifo):
    before = (os.sched_getscheduler(0), os.sched_getparam(0))
    with pytest.raises(RuntimeError), realtime_scheduling(12):
        assert os.sched_getscheduler(0) == os.SCHED_FIFO
        assert os.sched_getparam(0).sched_priority == 12
        raise RuntimeError('leaves the block')
    assert (os.sched_getscheduler(0), os.sched_getparam(0)) == before
